"""Turning points of phi: a check of the steps next to them that Richardson cannot make.

Where omega = dphi/dtau vanishes (a turning point tau_z of the motion) the links stop
rotating.  Near it the link velocities are u and ~ omega'(tau_z) (tau - tau_z) s, and
the force law is homogeneous in the velocity (degree p, up to delta_tau), so F(u, tau)
changes by O(mu) across a window of width w ~ |u(tau_z)| / |omega'(tau_z)| around tau_z:
(tau_z, u = 0) is a singular point of eq. (Newtonu).  A step much longer than w that
samples F inside the window (a node on tau_z, where a Radau stage sees omega = 0 and the
whole link sliding one way: full friction) makes an O(T^(2-p) mu h) error in u, and its
implicit stage can stop the body there.  A grid and its bisection then share one wrong
solution, and their comparison is blind to it.  Measured (harmonic A0 1.0599, A1 0.5407,
anisotropy 0.119, scaled period 0.088, delta 1e-8): rtol 1e-3 returned U = -0.02308
with an estimate of 2.5e-4 against the true -0.015694; the grids held u = 4e-10 at
tau_z = 1/2 where the solution passes at 6.6e-4, and uniform grids stayed trapped up to
~1,000 steps.

The check, on the solution a refinement pass would accept.  Turning points are the sign
changes of omega at SAMPLES points per step (so two zeros in one step are seen), located by
regula falsi, and the near-tangencies, where |omega| has an interior minimum below
TANGENCY |u| (the window opens without a zero).  Each gets its window half-width, where
|omega| reaches max(|u|, delta_tau) (``window_width``, by bisection: any order of zero).
For each step within its own length of a turning point, the defect of its collocation
polynomial u_h (through u_n, U1, U2 at theta = 0, 1/3, 1),

    D_n = u_{n+1} - u_n - T^(2-p) int_step F(u_h(tau), tau) dtau,

is the error the step makes in u: the collocation conditions make the Radau weights'
quadrature of that integral exact up to the stage Newton's residual, so D_n is the
quadrature error of F along u_h.  The integral is taken by 4-point Gauss-Legendre panels
graded geometrically toward tau_z down to WINDOW_FRACTION of the window (``step_defect``),
so it resolves the window the step does not (to ~1e-6 of T^(2-p) mu h at a simple zero;
kinks of F inside a panel limit it to ~1e-3 of D_n at a triple zero).  Weighted by the node
weight lambda_{n+1} (``_periodic.node_weights``, the sensitivity of int u to a jump of u
there) |D_n lambda_{n+1}| is the step's error in int u, linearised (a dual-weighted
residual).  For the Radau stages u_{n+1} - u_n is replaced by the rule's quadrature of F, so
that the stage Newton's residual, which every step carries (up to its tolerance,
``_periodic.stage_tolerance``), is not counted: at a corner turning point where the body
rests, lambda reached 9e18 and made a 1e-14 residual 7e8 rtol.  Defects within
ROUNDING_FACTOR times their own rounding error are not counted either (the same corner,
refined: lambda 7e35, D_n 4e-29).  (Until session 9 defects below the stage tolerance were
dropped instead; with that tolerance at 1e-5 rtol V and weights of ~800 at short periods,
it dropped trapped steps' defects of 3e-9 worth 2.6 rtol.)  The node weights are those of
the resolved problem (``_resolved_weights``).  The march passes pseudo-stages on which u_h
is its linear interpolant (``_march._check_inputs``); D_n is then the defect of that
interpolant, which also holds Heun's ordinary local error (counted by Richardson too:
twice, conservatively).  Measured on a clapping Fourier point whose march was 16 rtol off
at rtol 1e-7 with nothing flagged: the check estimated 1.5-3x its true errors.

The sum of |D_n lambda_{n+1}|, relative to the norm of U (``_solve``), is added to the error
estimate; the steps holding the most of it (each above FLAG_SHARE rtol, and the largest
until the rest is below FLAG_REST rtol) get nodes graded toward tau_z.

Layers after corners of phi (the power law's tau = 0 and tau0, Radau stages only).  At a
corner omega jumps, so does the quasi-static velocity, and u relaxes to it across a layer of
width ~ 1 / (T^(2-p) |dF/du|).  A step far longer than that (at long periods, where
T^(2-p) is large) holds an area of u that none of its stages samples, nor its bisection's:
both miss it alike.  Measured: ``tests/test_study.py``'s power_law_period_113 (scaled period
113), rtol 1e-3, 12.7 rtol off with an estimate of 0.5, the layer (width ~1e-5) inside a
step of 1e-3 whose own integral of u held the whole error; the turning-point check did not
see it, as omega changes sign at a node there, not inside a step.  So the first LAYER_STEPS
steps within LAYER_REACH after each corner (and before the next) whose fastest rate times h
exceeds LAYER_STIFFNESS (tiny steps before them resolve their part) are solved again on
sub-steps growing geometrically from the layer's width (``corner_layer_error``); the change
of the step's integral of u plus lambda_{n+1} times the change of its end value is its
error, added like D_n lambda_{n+1} (and in place of it, which the stiff step's damping makes
300x too large there).  Consecutive layer steps are re-solved as one stretch, each from
where the re-solve of the one before ended, and only the last end is weighted by lambda: a
jump of u into a stuck region is not linear (on power_law_ratio_4096 a stage on a spurious
stuck root ended a step 1.8 short, lambda after it was 3e-9, and the stop it moved cost
48 rtol).  A flagged layer step grades nodes forward from the start of its stretch down to
the width of the stretch's first step.  On 2 x 300 long-period power-law points
(scaled period 4 .. 256, delta 1e-10 .. 1e-5) the worst error went from 17 / 36 rtol to
0.55 / 0.96 at rtol 1e-3, 45 / 0.53 to 0.39 / 0.53 at 1e-4 and 0.51 / 3.5 to 0.51 / 0.55
at 1e-5, n_tau within 1 %.

The check covers U only.  P's error in the trapped solutions was small: the point above,
0.007 rtol; the session-4 point B (rtol 1e-5), 0.15 rtol; and over the 2000 benchmark points
at rtol 1e-4, whose worst U was 27.7 rtol, the worst P was 0.16 rtol: P is a relative error
of a quantity the whole period contributes to, while U's norm can be as small as 1e-3 V.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._events import illinois_update, radau_step_from
from ._force import force_and_slope
from ._kinematics import FOURIER, angle_and_rate
from ._periodic import collocation_value, monodromy_factor, node_weights, one_minus_monodromy

_x4, _w4 = np.polynomial.legendre.leggauss(4)
GL4_NODES = 0.5 * (_x4 + 1.0)
GL4_WEIGHTS = 0.5 * _w4

#: panels are graded toward tau_z down to this fraction of the window w
WINDOW_FRACTION = 0.125
#: ... and never below this fraction of the step
MIN_PANEL_FRACTION = 1e-14
#: a step whose weighted defect exceeds this share of rtol is graded toward tau_z ...
FLAG_SHARE = 0.1
#: ... and so are the largest until the others hold at most this share of rtol
FLAG_REST = 0.25
#: a defect within this many times its own rounding error (``step_defect``) is noise
ROUNDING_FACTOR = 1e3
_EPS = float(np.finfo(np.float64).eps)
#: a step after a corner of phi (the power law's tau = 0 and tau0) is solved again on graded
#: sub-steps (``corner_layer_error``) when its fastest relaxation rate times h exceeds this:
#: a layer shorter than the step, which the step and its bisection both miss ...
LAYER_STIFFNESS = 4.0
#: ... the first LAYER_STEPS such steps among the LAYER_SEARCH after the corner (and before
#: the next one) ...
LAYER_STEPS = 8
LAYER_SEARCH = 64
#: ... that start within this distance of the corner (a layer's longest measured reach,
#: a slide to a stop after tau = 0, was 4.4e-4; past it a stiff step's stage on the corner
#: at tau = 1, 0.9 later, was taken for one and its defect left unchecked) ...
LAYER_REACH = 2.0 ** -10
#: ... the first sub-step is this fraction of the layer's width ...
LAYER_FIRST_FRACTION = 0.125
#: ... and the sub-steps' stage tolerance this times rtol times the norm of int u, at least
#: LAYER_ROUNDING times the rounding of u (|u| reached 250 times that norm at rtol 1e-3:
#: below its rounding, a sub-step's Newton failed and the estimate became inf)
LAYER_TOLERANCE = 1e-9
LAYER_ROUNDING = 16.0
#: at most this many flagged steps per point are returned
MAX_FLAGGED = 32
#: omega is sampled at this many equal sub-steps of each step (two zeros in one step)
SAMPLES = 4
#: an interior minimum of |omega| below this many |u| opens a window without a zero
TANGENCY = 4.0
#: at most this many turning points per period are checked
MAX_TURNING_POINTS = 256
#: the window is not searched beyond this distance from tau_z
MAX_WINDOW = 0.25


@njit(cache=True, error_model="numpy")
def _rate(code, params, t, side):
    return angle_and_rate(code, params, t, side)[1]


@njit(cache=True, error_model="numpy")
def zero_of_rate(code, params, t0, t1, w0, w1, side):
    """A zero of omega in [t0, t1] given omega(t0) = w0, omega(t1) = w1 of opposite signs
    (or one of them 0): Illinois regula falsi."""
    if w0 == 0.0:
        return t0
    if w1 == 0.0:
        return t1
    a, b, fa, fb = t0, t1, w0, w1
    c = a
    last = 0
    for _ in range(100):
        c = (a * fb - b * fa) / (fb - fa)
        if not (a < c < b) or b - a <= 1e-15 * max(1.0, abs(c)):
            c = min(max(c, a), b)
            break
        fc = _rate(code, params, c, side)
        if fc == 0.0:
            break
        a, b, fa, fb, last = illinois_update(a, b, fa, fb, c, fc, last)
    return c


@njit(cache=True, error_model="numpy")
def _panel(code, params, t0, h, a, b, u_n, U1, U2, side, mu_n, mu_s, p, dtau):
    """(int_a^b F, int_a^b dF/du, int_a^b |F|) along u_h(tau) by 4-point Gauss-Legendre."""
    force = 0.0
    slope = 0.0
    size = 0.0
    for i in range(4):
        t = a + (b - a) * GL4_NODES[i]
        phi, om = angle_and_rate(code, params, t, side)
        u = collocation_value((t - t0) / h, u_n, U1, U2)
        F, F_u = force_and_slope(u, phi, om, mu_n, mu_s, p, dtau)
        force += GL4_WEIGHTS[i] * F
        slope += GL4_WEIGHTS[i] * F_u
        size += GL4_WEIGHTS[i] * abs(F)
    return (b - a) * force, (b - a) * slope, (b - a) * size


@njit(cache=True, error_model="numpy")
def step_defect(code, params, t0, t1, u_n, U1, U2, tz, window, kappa, mu_n, mu_s, p, dtau,
                collocated):
    """D_n of the module docstring for the step [t0, t1] with stages U1, U2, the panels
    graded toward the point of the step nearest to the zero tz of omega, down to
    WINDOW_FRACTION of its ``window`` (``window_width``); and on the same panels the log of
    the step's resolved factor, T^(2-p) int_step dF/du(u_h(tau), tau) dtau (the variational
    equation along u_h, ``_resolved_weights``).  ``collocated`` (Radau stages): u_{n+1} - u_n
    is taken as the Radau rule's T^(2-p) h (3 F(U1) + F(U2)) / 4, which it is up to the stage
    Newton's residual, so D_n is the rule's quadrature error alone.

    Returns (D_n, log of the resolved factor, number of panels, rounding): ``rounding`` is
    D_n's own rounding error, ~eps times the magnitudes of the terms it is formed from."""
    h = t1 - t0
    side = t0 + 0.5 * h
    centre = min(max(tz, t0), t1)
    smallest = max(WINDOW_FRACTION * window, 0.125 * abs(centre - tz), MIN_PANEL_FRACTION * h)
    force = 0.0
    slope = 0.0
    size = 0.0
    panels = 0
    for direction in (-1.0, 1.0):
        far = t1 - centre if direction > 0.0 else centre - t0
        outer = far
        while outer > 0.0:
            inner = 0.5 * outer if 0.5 * outer > smallest else 0.0
            a = centre + direction * inner
            b = centre + direction * outer
            if direction < 0.0:
                a, b = b, a
            F, F_u, F_abs = _panel(code, params, t0, h, a, b, u_n, U1, U2, side, mu_n, mu_s, p,
                                   dtau)
            force += F
            slope += F_u
            size += F_abs
            panels += 1
            outer = inner
    change = U2 - u_n
    magnitude = abs(U2) + abs(u_n)
    if collocated:
        phi1, om1 = angle_and_rate(code, params, t0 + h / 3.0, side)
        phi2, om2 = angle_and_rate(code, params, t1, side)
        F1 = force_and_slope(U1, phi1, om1, mu_n, mu_s, p, dtau)[0]
        F2 = force_and_slope(U2, phi2, om2, mu_n, mu_s, p, dtau)[0]
        change = kappa * h * (0.75 * F1 + 0.25 * F2)
        magnitude = kappa * h * (0.75 * abs(F1) + 0.25 * abs(F2))
    rounding = _EPS * (magnitude + kappa * size)
    return change - kappa * force, kappa * slope, panels, rounding


