"""The ``periodic`` method: the periodic boundary-value problem on a tau-grid.

Discretisation: the 2-stage Radau IIA collocation method (order 3, stage
order 2, L-stable and stiffly accurate).  L-stability matters: when the body
sticks the friction rate T^(2-p) dF/du ~ T^(2-p) mu / delta_tau is huge, and
an A-stable but not L-stable rule (trapezoidal, implicit midpoint) passes the
stiff mode through with amplification -1 per step, so the discrete solution
rings.  Radau IIA damps it to 0.  Grid nodes sit at the corners of phi.

Solution of the discrete periodic problem: Newton on the single unknown
u(0), with the step equations eliminated step by step.  Each step solves the
2 x 2 stage system by damped Newton (a line search on the residual, and a
cold restart when the predicted start fails; it stops when a step, or the error
left after it as estimated from the observed contraction, is below the stage
tolerance), and carries the derivative du_{n+1}/du_n along, so the derivative of the
discrete period map (the monodromy M) is Newton's own.  It is formed from the slopes at the
last evaluated stage iterate, so it is exact up to the final correction: in a 3000-input
check its relative error was <= 7e-5 at stage tolerance 1e-9 and <= 1.4e-7 at 1e-12
(the adjoint of ``_gradient`` re-evaluates the slopes at the final stages); M is almost always in
(0, 1) (friction dissipates; the anisotropic law is not monotone everywhere,
so single steps can amplify), and 1 - M is accumulated as
-expm1(sum log m_n) with m_n - 1 formed without cancellation.  While M < 1
the Newton iterate is kept inside a bracket of the fixed point.  This is Newton's method on the
whole cyclic system (its Jacobian is cyclic bidiagonal after eliminating the
stages) with the stage equations always kept solved, which is what keeps it
convergent through stiff sticking phases.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._force import force_slope_power_sc
from ._kinematics import angle_and_rate
from ._monodromy import batch_outputs, monodromy_factor, node_weights, one_minus_monodromy  # noqa: F401 (re-exported)
from ._status import CONVERGED, NON_FINITE, NOT_PERIODIC, STAGE_SOLVE_FAILED

#: Radau IIA, 2 stages (Butcher tableau).
RADAU_C = np.array([1.0 / 3.0, 1.0])
RADAU_A = np.array([[5.0 / 12.0, -1.0 / 12.0], [3.0 / 4.0, 1.0 / 4.0]])
RADAU_B = np.array([3.0 / 4.0, 1.0 / 4.0])
ORDER = 3


MAX_STAGE_ITERATIONS = 60
MAX_SHOOTING_ITERATIONS = 80


@njit(cache=True, error_model="numpy")
def stage_jacobian(hd1, hd2):
    """I - h A diag(kappa dF/du at the stages) for RADAU_A; returns (J11, J12, J21, J22, det)."""
    J11 = 1.0 - (5.0 / 12.0) * hd1
    J12 = (1.0 / 12.0) * hd2
    J21 = -0.75 * hd1
    J22 = 1.0 - 0.25 * hd2
    return J11, J12, J21, J22, J11 * J22 - J12 * J21


@njit(cache=True, error_model="numpy")
def stage_tolerance(rtol, vscale):
    """The stage Newton's absolute tolerance in u: max(1e-5 rtol, 1e-14) V, V the speed scale.
    Every converged step carries a residual up to this size."""
    return max(1e-5 * rtol, 1e-14) * vscale


@njit(cache=True, error_model="numpy")
def flip_cut(flipped, U, x):
    """The factor (<= 1) a Newton step x of stage value U is cut by: where the previous
    iterate flipped U's sign (``flipped``) and x flips it again keeping more than half of
    |U|, the step is cut to land halfway to zero (see ``radau_step``)."""
    if flipped and U * (U + x) < 0.0 and abs(U + x) > 0.5 * abs(U):
        return -0.5 * U / x
    return 1.0


@njit(cache=True, error_model="numpy")
def bracketed_newton_update(u0, g, one_minus_M, lo, hi):
    """Newton's step on u(0) for the shooting residual g = u(1) - u(0) with 1 - M its
    derivative, kept inside the bracket [lo, hi] of the fixed point (g > 0 below it, g < 0
    above it) and bisecting where Newton leaves the bracket (the map need not be monotone:
    the anisotropic law can amplify, M > 1 or M < 0).  Returns (new u0, lo, hi)."""
    if g > 0.0:
        lo = max(lo, u0)
    else:
        hi = min(hi, u0)
    candidate = u0 + g / one_minus_M
    if not (lo < candidate < hi):
        candidate = 0.5 * (lo + hi)
    return candidate, lo, hi


@njit(cache=True, error_model="numpy")
def radau_step(u_n, U1, U2, h, sin1, cos1, om1, sin2, cos2, om2, kappa, mu_n, mu_s, p, dtau,
               atol):
    """Solve one Radau IIA step from u_n, starting at the guess (U1, U2); sin_i, cos_i are
    those of phi at the stages, om_i dphi/dtau there.

    Returns (U1, U2, s1, s2, m_minus_1, iterations, Pi1, Pi2, Pi_u1, Pi_u2, ok): the stage
    values, their sensitivities dU_i/du_n, du_{n+1}/du_n - 1, the power density at the
    stages with its u-derivative, and whether Newton converged.  Pi comes with every
    evaluation of F (``force_slope_power_sc``); where the last Newton step is taken without
    one, Pi moves with it to first order (the convergence test bounds that step by about
    sqrt(atol times the previous one); in the solver the carried int Pi was within 2e-10
    relative of Pi evaluated at the final stages).
    """
    a11, a12, a21, a22 = 5.0 / 12.0, -1.0 / 12.0, 0.75, 0.25
    F1, d1, P1, Pu1 = force_slope_power_sc(U1, sin1, cos1, om1, mu_n, mu_s, p, dtau)
    F2, d2, P2, Pu2 = force_slope_power_sc(U2, sin2, cos2, om2, mu_n, mu_s, p, dtau)
    R1 = U1 - u_n - h * kappa * (a11 * F1 + a12 * F2)
    R2 = U2 - u_n - h * kappa * (a21 * F1 + a22 * F2)
    ok = False
    it = 0
    previous = math.inf  # size of the previous full Newton step (inf: none yet, or damped)
    flipped1 = False  # the previous iterate changed the stage's sign (0 < p < 1, delta = 0 only)
    flipped2 = False
    # p = 0: the line search handles the regularised sign; p >= 1: F is C^1 in u; delta > 0:
    # the slope is finite (cutting there too made the shooting of 10 of 300 points at p = 0.5
    # take 250-1400 iterations instead of 15: the cut steers stages between roots)
    singular = 0.0 < p < 1.0 and dtau == 0.0
    for it in range(1, MAX_STAGE_ITERATIONS + 1):
        J11, J12, J21, J22, det = stage_jacobian(h * kappa * d1, h * kappa * d2)
        x1 = -(J22 * R1 - J12 * R2) / det
        x2 = -(-J21 * R1 + J11 * R2) / det
        size = max(abs(x1), abs(x2))
        # error left after this step, at the observed contraction theta = size / previous:
        # theta / (1 - theta) size (Hairer & Wanner IV.8); Newton converges faster than that
        if size <= atol or (size < previous < math.inf
                             and size * size <= atol * (previous - size)):
            # converged: take the step without a line search (at rounding level the
            # residual cannot decrease, and backtracking would only burn evaluations)
            U1 += x1
            U2 += x2
            P1 += Pu1 * x1
            P2 += Pu2 * x2
            ok = True
            break
        # A stage whose sign Newton flips back and forth sits next to a root at zero velocity
        # where F has an infinite slope (0 < p < 1 with delta = 0 and the whole link at rest:
        # F ~ -|u|^p sign u, on which Newton maps u to about -u): a flip right after a flip
        # that keeps more than half the stage's size is cut to land halfway to zero
        # (measured: 60 iterations oscillating at a rate of 0.93 before; a genuine reversal,
        # even one that overshoots once, shrinks faster and is not cut).  Not at p = 0,
        # where cutting the flips of the regularised sign cost 14 % more step-sweeps
        cut = min(1.0, flip_cut(flipped1, U1, x1), flip_cut(flipped2, U2, x2))
        if cut < 1.0:
            x1 *= cut
            x2 *= cut
        norm0 = R1 * R1 + R2 * R2
        lam = 1.0
        for _ in range(40):
            T1 = U1 + lam * x1
            T2 = U2 + lam * x2
            G1, g1, Q1, Qu1 = force_slope_power_sc(T1, sin1, cos1, om1, mu_n, mu_s, p, dtau)
            G2, g2, Q2, Qu2 = force_slope_power_sc(T2, sin2, cos2, om2, mu_n, mu_s, p, dtau)
            S1 = T1 - u_n - h * kappa * (a11 * G1 + a12 * G2)
            S2 = T2 - u_n - h * kappa * (a21 * G1 + a22 * G2)
            if S1 * S1 + S2 * S2 <= (1.0 - 1e-4 * lam) * norm0 or lam < 1e-9:
                break
            lam *= 0.5
        # (the iterate's own sign changes: a cut step that stays on its side is not one)
        flipped1 = singular and U1 * T1 < 0.0
        flipped2 = singular and U2 * T2 < 0.0
        U1, U2, F1, F2, d1, d2, R1, R2 = T1, T2, G1, G2, g1, g2, S1, S2
        P1, P2, Pu1, Pu2 = Q1, Q2, Qu1, Qu2
        if not (math.isfinite(U1) and math.isfinite(U2)):
            break
        # (size: the Newton step before any cut, so a cut step is not taken for convergence;
        # a line search that bottomed out is not convergence either: its step is tiny
        # because no decrease was found, not because the stages are solved)
        if (lam * size <= atol and lam >= 1e-9) or (R1 == 0.0 and R2 == 0.0):
            ok = True
            break
        previous = size if lam == 1.0 and cut == 1.0 else math.inf
    # sensitivities at the converged stages: J s = 1, and m - 1 = e2^T J^-1 (h A D 1)
    hd1 = h * kappa * d1
    hd2 = h * kappa * d2
    J11, J12, J21, J22, det = stage_jacobian(hd1, hd2)
    s1 = (J22 - J12) / det
    s2 = (J11 - J21) / det
    v1 = a11 * hd1 + a12 * hd2
    v2 = a21 * hd1 + a22 * hd2
    m_minus_1 = (-J21 * v1 + J11 * v2) / det
    return U1, U2, s1, s2, m_minus_1, it, P1, P2, Pu1, Pu2, ok


@njit(cache=True, error_model="numpy")
def _radau_step_retrying(u_n, U1, U2, predicted, h, sin1, cos1, om1, sin2, cos2, om2, kappa,
                         mu_n, mu_s, p, dtau, atol):
    """``radau_step`` from the start (U1, U2); where its Newton fails, again from u_n if the
    start was ``predicted`` (a tangent prediction or a guess can miss the basin), then from rest
    (a step into a stop can defeat both: a burst-and-coast power law at its corner took 60
    iterations from each, from rest 6).  Returns as ``radau_step``, iterations summed."""
    out = radau_step(u_n, U1, U2, h, sin1, cos1, om1, sin2, cos2, om2, kappa, mu_n, mu_s, p,
                     dtau, atol)
    its = out[5]
    if not out[10] and predicted:
        out = radau_step(u_n, u_n, u_n, h, sin1, cos1, om1, sin2, cos2, om2, kappa, mu_n, mu_s,
                         p, dtau, atol)
        its += out[5]
    if not out[10] and u_n != 0.0:
        out = radau_step(u_n, 0.0, 0.0, h, sin1, cos1, om1, sin2, cos2, om2, kappa, mu_n, mu_s,
                         p, dtau, atol)
        its += out[5]
    return out[:5] + (its,) + out[6:]


@njit(cache=True, error_model="numpy")
def solve_point_on_grid(code, params, grid, N, kappa, mu_n, mu_s, p, dtau, u0, vscale, rtol,
                        u_out, step_u, step_pi, step_m, stages_out=None, stage_guess=None,
                        kinematics_out=None, weights_out=None, step_weights_out=None):
    """Periodic solution for one parameter point on the first N steps of ``grid``.

    Writes u at the nodes into ``u_out``, the per-step integrals of u and Pi into
    ``step_u``, ``step_pi``, the step derivatives du_{n+1}/du_n into ``step_m`` and,
    if given, the stage values (U1_0, U2_0, U1_1, ...) of the converged sweep into
    ``stages_out`` (>= 2N,).  ``stage_guess`` (2N,), optional: starting stage values for the
    first sweep (default, or an array of another size: the previous step's collocation
    polynomial extrapolated, u_n at the first step; a step whose Newton fails from its start
    retries from u_n, then from rest).  ``kinematics_out`` (2 or 4, >= 2N), optional: receives phi
    and dphi/dtau at the stage times, and with 4 rows also sin phi and cos phi there (for
    the adjoint, ``_gradient``).  ``vscale`` <= 0: the speed scale is computed here,
    (1/4) int |dphi/dtau| by the Radau rule.  ``weights_out`` (>= N,),
    optional: receives the node weights of ``node_weights``, and ``step_weights_out`` (>= N,),
    optional, the step weights q_n they are formed from.
    Returns (int_u, int_Pi, u0, status, shooting_iterations, stage_iterations).
    """
    phis = np.empty(2 * N)
    oms = np.empty(2 * N)
    hs = np.empty(N)
    for n in range(N):
        h = grid[n + 1] - grid[n]
        hs[n] = h
        mid = grid[n] + 0.5 * h
        phis[2 * n], oms[2 * n] = angle_and_rate(code, params, grid[n] + h / 3.0, mid)
        phis[2 * n + 1], oms[2 * n + 1] = angle_and_rate(code, params, grid[n + 1], mid)
    sins = np.sin(phis)
    coss = np.cos(phis)
    if kinematics_out is not None:
        kinematics_out[0, :2 * N] = phis
        kinematics_out[1, :2 * N] = oms
        if kinematics_out.shape[0] >= 4:
            kinematics_out[2, :2 * N] = sins
            kinematics_out[3, :2 * N] = coss
    if vscale <= 0.0:  # (1/4) int |dphi/dtau| by the Radau rule: a speed scale for the tolerances
        vscale = 0.0
        for n in range(N):
            vscale += 0.25 * hs[n] * (0.75 * abs(oms[2 * n]) + 0.25 * abs(oms[2 * n + 1]))
        vscale = max(vscale, 1e-300)
    guessed = stage_guess is not None and stage_guess.size == 2 * N
    stages = np.empty(2 * N)
    powers = np.empty(2 * N)  # Pi and dPi/du at the stages, from the stage iterations
    powers_u = np.empty(2 * N)
    sens = np.empty(2 * N)
    m_minus_1 = np.empty(N)
    u_start = np.empty(N)
    atol_stage = stage_tolerance(rtol, vscale)
    tol_fix = max(1e-3 * rtol, 1e-13) * vscale
    status = NOT_PERIODIC
    stage_its = 0
    first = True
    it_out = 0
    # g(u0) = Phi(u0) - u0 is > 0 for u0 << 0 and < 0 for u0 >> 0 (friction decelerates any
    # fast enough body within a period): a fixed point lies in (-bound, bound), and the sign
    # of g at any iterate tells on which side of it one lies
    bound = 1e3 * vscale + 10.0 * abs(u0)
    lo = -bound
    hi = bound
    for it_out in range(1, MAX_SHOOTING_ITERATIONS + 1):
        u = u0
        log_m = 0.0
        sign_m = 1.0
        for n in range(N):
            if first and guessed:
                U1 = stage_guess[2 * n]
                U2 = stage_guess[2 * n + 1]
            elif first and n > 0:
                # the previous step's collocation polynomial extrapolated: O(h^3) from the
                # stages where u is smooth, against O(h) for u_n (a stage iteration fewer)
                r = hs[n] / hs[n - 1]
                U1 = collocation_value(1.0 + r / 3.0, u_start[n - 1], stages[2 * n - 2],
                                       stages[2 * n - 1])
                U2 = collocation_value(1.0 + r, u_start[n - 1], stages[2 * n - 2],
                                       stages[2 * n - 1])
            elif first:
                U1 = u
                U2 = u
            else:  # tangent prediction from the previous sweep
                du = u - u_start[n]
                U1 = stages[2 * n] + sens[2 * n] * du
                U2 = stages[2 * n + 1] + sens[2 * n + 1] * du
            u_start[n] = u
            U1, U2, s1, s2, mm1, its, P1, P2, Pu1, Pu2, ok = _radau_step_retrying(
                u, U1, U2, not first or guessed or n > 0, hs[n], sins[2 * n], coss[2 * n],
                oms[2 * n], sins[2 * n + 1], coss[2 * n + 1], oms[2 * n + 1], kappa, mu_n, mu_s,
                p, dtau, atol_stage)
            stage_its += its
            if not ok:
                status = STAGE_SOLVE_FAILED if math.isfinite(U2) else NON_FINITE
                return math.nan, math.nan, u0, status, it_out, stage_its
            stages[2 * n] = U1
            stages[2 * n + 1] = U2
            powers[2 * n] = P1
            powers[2 * n + 1] = P2
            powers_u[2 * n] = Pu1
            powers_u[2 * n + 1] = Pu2
            sens[2 * n] = s1
            sens[2 * n + 1] = s2
            m_minus_1[n] = mm1
            log_m, sign_m = monodromy_factor(log_m, sign_m, mm1)
            u = U2
        first = False
        g = u - u0
        one_minus_M = one_minus_monodromy(log_m, sign_m)
        if not (math.isfinite(g) and one_minus_M != 0.0 and math.isfinite(one_minus_M)):
            return math.nan, math.nan, u0, NON_FINITE, it_out, stage_its
        if abs(g) <= tol_fix * abs(one_minus_M):
            status = CONVERGED
            break
        u0, lo, hi = bracketed_newton_update(u0, g, one_minus_M, lo, hi)
    if status == CONVERGED and not (abs(u0) < 0.999 * bound):
        status = NOT_PERIODIC  # converged onto the edge of the bracket: no fixed point inside
    if status != CONVERGED:
        return math.nan, math.nan, u0, status, it_out, stage_its
    # the converged sweep starts |d| <= tol_fix short of the fixed point, d = g / (1 - M):
    # shift it along the sweep to first order (the offset left is O(d^2)).  Unshifted, d
    # carried into int u about one for one, and tol_fix is a full rtol of the smallest norm
    # of int u (1e-3 V); the bisected grid starts from its coarse partner's u(0), so both
    # shared the offset and Richardson did not see it (a Fourier point was 25x over its
    # estimate at rtol 1e-6)
    shift = g / one_minus_M
    u0 += shift
    for n in range(N):
        u_start[n] += shift
        for i in (2 * n, 2 * n + 1):
            stages[i] += sens[i] * shift
            powers[i] += powers_u[i] * sens[i] * shift
        shift *= 1.0 + m_minus_1[n]
    # quadrature of the converged sweep with the Radau weights (order 3)
    int_u = 0.0
    int_pi = 0.0
    for n in range(N):
        U1 = stages[2 * n]
        U2 = stages[2 * n + 1]
        P1 = powers[2 * n]
        P2 = powers[2 * n + 1]
        step_u[n] = hs[n] * (0.75 * U1 + 0.25 * U2)
        step_pi[n] = hs[n] * (0.75 * P1 + 0.25 * P2)
        int_u += step_u[n]
        int_pi += step_pi[n]
        u_out[n] = u_start[n]
        step_m[n] = 1.0 + m_minus_1[n]
    if stages_out is not None and stages_out.size >= 2 * N:
        stages_out[:2 * N] = stages
    if weights_out is not None:
        for n in range(N):  # d(step integral of u)/du_n, with dU_i/du_n from the last sweep
            weights_out[n] = hs[n] * (0.75 * sens[2 * n] + 0.25 * sens[2 * n + 1])
        if step_weights_out is not None:
            step_weights_out[:N] = weights_out[:N]
        node_weights(weights_out[:N], step_m, one_minus_M)
    return int_u, int_pi, u0, CONVERGED, it_out, stage_its


@njit(cache=True, parallel=True, error_model="numpy")
def solve_points(code, params, grids, n_steps, kappa, mu_n, mu_s, p, dtau, u0, vscale, rtol):
    """Batched ``solve_point_on_grid`` over parameter points (one thread per point).

    ``grids`` has shape (n, max_steps + 1), row i valid up to ``n_steps[i]`` steps.
    """
    n, m = grids.shape
    int_u, int_pi, u0_out, status, its, stage_its, step_u, step_pi, step_m, nodes = \
        batch_outputs(n, m)
    for i in prange(n):
        int_u[i], int_pi[i], u0_out[i], status[i], its[i], stage_its[i] = solve_point_on_grid(
            code, params[i], grids[i], n_steps[i], kappa[i], mu_n[i], mu_s[i], p[i], dtau[i],
            u0[i], vscale[i], rtol, nodes[i], step_u[i], step_pi[i], step_m[i])
    return int_u, int_pi, u0_out, status, its, step_u, step_pi, step_m, nodes


@njit(cache=True, error_model="numpy")
def collocation_value(theta, u_n, U1, U2):
    """The quadratic collocation polynomial of a Radau step at theta = (t - t_n) / h_n:
    through (0, u_n), (1/3, U1), (1, U2)."""
    return (3.0 * (theta - 1.0 / 3.0) * (theta - 1.0) * u_n
            - 4.5 * theta * (theta - 1.0) * U1 + 1.5 * theta * (theta - 1.0 / 3.0) * U2)


@njit(cache=True, error_model="numpy")
def collocation_guess(grid, N, old_grid, old_N, old_nodes, old_stages, guess):
    """Stage values on ``grid`` from a solution on another grid of the period: at each stage
    time, the quadratic collocation polynomial of the old step that contains it (through
    (0, u_k), (1/3, U1_k), (1, U2_k) in theta = (t - t_k) / h_k)."""
    k = 0
    for n in range(N):
        h = grid[n + 1] - grid[n]
        for q in range(2):
            t = grid[n] + h / 3.0 if q == 0 else grid[n + 1]
            while k < old_N - 1 and old_grid[k + 1] < t:
                k += 1
            theta = (t - old_grid[k]) / (old_grid[k + 1] - old_grid[k])
            guess[2 * n + q] = collocation_value(theta, old_nodes[k], old_stages[2 * k],
                                                 old_stages[2 * k + 1])


@njit(cache=True, parallel=True, error_model="numpy")
def solve_pairs(code, params, grids, n_steps, kappa, mu_n, mu_s, p, dtau, u0, vscale, rtol,
                old_grids, old_steps, old_nodes, old_stages):
    """``solve_points`` for rows that come in pairs: row 2j a grid, row 2j + 1 its bisection.

    The bisected grid's shooting starts from the coarse grid's u(0) and its first sweep
    from the coarse collocation polynomials: its stage Newton then starts O(h^3) close
    instead of O(h) (u_n).  The coarse grid's first sweep starts likewise from pair j's
    previous solution where ``old_steps[j]`` > 0 (the old_* rows: its grid, node values and
    stages).  Both guesses are ``collocation_guess``.  One thread per pair.

    Returns the arrays of ``solve_points``, the stages of every row (n, 2 (m - 1)),
    written for the converged rows, and the node weights (``node_weights``) of the
    converged bisected rows (n, m - 1; NaN elsewhere).
    """
    n, m = grids.shape
    if n % 2:
        raise ValueError("grids: solve_pairs needs rows in (grid, bisection) pairs")
    int_u, int_pi, u0_out, status, its, stage_its, step_u, step_pi, step_m, nodes = \
        batch_outputs(n, m)
    stages = np.empty((n, 2 * (m - 1)))
    weights = np.full((n, m - 1), np.nan)
    step_weights = np.full((n, m - 1), np.nan)
    for j in prange(n // 2):
        c = 2 * j
        f = c + 1
        N = n_steps[c]
        guess = np.empty(2 * N)
        if old_steps[j] > 0:
            collocation_guess(grids[c], N, old_grids[j], old_steps[j], old_nodes[j],
                              old_stages[j], guess)
            guess_c = guess
        else:
            guess_c = guess[:0]  # cold
        int_u[c], int_pi[c], u0_out[c], status[c], its[c], stage_its[c] = solve_point_on_grid(
            code, params[c], grids[c], N, kappa[c], mu_n[c], mu_s[c], p[c], dtau[c],
            u0[c], vscale[c], rtol, nodes[c], step_u[c], step_pi[c], step_m[c], stages[c],
            guess_c)
        start = u0[f]
        guess_f = guess[:0]
        if status[c] == CONVERGED and n_steps[f] == 2 * N:
            guess_f = np.empty(4 * N)
            collocation_guess(grids[f], 2 * N, grids[c], N, nodes[c], stages[c], guess_f)
            start = u0_out[c]
        int_u[f], int_pi[f], u0_out[f], status[f], its[f], stage_its[f] = solve_point_on_grid(
            code, params[f], grids[f], n_steps[f], kappa[f], mu_n[f], mu_s[f], p[f],
            dtau[f], start, vscale[f], rtol, nodes[f], step_u[f], step_pi[f], step_m[f],
            stages[f], guess_f, None, weights[f], step_weights[f])
    return (int_u, int_pi, u0_out, status, its, step_u, step_pi, step_m, nodes, stages, weights,
            step_weights)
