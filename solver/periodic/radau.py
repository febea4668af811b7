"""The 3-stage Radau IIA step: the pure kernel of the engine.

Method as data (scipy ``integrate/_ivp/rk.py``, diffrax ``_solver``): the Butcher tableau
is module constants, and ``radau5_step`` is one implicit step of eq. (Newtonu),

    u' = kappa F(u, tau),      kappa = T^(2-p),

from (tau_n, u_n) over h: the stage equations

    U_i = u_n + h kappa sum_j a_ij F(U_j, tau_n + c_j h),     i = 1, 2, 3,

solved by Newton's method with the exact Jacobian I - h kappa A diag(dF/du(U_j)) (the force
kernel returns dF/du with F), u_{n+1} = U_3.  Radau IIA with 3 stages has order 5 at the
step ends (stage order 3), is L-stable and stiffly accurate: where the body sticks the
friction rate kappa dF/du ~ kappa mu / delta_tau is huge, and the stiff mode is damped to
0 in one step instead of ringing (Hairer & Wanner, Solving ODEs II, IV.5).  The period
integrals int u and int Pi ride along as quadratures with the same weights (the augmented
state (u, int u, int Pi) of the issue; their stage equations are explicit).

The embedded error estimate is RADAU5's (Hairer & Wanner IV.8, eq. (8.19)-(8.20); scipy
``radau.py``): with Z_i = U_i - u_n,

    err = (MU_REAL / h - J0)^-1 (f0 + sum_i E_i Z_i / h),

f0 = kappa F(u_n, tau_n+) and J0 = kappa dF/du there.  It is the difference of the step and
an embedded method of order 3, filtered by (I - h gamma0 J0)^-1 so that it stays bounded
where the problem is stiff; applied to the augmented state it also estimates the local
errors of the two quadratures (``embedded_error``).  The defect estimate, which judges the
target pass's steps, is in ``periodic.defect``.

The stage Newton keeps the former order-3 engine's safeguards, each measured
there: a line search on the residual, a cut of sign flips where F has an infinite slope in
u (0 < p < 1 with delta = 0), and no convergence claimed from a line search that bottomed
out.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..model.force import force_slope_power_sc


_S6 = math.sqrt(6.0)


#: Radau IIA, 3 stages (Butcher tableau): nodes, matrix and weights (= last row).
RADAU5_C = np.array([(4.0 - _S6) / 10.0, (4.0 + _S6) / 10.0, 1.0])
RADAU5_A = np.array([
    [(88.0 - 7.0 * _S6) / 360.0, (296.0 - 169.0 * _S6) / 1800.0, (-2.0 + 3.0 * _S6) / 225.0],
    [(296.0 + 169.0 * _S6) / 1800.0, (88.0 + 7.0 * _S6) / 360.0, (-2.0 - 3.0 * _S6) / 225.0],
    [(16.0 - _S6) / 36.0, (16.0 + _S6) / 36.0, 1.0 / 9.0]])
RADAU5_B = RADAU5_A[2].copy()


#: the embedded estimate's combination of the stage increments and the real eigenvalue of
#: A^-1 (scipy ``radau.py``: E, MU_REAL)
RADAU5_E = np.array([-13.0 - 7.0 * _S6, -13.0 + 7.0 * _S6, -1.0]) / 3.0
MU_REAL = 3.0 + 3.0 ** (2.0 / 3.0) - 3.0 ** (1.0 / 3.0)


#: E A: the embedded estimate's combination for the quadratures, whose stage increments
#: are h A (stage values of the integrand)
RADAU5_EA = RADAU5_E @ RADAU5_A
ORDER = 5


#: the local errors the step-size control sees are O(h^(ERROR_ORDER + 1)): those of the
#: defect estimate (``defect_error``; its fallback, the embedded estimate, is O(h^4))
ERROR_ORDER = 5


# the tableau as scalars for the compiled kernels (numba reads module globals as constants)
C1, C2 = RADAU5_C[0], RADAU5_C[1]
A11, A12, A13 = RADAU5_A[0]
A21, A22, A23 = RADAU5_A[1]
A31, A32, A33 = RADAU5_A[2]
E1, E2, E3 = RADAU5_E
EA1, EA2, EA3 = RADAU5_EA


class StageKinematics(NamedTuple):
    """sin phi, cos phi and dphi/dtau at the three stage times of a step."""

    S1: float
    S2: float
    S3: float
    C1: float
    C2: float
    C3: float
    om1: float
    om2: float
    om3: float


class StepSolution(NamedTuple):
    """One solved Radau IIA step (``radau5_step``).

    U1, U2, U3 : stage values of u (U3 = u_{n+1})
    P1, P2, P3 : power density Pi at the stages
    s1, s2, s3 : dU_i/du_n, the stages' sensitivity to the step's start
    m_minus_1 : du_{n+1}/du_n - 1, formed without cancellation
    Pu1, Pu2, Pu3 : dPi/du at the stages (for the power's adjoint weights)
    F3 : F at the last stage (first-order updated to its final value): the next step's f0
        where phi is smooth at the node (first same as last)
    d1, d2, d3 : dF/du at the stages
    iterations : evaluations of F at the three stages (the start, Newton's and the line
        search's trials)
    ok : whether the stage Newton converged
    rate : Newton's observed quadratic constant |x_2| / |x_1|^2 (1/u), or NaN where the
        step took one correction (``radau5_step``'s ``rate``)
    """

    U1: float
    U2: float
    U3: float
    P1: float
    P2: float
    P3: float
    s1: float
    s2: float
    s3: float
    m_minus_1: float
    Pu1: float
    Pu2: float
    Pu3: float
    F3: float
    d1: float
    d2: float
    d3: float
    iterations: int
    ok: bool
    rate: float


class StepError(NamedTuple):
    """The embedded local-error estimate of a step for the augmented state:
    u (``u``), int u (``int_u``) and int Pi (``int_pi``)."""

    u: float
    int_u: float
    int_pi: float


@njit(cache=True, error_model="numpy")
def runtime_bool(flag):
    """``flag`` as a run-time bool, not a literal.  numba compiles a kernel once per literal
    argument (a bool or int constant at a call site: ``adaptive_pass(..., True, False)`` and
    ``(..., True)`` were two compilations of the pass, its callees included); the engine
    passes its constant flags, rows and starting indices through ``runtime_bool`` and
    ``runtime_int`` so that a kernel has one signature (docs/validation.md).  (An identity
    function would not do: its return type is the literal again.)"""
    if flag:
        return True
    return False


@njit(cache=True, error_model="numpy")
def runtime_int(value):
    """``value`` as a run-time int64, not a literal (``runtime_bool``)."""
    return value + 0


@njit(cache=True, error_model="numpy")
def flip_cut(flipped, U, x):
    """The factor (<= 1) a Newton step x of stage value U is cut by: where the previous
    iterate flipped U's sign (``flipped``) and x flips it again keeping more than half of
    |U|, the step is cut to land halfway to zero (where F has an infinite slope, 0 < p < 1
    with delta = 0, the plain iteration oscillates between the two signs)."""
    if flipped and U * (U + x) < 0.0 and abs(U + x) > 0.5 * abs(U):
        return -0.5 * U / x
    return 1.0


@njit(cache=True, error_model="numpy")
def solve3(J, r0, r1, r2):
    """x with J x = r for a 3 x 3 ``J`` (tuple of 9, row-major), Gaussian elimination with
    partial pivoting (the stiff stages make the rows differ by up to ~1e10 in size)."""
    a00, a01, a02, a10, a11, a12, a20, a21, a22 = J
    # pivot the first column
    if abs(a10) > abs(a00) and abs(a10) >= abs(a20):
        a00, a01, a02, r0, a10, a11, a12, r1 = a10, a11, a12, r1, a00, a01, a02, r0
    elif abs(a20) > abs(a00):
        a00, a01, a02, r0, a20, a21, a22, r2 = a20, a21, a22, r2, a00, a01, a02, r0
    f1 = a10 / a00
    f2 = a20 / a00
    a11 -= f1 * a01
    a12 -= f1 * a02
    r1 -= f1 * r0
    a21 -= f2 * a01
    a22 -= f2 * a02
    r2 -= f2 * r0
    if abs(a21) > abs(a11):
        a11, a12, r1, a21, a22, r2 = a21, a22, r2, a11, a12, r1
    f = a21 / a11
    a22 -= f * a12
    r2 -= f * r1
    x2 = r2 / a22
    x1 = (r1 - a12 * x2) / a11
    x0 = (r0 - a01 * x1 - a02 * x2) / a00
    return x0, x1, x2


@njit(cache=True, error_model="numpy")
def stage_matrix(hk, d1, d2, d3):
    """I - h kappa A diag(d) for the Radau IIA matrix A, row-major (``hk`` = h kappa)."""
    z1 = hk * d1
    z2 = hk * d2
    z3 = hk * d3
    return (1.0 - A11 * z1, -A12 * z2, -A13 * z3,
            -A21 * z1, 1.0 - A22 * z2, -A23 * z3,
            -A31 * z1, -A32 * z2, 1.0 - A33 * z3)


@njit(cache=True, error_model="numpy")
def _residual(u_n, hk, U1, U2, U3, F1, F2, F3):
    return (U1 - u_n - hk * (A11 * F1 + A12 * F2 + A13 * F3),
            U2 - u_n - hk * (A21 * F1 + A22 * F2 + A23 * F3),
            U3 - u_n - hk * (A31 * F1 + A32 * F2 + A33 * F3))


@njit(cache=True, error_model="numpy")
def radau5_step(u_n, U1, U2, U3, h, kin, phys, atol, options, rate=math.inf, slope=math.nan):
    """Solve one Radau IIA step from u_n over h, starting Newton at (U1, U2, U3).

    Parameters
    ----------
    u_n : float
        u at the step's start.
    U1, U2, U3 : float
        Starting stage values (a prediction: the previous step's collocation polynomial,
        or the previous pass's stages moved along their sensitivities).
    h : float
        Step length in tau.
    kin : StageKinematics
        sin phi, cos phi, dphi/dtau at tau_n + c_i h (one side of a corner: the step's).
    phys : PointPhysics
    atol : float
        Absolute tolerance of the stage values (the Newton step, or the error left after it
        at the observed contraction (Hairer & Wanner IV.8), must be below it).
    options : StageOptions
        ``periodic.options``: Newton gives up after ``max_iterations`` (MAX_STAGE_ITERATIONS);
        ``first_correction_share`` and ``slope_share`` below.
    rate : float
        Newton's quadratic constant K (1/u) observed on the previous step (its
        ``StepSolution.rate``; inf: none).  The first correction x is taken as the last
        when K |x|^2 <= first_correction_share atol (with the exact Jacobian the next
        correction is about K |x|^2), which saves the second evaluation of most steps; the
        stage error is then predicted, not measured (callers that need ``atol`` to hold pass
        inf).
    slope : float
        dF/du at the previous step's end (NaN: none).  ``rate`` is used only where dF/du at
        the predicted stages lies within slope_share of it: across the friction's band
        (width delta) K grows by orders of magnitude from one step to the next (measured
        without this guard: step budgets exceeded on 20-30 % of the stress power laws).

    Returns
    -------
    StepSolution
    """
    kappa, mu_n, mu_s, p, dtau = phys
    hk = h * kappa
    F1, d1, P1, Pu1 = force_slope_power_sc(U1, kin.S1, kin.C1, kin.om1, mu_n, mu_s, p, dtau)
    F2, d2, P2, Pu2 = force_slope_power_sc(U2, kin.S2, kin.C2, kin.om2, mu_n, mu_s, p, dtau)
    F3, d3, P3, Pu3 = force_slope_power_sc(U3, kin.S3, kin.C3, kin.om3, mu_n, mu_s, p, dtau)
    R1, R2, R3 = _residual(u_n, hk, U1, U2, U3, F1, F2, F3)
    ok = False
    rounds = 1
    previous = math.inf
    flipped1 = flipped2 = flipped3 = runtime_bool(False)
    # the sign-flip cut only where F has an infinite slope at u = 0 (``flip_cut``)
    singular = 0.0 < p < 1.0 and dtau == 0.0
    observed = math.nan
    first_size = math.nan
    # the carried constant holds where F's slope at the predicted stages is that of the
    # previous step's end (not across the friction's band, where it changes by mu / delta)
    span = max(abs(d1 - slope), abs(d2 - slope), abs(d3 - slope))
    if not span <= options.slope_share * abs(slope):
        rate = math.inf
    for it in range(options.max_iterations):
        J = stage_matrix(hk, d1, d2, d3)
        x1, x2, x3 = solve3(J, -R1, -R2, -R3)
        size = max(abs(x1), abs(x2), abs(x3))
        if it == 1 and first_size > 0.0:
            observed = size / (first_size * first_size)
        if size <= atol or (size < previous < math.inf
                            and size * size <= atol * (previous - size)) \
                or (it == 0 and rate * size * size <= options.first_correction_share * atol):
            U1 += x1
            U2 += x2
            U3 += x3
            P1 += Pu1 * x1
            P2 += Pu2 * x2
            P3 += Pu3 * x3
            F3 += d3 * x3
            ok = math.isfinite(U1) and math.isfinite(U2) and math.isfinite(U3)
            break
        cut = min(1.0, flip_cut(flipped1, U1, x1), flip_cut(flipped2, U2, x2),
                  flip_cut(flipped3, U3, x3))
        if cut < 1.0:
            x1 *= cut
            x2 *= cut
            x3 *= cut
        norm0 = R1 * R1 + R2 * R2 + R3 * R3
        lam = 1.0
        for _ in range(40):
            T1 = U1 + lam * x1
            T2 = U2 + lam * x2
            T3 = U3 + lam * x3
            G1, g1, Q1, Qu1 = force_slope_power_sc(T1, kin.S1, kin.C1, kin.om1, mu_n, mu_s,
                                                   p, dtau)
            G2, g2, Q2, Qu2 = force_slope_power_sc(T2, kin.S2, kin.C2, kin.om2, mu_n, mu_s,
                                                   p, dtau)
            G3, g3, Q3, Qu3 = force_slope_power_sc(T3, kin.S3, kin.C3, kin.om3, mu_n, mu_s,
                                                   p, dtau)
            rounds += 1
            S1, S2, S3 = _residual(u_n, hk, T1, T2, T3, G1, G2, G3)
            if S1 * S1 + S2 * S2 + S3 * S3 <= (1.0 - 1e-4 * lam) * norm0 or lam < 1e-9:
                break
            lam *= 0.5
        flipped1 = singular and U1 * T1 < 0.0
        flipped2 = singular and U2 * T2 < 0.0
        flipped3 = singular and U3 * T3 < 0.0
        U1, U2, U3, F1, F2, F3 = T1, T2, T3, G1, G2, G3
        d1, d2, d3, R1, R2, R3 = g1, g2, g3, S1, S2, S3
        P1, P2, P3, Pu1, Pu2, Pu3 = Q1, Q2, Q3, Qu1, Qu2, Qu3
        if not (math.isfinite(U1) and math.isfinite(U2) and math.isfinite(U3)):
            break
        if (lam * size <= atol and lam >= 1e-9) or (R1 == 0.0 and R2 == 0.0 and R3 == 0.0):
            ok = True
            break
        previous = size if lam == 1.0 and cut == 1.0 else math.inf
        if it == 0 and lam == 1.0 and cut == 1.0:
            first_size = size
    # sensitivities at the converged stages: J s = 1, and s - 1 = J^-1 (h kappa A d)
    J = stage_matrix(hk, d1, d2, d3)
    z1 = hk * d1
    z2 = hk * d2
    z3 = hk * d3
    v1 = A11 * z1 + A12 * z2 + A13 * z3
    v2 = A21 * z1 + A22 * z2 + A23 * z3
    v3 = A31 * z1 + A32 * z2 + A33 * z3
    e1, e2, e3 = solve3(J, v1, v2, v3)
    return StepSolution(U1, U2, U3, P1, P2, P3, 1.0 + e1, 1.0 + e2, 1.0 + e3, e3,
                        Pu1, Pu2, Pu3, F3, d1, d2, d3, rounds, ok, observed)


@njit(cache=True, error_model="numpy")
def embedded_error(u_n, f0, J0, Pi0, Pi_u0, step, h):
    """RADAU5's embedded estimate of the step's local error in (u, int u, int Pi).

    ``f0``, ``J0`` are kappa F and kappa dF/du at (tau_n+, u_n), ``Pi0``, ``Pi_u0`` the power
    density and its u-derivative there, ``step`` the ``StepSolution``.  For the augmented
    right-hand side (kappa F, u, Pi) with Jacobian [[J0, 0, 0], [1, 0, 0], [Pi_u0, 0, 0]],
    (MU_REAL / h - J_aug)^-1 applied to f0_aug + sum_i E_i Z_i / h gives, with the
    quadratures' stage increments h A (U, Pi):

        err_u   = r_u / (MU_REAL / h - J0),   r_u = f0 + sum E_i (U_i - u_n) / h
        err_int_u  = (h / MU_REAL) (u_n + sum (EA)_j U_j + err_u)
        err_int_pi = (h / MU_REAL) (Pi0 + sum (EA)_j Pi_j + Pi_u0 err_u)
    """
    r_u = f0 + (E1 * (step.U1 - u_n) + E2 * (step.U2 - u_n) + E3 * (step.U3 - u_n)) / h
    err_u = r_u / (MU_REAL / h - J0)
    scale = h / MU_REAL
    err_v = scale * (u_n + EA1 * step.U1 + EA2 * step.U2 + EA3 * step.U3 + err_u)
    err_w = scale * (Pi0 + EA1 * step.P1 + EA2 * step.P2 + EA3 * step.P3 + Pi_u0 * err_u)
    return StepError(err_u, err_v, err_w)


@njit(cache=True, error_model="numpy")
def dense_value(theta, u_n, U1, U2, U3):
    """The collocation polynomial of a step at theta = (tau - tau_n) / h: the cubic through
    (0, u_n), (c1, U1), (c2, U2), (1, U3)."""
    l0 = (theta - C1) * (theta - C2) * (theta - 1.0) / ((-C1) * (-C2) * (-1.0))
    l1 = theta * (theta - C2) * (theta - 1.0) / (C1 * (C1 - C2) * (C1 - 1.0))
    l2 = theta * (theta - C1) * (theta - 1.0) / (C2 * (C2 - C1) * (C2 - 1.0))
    l3 = theta * (theta - C1) * (theta - C2) / ((1.0 - C1) * (1.0 - C2))
    return l0 * u_n + l1 * U1 + l2 * U2 + l3 * U3


@njit(cache=True, error_model="numpy")
def step_integrals(h, step):
    """(int u, int Pi) over the step by the Radau weights (order 5)."""
    return (h * (A31 * step.U1 + A32 * step.U2 + A33 * step.U3),
            h * (A31 * step.P1 + A32 * step.P2 + A33 * step.P3))


@njit(cache=True, error_model="numpy")
def step_weights(h, step):
    """(d int_step u / du_n, d int_step Pi / du_n): the step's own share of the adjoint."""
    return (h * (A31 * step.s1 + A32 * step.s2 + A33 * step.s3),
            h * (A31 * step.Pu1 * step.s1 + A32 * step.Pu2 * step.s2
                 + A33 * step.Pu3 * step.s3))