@njit(cache=True, error_model="numpy")
def window_width(code, params, tz, level):
    """The half-width of the window around the zero tz of omega: the smaller distance, on
    either side, at which |omega| reaches ``level`` (|u(tz)|, at least delta_tau), by
    bisection in log distance (any order of zero, and one-sided zeros at corners of phi);
    at most MAX_WINDOW."""
    width = MAX_WINDOW
    for direction in (-1.0, 1.0):
        far = MAX_WINDOW
        t = tz + direction * far
        if abs(_rate(code, params, t, tz + 0.5 * direction * far)) < level:
            continue
        near = 1e-15
        for _ in range(60):
            mid = math.sqrt(near * far)
            t = tz + direction * mid
            if abs(_rate(code, params, t, tz + 0.5 * direction * mid)) < level:
                near = mid
            else:
                far = mid
            if far <= 1.01 * near:
                break
        width = min(width, far)
    return width


@njit(cache=True, error_model="numpy")
def rate_slope_bound(code, params):
    """A bound on |d omega / d tau| over the period: sum_k (2 pi k)^2 (|A_k| + |B_k|) for the
    Fourier encoding; inf for the power law (omega' is unbounded at a corner for exponents
    below 2)."""
    if code != FOURIER:
        return math.inf
    K = int(params[0])
    bound = 0.0
    for k in range(1, K + 1):
        bound += (2.0 * math.pi * k) ** 2 * (abs(params[1 + k]) + abs(params[K + 1 + k]))
    return bound


