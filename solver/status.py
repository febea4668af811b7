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

#: what a status means, whichever engine gave it (``status_reason`` names the engine)
STATUS_REASONS = {
    CONVERGED: "converged: error estimate below rtol",
    STAGE_SOLVE_FAILED: "implicit stage equations did not converge (damped Newton)",
    NOT_PERIODIC: "periodic state not reached within the iteration budget",
    NON_FINITE: "NaN or inf in the iterates",
    UNSTABLE: "explicit march unstable: step too large for the stiff friction (use method='periodic')",
    STEP_BUDGET_EXCEEDED: "step budget exhausted (max_steps_per_period)",
    TOLERANCE_NOT_REACHED: "the error estimate did not fall below rtol within the refinement "
                           "allowed",
    NO_MOTION: "phi is constant: the body does not move and the efficiency is undefined",
    OUT_OF_RANGE: "converged, but U or P is outside the floating-point range (extreme period or "
                  "friction scale): rescale (the scaled outputs depend only on mu_n/mu_s, the "
                  "scaled period, p and delta T)",
}

#: the engine's own words where they say more than STATUS_REASONS
_ENGINE_REASONS = {
    "periodic": {
        STAGE_SOLVE_FAILED: "a Radau IIA stage solve (damped Newton) did not converge",
        NOT_PERIODIC: "Newton on u(0) by frozen-grid sweeps did not reach the periodic state",
        STEP_BUDGET_EXCEEDED: "a sweep of one period needed more than max_steps_per_period "
                              "steps",
        TOLERANCE_NOT_REACHED: "its refinement rounds ran out before the error estimate fell "
                               "below rtol (or a step next to a turning point of phi was still "
                               "over its trap ceiling)",
    },
    "march": {
        NOT_PERIODIC: "the march did not become periodic within its period budget",
        STEP_BUDGET_EXCEEDED: "step budget exhausted before the march became periodic",
        TOLERANCE_NOT_REACHED: "finest grid reached before the error estimate fell below rtol",
    },
}


def status_reason(status, method="periodic"):
    """One line saying what ``status`` means, naming the engine (method) that gave it."""
    status = int(status)
    text = _ENGINE_REASONS.get(method, {}).get(status, STATUS_REASONS.get(status, "unknown"))
    return f"{text} (method {method})"
