"""Status codes of a solve.  Every failure is NaN in the outputs plus one of these codes."""

CONVERGED = 0
STAGE_SOLVE_FAILED = 1
NOT_PERIODIC = 2
NON_FINITE = 3
UNSTABLE = 4
STEP_BUDGET_EXCEEDED = 5
TOLERANCE_NOT_REACHED = 6
NO_MOTION = 7
OUT_OF_RANGE = 8

STATUS_REASONS = {
    CONVERGED: "converged: error estimate below rtol",
    STAGE_SOLVE_FAILED: "implicit stage equations did not converge (damped Newton)",
    NOT_PERIODIC: "periodic state not reached within the iteration budget",
    NON_FINITE: "NaN or inf in the iterates",
    UNSTABLE: "explicit march unstable: step too large for the stiff friction (use method='periodic')",
    STEP_BUDGET_EXCEEDED: "step budget exhausted before the march became periodic",
    TOLERANCE_NOT_REACHED: "finest grid reached before the error estimate fell below rtol "
                           "(radau5: its refinement rounds ran out, or a step next to a "
                           "turning point of phi was still over its trap ceiling)",
    NO_MOTION: "phi is constant: the body does not move and the efficiency is undefined",
    OUT_OF_RANGE: "converged, but U or P is outside the floating-point range (extreme period or "
                  "friction scale): rescale (the scaled outputs depend only on mu_n/mu_s, the "
                  "scaled period, p and delta T)",
}