@njit(cache=True, error_model="numpy")
def _differ(a, b):
    """omega changes sign (or vanishes) between the values a and b."""
    return a == 0.0 or b == 0.0 or (a < 0.0) != (b < 0.0)


@njit(cache=True, error_model="numpy")
def _turning_points(code, params, grid, N, u_nodes, stages, dtau, out):
    """Zeros of omega (sign changes between SAMPLES points of each step, omega one-sided
    from inside the step) and near-tangencies (an interior minimum of |omega| below
    TANGENCY |u|, where the window opens without a zero), with their windows.

    Writes rows (tz, window) into ``out``; returns their number (sorted by tz)."""
    count = 0
    values = np.empty(SAMPLES + 1)
    times = np.empty(SAMPLES + 1)
    slope = rate_slope_bound(code, params)
    for n in range(N):
        t0 = grid[n]
        h = grid[n + 1] - t0
        side = t0 + 0.5 * h
        times[0] = t0
        times[SAMPLES] = grid[n + 1]
        values[0] = _rate(code, params, t0, side)
        values[SAMPLES] = _rate(code, params, grid[n + 1], side)
        # |omega| >= (|omega(t0)| + |omega(t1)| - slope h) / 2 on the step: where that stays
        # above TANGENCY |u| (|u| on the step <= 2 max |u_n|, |U1|, |U2|: the collocation
        # quadratic's Lebesgue constant is ~1.7), the samples could find nothing
        u_bound = 2.0 * max(abs(u_nodes[n]), abs(stages[2 * n]), abs(stages[2 * n + 1]))
        if abs(values[0]) + abs(values[SAMPLES]) - slope * h > 2.0 * TANGENCY * max(u_bound,
                                                                                  dtau):
            continue
        for k in range(1, SAMPLES):
            times[k] = t0 + h * k / SAMPLES
            values[k] = _rate(code, params, times[k], side)
        found = False
        for k in range(SAMPLES):
            if _differ(values[k], values[k + 1]):
                found = True
                tz = zero_of_rate(code, params, times[k], times[k + 1], values[k],
                                  values[k + 1], side)
                if _add_turning_point(code, params, grid, n, u_nodes, stages, dtau, tz, out,
                                      count):
                    count += 1
        if found:
            continue
        for k in range(1, SAMPLES):
            a = abs(values[k])
            if a < abs(values[k - 1]) and a < abs(values[k + 1]):
                u = collocation_value((times[k] - t0) / h, u_nodes[n], stages[2 * n],
                                      stages[2 * n + 1])
                if a <= TANGENCY * max(abs(u), dtau) and _add_turning_point(
                        code, params, grid, n, u_nodes, stages, dtau, times[k], out, count):
                    count += 1
    return count


@njit(cache=True, error_model="numpy")
def _add_turning_point(code, params, grid, n, u_nodes, stages, dtau, tz, out, count):
    """Row (tz, window) at ``count`` unless tz repeats the previous row or ``out`` is full."""
    if count >= out.shape[0] or (count > 0 and tz <= out[count - 1, 0]):
        return False
    h = grid[n + 1] - grid[n]
    u = collocation_value((tz - grid[n]) / h, u_nodes[n], stages[2 * n], stages[2 * n + 1])
    out[count, 0] = tz
    out[count, 1] = window_width(code, params, tz, max(abs(u), dtau))
    return True


@njit(cache=True, error_model="numpy")
def _resolved_weights(step_weights, step_m, N, steps, log_factors, count):
    """The node weights lambda (``_periodic.node_weights``) with the factors m_n of the
    ``count`` steps ``steps`` replaced by their resolved ones, exp(``log_factors``).

    The discrete factor of a step that samples F inside a turning-point window holds the
    discretisation's error: a stage on tau_z with the body at rest sees the full stiffness
    T^(2-p) mu / delta_tau there and damps a perturbation (m = 0.32 on the point of
    ``tests/test_study.py::test_trapped_turning_point_at_short_period_is_seen``) that the
    resolved window passes almost unchanged (0.9996), so the discrete 1 - M (0.68) hid the
    solution's weak hold on its mean (1 - M = 0.0017) and lambda, 1.5 instead of 587, hid a
    40 rtol error as 0.14 rtol."""
    m_minus_1 = np.empty(N)
    for n in range(N):
        m_minus_1[n] = step_m[n] - 1.0
    for r in range(count):
        m_minus_1[steps[r]] = math.expm1(log_factors[r])
    log_m = 0.0
    sign_m = 1.0
    for n in range(N):
        log_m, sign_m = monodromy_factor(log_m, sign_m, m_minus_1[n])
    weights = step_weights[:N].copy()
    node_weights(weights, 1.0 + m_minus_1, one_minus_monodromy(log_m, sign_m))
    return weights


@njit(cache=True, error_model="numpy")
def layer_rate(code, params, t0, t1, u_n, U1, U2, kappa, mu_n, mu_s, p, dtau):
    """The fastest relaxation rate T^(2-p) |dF/du| of the step [t0, t1] at u_n (just after
    t0) and at its stages: the inverse width of a layer that starts at t0."""
    h = t1 - t0
    side = t0 + 0.5 * h
    rate = 0.0
    for t, u in ((t0, u_n), (t0 + h / 3.0, U1), (t1, U2)):
        phi, om = angle_and_rate(code, params, t, side)
        rate = max(rate, kappa * abs(force_and_slope(u, phi, om, mu_n, mu_s, p, dtau)[1]))
    return rate


@njit(cache=True, error_model="numpy")
def corner_layer_error(code, params, t0, t1, u_start, U1, U2, width, weight_next, kappa, mu_n,
                       mu_s, p, dtau, atol):
    """The error in int u of the Radau step [t0, t1] (stages U1, U2) that a corner of phi's
    layer, of ``width`` (1 / ``layer_rate``), may reach.

    The step is solved again from ``u_start`` (its u_n, or where the re-solve of the step
    before ended) on sub-steps growing geometrically (ratio 2) from LAYER_FIRST_FRACTION of
    the width at t0, to stage tolerance ``atol``.  Returns (error, end value of the re-solve):
    error is the change of the step's integral of u plus ``weight_next`` (lambda_{n+1}, or 0
    where the next step is re-solved from this one's end) times the change of its end value;
    NaN where a sub-step fails.  A layer far shorter than the step holds an area of u that no
    Radau stage samples: the step's own integral of u misses it, and the grid's bisection,
    whose stages miss it too, agrees (12.7 rtol off at rtol 1e-3 with an estimate of 0.5 on
    ``tests/test_study.py``'s power_law_period_113)."""
    h = t1 - t0
    first = max(LAYER_FIRST_FRACTION * width, MIN_PANEL_FRACTION * h)
    integral = 0.0
    u = u_start
    a = t0
    d = first
    while a < t1:
        b = a + d
        if b + d > t1:  # the last sub-step takes the rest (at most 2 d)
            b = t1
        q, u, ok = radau_step_from(u, a, b, code, params, kappa, mu_n, mu_s, p, dtau, atol)
        if not ok:
            return math.nan, math.nan
        integral += q
        a = b
        d *= 2.0
    return integral - h * (0.75 * U1 + 0.25 * U2) + weight_next * (u - U2), u


@njit(cache=True, error_model="numpy")
def corner_layers(code, params, grid, N, u_nodes, stages, corners, kappa, mu_n, mu_s, p, dtau,
                  steps, widths, first):
    """The steps after each corner of phi that may hold its layer: among the first
    LAYER_SEARCH steps that start within LAYER_REACH of it, the first LAYER_STEPS whose
    fastest relaxation rate times h exceeds LAYER_STIFFNESS (a layer shorter than the step;
    the shorter steps before them resolve theirs), and not beyond the next corner.  Writes
    them into ``steps`` with their layer widths (1 / rate), in order, and marks each corner's
    first one in ``first``; returns their number."""
    count = 0
    for c in corners:
        n0 = np.searchsorted(grid[:N + 1], c)
        if n0 >= N or abs(grid[n0] - c) > 1e-12:
            continue
        end = min(n0 + LAYER_SEARCH, N)
        for c2 in corners:  # (the next corner's layer is its own)
            n2 = np.searchsorted(grid[:N + 1], c2)
            if n0 < n2 < end:
                end = n2
        found = 0
        for n in range(n0, end):
            if grid[n] - c > LAYER_REACH:
                break  # (a stiff step far after the corner is no layer's: a stop, say)
            rate = layer_rate(code, params, grid[n], grid[n + 1], u_nodes[n], stages[2 * n],
                              stages[2 * n + 1], kappa, mu_n, mu_s, p, dtau)
            if rate * (grid[n + 1] - grid[n]) > LAYER_STIFFNESS:
                steps[count] = n
                widths[count] = 1.0 / rate
                first[count] = found == 0
                count += 1
                found += 1
                if found == LAYER_STEPS:
                    break
    return count


@njit(cache=True, error_model="numpy")
def _point_check(code, params, grid, N, u_nodes, stages, step_m, step_weights, kappa, mu_n,
                 mu_s, p, dtau, scale_u, rtol, min_step, collocated, corners, flagged):
    """Returns (estimate, number of flagged steps); flagged rows (tz, target step, reach)."""
    zeros = np.empty((MAX_TURNING_POINTS, 2))
    n_zeros = _turning_points(code, params, grid, N, u_nodes, stages, dtau, zeros)
    layer_steps = np.empty(LAYER_STEPS * corners.size, dtype=np.int64)
    widths = np.empty(LAYER_STEPS * corners.size)
    first = np.empty(LAYER_STEPS * corners.size, dtype=np.bool_)
    n_layers = 0
    if collocated:
        n_layers = corner_layers(code, params, grid, N, u_nodes, stages, corners, kappa, mu_n,
                                 mu_s, p, dtau, layer_steps, widths, first)
    if n_zeros == 0 and n_layers == 0:
        return 0.0, 0
    defects = np.empty(N)
    log_factors = np.empty(N)
    checked = np.empty(N, dtype=np.int64)
    # per row (turning-point steps, then layer steps): the node tz to grade toward, the
    # step it is checked in, and how far from tz the grading reaches
    row_tz = np.empty(N + n_layers)
    row_h = np.empty(N + n_layers)
    row_reach = np.empty(N + n_layers)
    n_checked = 0
    k = 0
    for n in range(N if n_zeros > 0 else 0):
        t0 = grid[n]
        t1 = grid[n + 1]
        h = t1 - t0
        while k + 1 < n_zeros and zeros[k + 1, 0] <= t0:
            k += 1
        best = -1
        distance = math.inf
        shift = 0.0
        for cand, offset in ((k, 0.0), (min(k + 1, n_zeros - 1), 0.0), (0, 1.0),
                             (n_zeros - 1, -1.0)):
            tz = zeros[cand, 0] + offset
            d = max(tz - t1, t0 - tz, 0.0)
            if d < distance:
                distance, best, shift = d, cand, offset
        if distance > h or n in layer_steps[:n_layers]:
            continue  # (a layer step, re-solved below: that holds what D_n measures)
        defect, log_factor, _, rounding = step_defect(
            code, params, t0, t1, u_nodes[n], stages[2 * n], stages[2 * n + 1],
            zeros[best, 0] + shift, zeros[best, 1], kappa, mu_n, mu_s, p, dtau, collocated)
        if abs(defect) <= ROUNDING_FACTOR * rounding:
            # rounding noise, not a quadrature error: where the body rests at a corner of
            # phi (u 1e-87, exponents 20) the linearised weights reach 7e35 and made a
            # D_n of 4e-29 (its rounding) an estimate of 1e16 rtol
            defect = 0.0
        defects[n_checked] = defect
        log_factors[n_checked] = log_factor
        checked[n_checked] = n
        row_tz[n_checked] = zeros[best, 0]
        row_h[n_checked] = h
        row_reach[n_checked] = distance + h
        n_checked += 1
    # the error of int u is sum D_n lambda_{n+1}, lambda the weights of the resolved problem
    weights = _resolved_weights(step_weights, step_m, N, checked, log_factors, n_checked)
    shares = np.empty(n_checked + n_layers)
    for r in range(n_checked):
        n = checked[r]
        lam = weights[n + 1] if n + 1 < N else weights[0]
        shares[r] = abs(defects[r] * lam) / scale_u if defects[r] != 0.0 else 0.0
    start = 0.0
    width = 0.0
    carried = math.nan
    for j in range(n_layers):
        r = n_checked + j
        n = layer_steps[j]
        # consecutive layer steps are re-solved as one stretch: the error at a step's end is
        # carried by the re-solve, not weighted by lambda_{n+1}, which is linear (a stage
        # stuck on a spurious root, 1.8 short, had lambda 3e-9 after it, and the triangle of
        # u it lost was 48 rtol on power_law_ratio_4096)
        follows = not first[j] and layer_steps[j - 1] == n - 1
        if not follows:  # a stretch starts
            start = grid[n]
            width = widths[j]
        chained = follows and math.isfinite(carried)
        goes_on = j + 1 < n_layers and not first[j + 1] and layer_steps[j + 1] == n + 1
        magnitude = max(abs(u_nodes[n]), abs(stages[2 * n]), abs(stages[2 * n + 1]))
        error, carried = corner_layer_error(
            code, params, grid[n], grid[n + 1], carried if chained else u_nodes[n],
            stages[2 * n], stages[2 * n + 1], widths[j],
            0.0 if goes_on else (weights[n + 1] if n + 1 < N else weights[0]),
            kappa, mu_n, mu_s, p, dtau,
            max(LAYER_TOLERANCE * rtol * scale_u, LAYER_ROUNDING * _EPS * magnitude))
        shares[r] = abs(error) / scale_u
        # graded one-sided from the stretch's start down to its first step's width (a later
        # step's, in a stuck region, is the regularisation's, 100x finer)
        row_tz[r] = start
        row_h[r] = -max(width, min_step)  # (< 0: a layer row, its target step)
        row_reach[r] = grid[n + 1] - start
    estimate = 0.0
    for r in range(shares.size):
        if not math.isfinite(shares[r]):
            shares[r] = math.inf
        estimate += shares[r]
    return estimate, flag_rows(shares, estimate, row_tz, row_h, row_reach, rtol, min_step,
                               flagged)


@njit(cache=True, error_model="numpy")
def flag_rows(shares, estimate, row_tz, row_h, row_reach, rtol, min_step, flagged):
    """Flag the rows holding the largest ``shares`` (of the sum ``estimate``) until the rest
    holds at most FLAG_REST rtol, and any above FLAG_SHARE rtol, into ``flagged`` as
    (tz, target step, reach) for ``grade_towards``; returns their number.  ``row_h`` is
    the checked step's length, or minus the target step of a layer row."""
    order = np.argsort(-shares)
    rest = estimate
    count = 0
    for r in order:
        share = shares[r]
        # (share 0: what rest holds is the rounding of its sum, 1e14 of an estimate of 1e30;
        # its step target divided by zero)
        if (not (rest > FLAG_REST * rtol or share > FLAG_SHARE * rtol) or share == 0.0
                or count >= flagged.shape[0]):
            break
        rest -= share
        flagged[count, 0] = row_tz[r]
        if row_h[r] < 0.0:  # a layer: grade forward from its start down to its width
            flagged[count, 1] = row_h[r]
        else:  # in the trapped regime D_n ~ h: shrink the step in proportion
            flagged[count, 1] = max(row_h[r] * min(0.5, FLAG_SHARE * rtol / share), min_step)
        flagged[count, 2] = row_reach[r]
        count += 1
    return count


@njit(cache=True, parallel=True, error_model="numpy")
def turning_point_estimates(code, params, grids, n_steps, u_nodes, stages, step_m, step_weights,
                            kappa, mu_n, mu_s, p, dtau, scale_u, rtol, min_step, collocated,
                            corners):
    """The check of the module docstring for every row of a solved batch.

    grids (n, m), row i valid for n_steps[i] steps; u_nodes (n, >= N), stages (n, >= 2N),
    the step factors m_n = du_{n+1}/du_n and the step weights q_n = d(step integral of
    u)/du_n (``_periodic.node_weights``) (n, >= N) of the converged solutions;
    kappa = T^(2-p), mu_n, mu_s, p, dtau, scale_u (the norm of int u) : (n,); min_step: the
    smallest target step; collocated: the stages are Radau stages (``step_defect``), not the
    march's pseudo-stages; corners (n, k): the corners of phi (the power law's tau = 0 and
    tau0; k = 0 for the smooth families), whose layers are checked (Radau stages only).
    Returns (estimate (n,), flagged (n, MAX_FLAGGED, 3): rows (tz, target step, reach), NaN
    padded): estimate is sum |D_n lambda_{n+1}| / scale_u plus the layers' errors.
    """
    n = grids.shape[0]
    estimate = np.zeros(n)
    flagged = np.full((n, MAX_FLAGGED, 3), np.nan)
    for i in prange(n):
        estimate[i], _ = _point_check(code, params[i], grids[i], n_steps[i], u_nodes[i],
                                      stages[i], step_m[i], step_weights[i], kappa[i], mu_n[i],
                                      mu_s[i], p[i], dtau[i], scale_u[i], rtol, min_step,
                                      collocated, corners[i], flagged[i])
    return estimate, flagged


@njit(cache=True, error_model="numpy")
def grade_towards(grid, flagged, min_gap):
    """``grid`` with nodes at tz and tz +- target 2^k (k = 0, 1, ... while within reach of tz)
    for every flagged row (tz, target, reach); a negative target grades forward only, at
    tz + |target| 2^k (a layer after a corner).  A node within ``min_gap`` of another (of
    the grid, or added before it) is not added, so |targets| should exceed ``min_gap``."""
    extra = []
    for r in range(flagged.shape[0]):
        tz, target, reach = flagged[r, 0], flagged[r, 1], flagged[r, 2]
        if not math.isfinite(tz):
            continue
        extra.append(tz)
        d = abs(target)
        while d < reach:
            if target > 0.0:
                back = tz - d
                extra.append(back - math.floor(back))  # the period wraps
            ahead = tz + d
            extra.append(ahead - math.floor(ahead))
            d *= 2.0
    if len(extra) == 0:
        return grid
    candidates = np.sort(np.array(extra))
    out = np.empty(grid.size + candidates.size)
    out[:grid.size] = grid
    count = grid.size
    for t in candidates:
        pos = np.searchsorted(grid, t)
        near = math.inf
        if pos < grid.size:
            near = grid[pos] - t
        if pos > 0:
            near = min(near, t - grid[pos - 1])
        if near > min_gap and (count == grid.size or t - out[count - 1] > min_gap):
            out[count] = t
            count += 1
    return np.sort(out[:count])
