"""Where the force F(u, tau) is not smooth along a solution: events to put grid nodes on.

With the link velocity of ``_force`` (w(s) = a + b s normal, c tangential,
a = -S (u + omega S / 4), c = C (u + omega S / 4), b = omega), the s-integrand
has its kink at w = 0.  F(u(tau), tau) has a corner in tau (for p = 0 with
small delta_tau: a jump of dF/dtau over a width ~ delta_tau) when

- the kink crosses an end of the link: w(0) = a = 0, i.e. S = 0 or
  g = u + omega S / 4 = 0, or w(1/2) = a + omega / 2 = 0;
- the tangential velocity vanishes, c = 0, i.e. C = 0 or g = 0 (with the kink
  on the link a point of it is at rest and F has a u log u singularity).

Such a corner inside a step costs the step's order, and it is worse than that
for error control: the two stages of a Radau IIA step sit at 1/3 and 1 of it,
so a corner in the first sixth of a step is seen by neither the step nor its
bisection (stages at 1/6, 1/3, 2/3, 1), and comparing the two cannot detect
the error it makes.  Measured: harmonic A0 = 0.958, A1 = 0.622, anisotropy
2^-0.72, scaled period 0.414, where the corner w(1/2) = 0 at tau = 0.99825 sat
in the first tenth of a step on two consecutive grids: U off by 7e-4 with an
estimate of 2e-7.  Nodes placed on the events remove both problems.

The events are found on a solved grid as sign changes of the four functions S, C, g and
a + omega / 2 between nodes (and as stops: g ending a step in the friction's band,
STOP_PROBE, where its extrapolation crosses zero), and located in the step as the root
along the extrapolation of u from the step's left end (``_locate``); on the next grid
they are nodes (a nearby node is moved onto the event, or one is inserted), so each
refinement pass moves them to the newer solution's events.

Where the nodes put a stop steps before the extrapolation does, a stage stuck on a spurious
root of the step equations stopped u early (h T^(2-p) mu > |u_n|, mu up to mu_n when the
body sticks); the event goes where the extrapolation stops, and the error of the steps
between is measured by solving them again in short steps (``misplaced_stop_error``).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._force import force_and_slope
from ._kinematics import FOURIER, angle_and_rate
from ._periodic import radau_step

#: a step whose g = u + omega S / 4 ends within this many delta_tau of zero without changing
#: sign is probed for a stop (measured: a power-law point whose stuck g, -5e-15, kept the
#: slipping g's sign was accepted at rtol 1e-4 7.4 rtol off, its stop 4.6e-4 from a node)
STOP_PROBE = 10.0
#: at most this many events per period are placed (beyond it the rest are not; a Fourier
#: motion of Kmax = 10 has at most ~4 Kmax zeros of each of the four functions)
MAX_EVENTS = 256
#: how far past a step whose nodes put a stop in it ``_follow`` follows u's extrapolation to
#: its zero, in lengths of that step (a spurious stop came 2.3 steps early at mu_n/mu_s 3,020)
STOP_REACH = 4.0
#: ... and how far at least, in lengths of that step, the zero must lie past its end (closer
#: is an ordinary crossing near the node, which the secant of the node values places better:
#: 0.000-0.003 h off against 0.008-0.08 h, measured by a reviewer on six such events)
FOLLOW_MARGIN = 0.5


@njit(cache=True, error_model="numpy")
def _event_functions(u, phi, omega, out):
    S = math.sin(phi)
    out[0] = S
    out[1] = math.cos(phi)
    g = u + 0.25 * omega * S
    out[2] = g
    out[3] = -S * g + 0.5 * omega


@njit(cache=True, error_model="numpy")
def _event_function(k, u, phi, omega):
    S = math.sin(phi)
    if k == 0:
        return S
    if k == 1:
        return math.cos(phi)
    g = u + 0.25 * omega * S
    if k == 2:
        return g
    return -S * g + 0.5 * omega


@njit(cache=True, error_model="numpy")
def _extrapolated(k, code, params, t, side, t0, u0, slope, curve):
    """Event function k along u's extrapolation u0 + s x + c x^2 from t0 (x = t - t0)."""
    phi, om = angle_and_rate(code, params, t, side)
    x = t - t0
    return _event_function(k, u0 + x * (slope + curve * x), phi, om)


@njit(cache=True, error_model="numpy")
def _follow(code, params, grid, N, u_nodes, n, k, g1, t0, u0, slope, curve, f1, corners):
    """Where u's extrapolation from node n takes event function k (u-dependent, k >= 2)
    through zero after step n, whose nodes already change its sign: the bracket (a, b, fa,
    fb) in the step it reaches, or a = NaN where it does not count as a spurious stop.

    A stop forced early by a stage stuck on a spurious root of the step equations
    (h T^(2-p) mu > |u_n|, with mu up to mu_n when the body sticks) ends the step near
    zero where the extrapolation is still far from it.  Followed only while the nodes keep
    the sign they took after step n, up to a corner of phi, and into the steps that start
    within STOP_REACH lengths of step n past it (the steps after a bisected crossing step
    are often longer: a stop 2.97 h past it sat in a step ending 4.25 h past it, and
    stopping at the last whole step left it 2.83 rtol off); ``_locate`` then keeps the zero
    only if it lies more than FOLLOW_MARGIN of them past step n."""
    t1 = grid[n + 1]
    h = t1 - t0
    fa = f1
    j = n + 1
    while j < N and grid[j] < t1 + STOP_REACH * h:
        ta, tb = grid[j], grid[j + 1]
        for c in corners:
            if ta == c:
                return math.nan, math.nan, math.nan, math.nan
        node = u_nodes[j + 1] if j + 1 < N else u_nodes[0]
        phi, om = angle_and_rate(code, params, tb, 0.5 * (ta + tb))
        if _event_function(k, node, phi, om) * g1 < 0.0:
            break  # the nodes cross back: not one stop
        fb = _extrapolated(k, code, params, tb, 0.5 * (ta + tb), t0, u0, slope, curve)
        if not math.isfinite(fb):
            break
        if fa * fb < 0.0:
            return ta, tb, fa, fb
        fa = fb
        j += 1
    return math.nan, math.nan, math.nan, math.nan


@njit(cache=True, error_model="numpy")
def _locate(code, params, grid, N, u_nodes, n, k, g0, g1, physics, corners):
    """Root of event function k whose node values g0, g1 bracket it in step n (or, for a
    probe, g0 g1 > 0, that only may): (time, origin).

    Along the solution's extrapolation from the step's left end, u_n + s x + c x^2
    (x = tau - tau_n) with the one-sided slope s = T^(2-p) F(u_n, tau_n+) and c
    from u_{n-1} (dropped when phi has a corner at tau_n): the solution is smooth
    up to the event, not across it, so this is accurate to O(h^3) where the secant
    of the node values is not (at a stop, u has a corner exactly at the event).
    Illinois regula falsi on it when it brackets a root.  When it does not, but clearly
    does in a later step (``_follow``: a stop forced early), the root is there and origin
    is n; otherwise the secant of the node values (NaN for a probe), and origin -1.
    """
    kappa, mu_n, mu_s, p, dtau = physics[0], physics[1], physics[2], physics[3], physics[4]
    t0 = grid[n]
    t1 = grid[n + 1]
    mid = 0.5 * (t0 + t1)
    u0 = u_nodes[n]
    phi, om = angle_and_rate(code, params, t0, mid)
    slope = kappa * force_and_slope(u0, phi, om, mu_n, mu_s, p, dtau)[0]
    curve = 0.0
    m = n - 1 if n >= 1 else N - 1
    t_prev = grid[m] - (1.0 if n == 0 else 0.0)
    _, om_left = angle_and_rate(code, params, t0, 0.5 * (t_prev + t0))
    if N >= 2 and t_prev < t0 and abs(om_left - om) <= 1e-12 * (1.0 + abs(om)):
        x = t_prev - t0
        curve = (u_nodes[m] - u0 - slope * x) / (x * x)
        if abs(curve) * (grid[n + 1] - t0) > abs(slope):
            curve = 0.0  # u has a corner at tau_n (an event of the last pass): linear only
    f0 = g0
    f1 = _extrapolated(k, code, params, t1, mid, t0, u0, slope, curve)
    a, b, fa, fb = t0, t1, f0, f1
    origin = -1
    if not (f0 * f1 < 0.0 and math.isfinite(f1)):
        if g0 * g1 > 0.0:  # a probe (``_point_events``): no root along the extrapolation
            return math.nan, -1
        a = math.nan
        if k >= 2 and math.isfinite(f1):
            a, b, fa, fb = _follow(code, params, grid, N, u_nodes, n, k, g1, t0, u0, slope,
                                   curve, f1, corners)
        if not math.isfinite(a):
            return t0 + (t1 - t0) * g0 / (g0 - g1), -1
        mid = 0.5 * (a + b)
        origin = n
    side = 0
    c = a
    for _ in range(100):
        if fb == fa:
            break
        c = (a * fb - b * fa) / (fb - fa)
        if b - a <= 1e-15 * max(1.0, abs(c)):
            break
        fc = _extrapolated(k, code, params, c, mid, t0, u0, slope, curve)
        if fc == 0.0:
            break
        a, b, fa, fb, side = illinois_update(a, b, fa, fb, c, fc, side)
    if origin >= 0 and not c > t1 + FOLLOW_MARGIN * (t1 - t0):
        return t0 + (t1 - t0) * g0 / (g0 - g1), -1  # an ordinary crossing near the node
    return c, origin


@njit(cache=True, error_model="numpy")
def illinois_update(a, b, fa, fb, c, fc, last):
    """One bracket update of Illinois regula falsi: the new point c (value fc) replaces the
    end of [a, b] on its side, and the other end's value is halved when the same end was kept
    twice running (``last``: -1 when b was replaced, 1 when a was, 0 at the start).

    Returns (a, b, fa, fb, last)."""
    if fc * fa < 0.0:
        if last == -1:
            fa *= 0.5
        return a, c, fa, fc, -1
    if last == 1:
        fb *= 0.5
    return c, b, fc, fb, 1


@njit(cache=True, error_model="numpy")
def _point_events(code, params, grid, N, u_nodes, physics, corners, out, origins):
    """Event times in (grid[0], grid[N]) for u at the nodes ``u_nodes`` (u_N = u_0) into
    ``out``, and in ``origins`` the step whose nodes' crossing ``_locate`` followed to each
    (-1 where it did not); returns their count."""
    count = 0
    prev = np.empty(4)
    cur = np.empty(4)
    phi, om = angle_and_rate(code, params, grid[0], 0.5 * (grid[0] + grid[1]))
    _event_functions(u_nodes[0], phi, om, prev)
    for n in range(N):
        t0 = grid[n]
        t1 = grid[n + 1]
        # the right-end value seen from inside the step (the side of a corner of phi)
        phi, om = angle_and_rate(code, params, t1, 0.5 * (t0 + t1))
        u1 = u_nodes[n + 1] if n + 1 < N else u_nodes[0]
        _event_functions(u1, phi, om, cur)
        for k in range(4):
            crossing = prev[k] * cur[k] < 0.0
            # g ending the step stuck in the friction's band without changing sign: a stop
            # there is an event where g's extrapolation from the left node crosses zero
            probe = k == 2 and prev[k] * cur[k] > 0.0 and abs(cur[k]) < STOP_PROBE * physics[4]
            if (crossing or probe) and count < out.size:
                t, origin = _locate(code, params, grid, N, u_nodes, n, k, prev[k], cur[k],
                                    physics, corners)
                if math.isfinite(t) or crossing:
                    out[count] = t
                    origins[count] = origin
                    count += 1
        if n + 1 < N and code == FOURIER:  # no corners: the next step sees the same values
            prev[:] = cur
        elif n + 1 < N:
            phi, om = angle_and_rate(code, params, t1, t1 + 0.5 * (grid[n + 2] - t1))
            _event_functions(u1, phi, om, prev)
    return count


@njit(cache=True, parallel=True, error_model="numpy")
def event_times(code, params, grids, n_steps, u_nodes, kappa, mu_n, mu_s, p, dtau, corners):
    """Events of every point: (times, origins), row i NaN- (-1-) padded.

    grids : (n, m) nodes, row i valid for n_steps[i] steps; u_nodes : (n, >= max n_steps);
    kappa = T^(2-p), mu_n, mu_s, p, dtau : (n,); corners : (n, k) corners of phi.
    Returns times, shape (n, MAX_EVENTS), and origins (int64, same shape): for an event
    that ``_locate`` followed past the step where the nodes cross, that step, else -1.
    """
    n = grids.shape[0]
    out = np.full((n, MAX_EVENTS), np.nan)
    origins = np.full((n, MAX_EVENTS), -1, dtype=np.int64)
    for i in prange(n):
        physics = np.array([kappa[i], mu_n[i], mu_s[i], p[i], dtau[i]])
        _point_events(code, params[i], grids[i], n_steps[i], u_nodes[i], physics, corners[i],
                      out[i], origins[i])
    return out, origins


@njit(cache=True, error_model="numpy")
def place_events(grid, events, protected, min_gap):
    """``grid`` with a node on every event.

    The node nearest to an event is moved onto it when it lies within a quarter
    of the event's step and is not ``protected`` (a corner of phi, or an end of
    the period); otherwise a node is inserted, unless one is within ``min_gap``
    already.  Moving rather than inserting keeps the grid from collecting nodes as
    an event drifts by small amounts from pass to pass.  Events closer than
    ``min_gap`` to each other give one node.
    """
    ev = np.sort(events[np.isfinite(events)])
    out = grid.copy()
    if ev.size == 0:
        return out
    fixed = np.zeros(out.size, dtype=np.bool_)
    fixed[0] = True
    fixed[-1] = True
    for j in range(out.size):
        for c in protected:
            if out[j] == c:
                fixed[j] = True
    inserted = np.empty(ev.size)
    count = 0
    for e in ev:
        pos = np.searchsorted(out, e)
        if pos == 0 or pos >= out.size:
            continue
        left = out[pos - 1]
        right = out[pos]
        near = pos - 1 if e - left <= right - e else pos
        gap = abs(e - out[near])
        if gap <= min_gap or (count > 0 and e - inserted[count - 1] <= min_gap):
            continue
        movable = False
        if not fixed[near]:  # (0 < near < size - 1 then)
            # the step beyond the moved node grows by gap: only where it is not finer
            far = out[near] - out[near - 1] if near == pos - 1 else out[near + 1] - out[near]
            movable = gap <= 0.25 * min(right - left, far)
        if movable:
            out[near] = e
        else:
            inserted[count] = e
            count += 1
    if count == 0:
        return out
    # an inserted node closer than min_gap to any node (a moved one) is dropped: only
    # inserted nodes, so refinement finer than min_gap elsewhere is kept
    merged = np.concatenate((out, inserted[:count]))
    is_new = np.zeros(merged.size, dtype=np.bool_)
    is_new[out.size:] = True
    order = np.argsort(merged)
    merged = merged[order]
    is_new = is_new[order]
    keep = np.ones(merged.size, dtype=np.bool_)
    for j in range(merged.size):
        if is_new[j] and ((j > 0 and merged[j] - merged[j - 1] <= min_gap)
                          or (j + 1 < merged.size and merged[j + 1] - merged[j] <= min_gap)):
            keep[j] = False
    return merged[keep]


@njit(cache=True, error_model="numpy")
def radau_step_from(u_n, t0, t1, code, params, kappa, mu_n, mu_s, p, dtau, atol):
    """One Radau step over [t0, t1] from u_n, cold: (its integral of u, end value, ok)."""
    h = t1 - t0
    mid = 0.5 * (t0 + t1)
    phi1, om1 = angle_and_rate(code, params, t0 + h / 3.0, mid)
    phi2, om2 = angle_and_rate(code, params, t1, mid)
    U1, U2, _, _, _, _, _, _, _, _, ok = radau_step(
        u_n, u_n, u_n, h, math.sin(phi1), math.cos(phi1), om1, math.sin(phi2), math.cos(phi2),
        om2, kappa, mu_n, mu_s, p, dtau, atol)
    return h * (0.75 * U1 + 0.25 * U2), U2, ok


@njit(cache=True, error_model="numpy")
def split_step_error(code, params, t0, event, t1, u_n, U1, U2, weight_next, kappa, mu_n, mu_s, p,
                     dtau, atol):
    """The error in int u of a Radau step (from u_n, stages U1, U2) over [t0, t1] that holds
    ``event``: the step is solved again as two steps split there, and the change of its
    integral of u plus ``weight_next`` (the node weight lambda_{n+1}, ``_periodic.node_weights``)
    times the change of its end value is returned (NaN where a split step fails).
    """
    qa, ua, ok_a = radau_step_from(u_n, t0, event, code, params, kappa, mu_n, mu_s, p, dtau, atol)
    qb, ub, ok_b = radau_step_from(ua, event, t1, code, params, kappa, mu_n, mu_s, p, dtau, atol)
    if not (ok_a and ok_b):
        return math.nan
    return qa + qb - (t1 - t0) * (0.75 * U1 + 0.25 * U2) + weight_next * (ub - U2)


#: sub-steps per step (on each side of the event in its step) in ``misplaced_stop_error``
STOP_SUBSTEPS = 8
#: times a sub-step whose stage Newton fails is halved before the re-solve gives up
SUBSTEP_HALVINGS = 6


@njit(cache=True, error_model="numpy")
def _substeps_from(u_n, t0, t1, m, code, params, kappa, mu_n, mu_s, p, dtau, atol):
    """m equal Radau steps over [t0, t1] from u_n, a step whose stage Newton fails halved
    (up to SUBSTEP_HALVINGS times): (their integral of u, end value, ok)."""
    total = 0.0
    u = u_n
    for j in range(m):
        a = t0 + (t1 - t0) * j / m
        end = t0 + (t1 - t0) * (j + 1) / m
        depth = 0
        while a < end:
            b = a + (end - a) / (1 << depth) if depth > 0 else end
            if not a < b < end:
                b = end  # (a rounding residue of the step)
            q, u_b, ok = radau_step_from(u, a, b, code, params, kappa, mu_n, mu_s, p, dtau, atol)
            if not ok:
                if depth == SUBSTEP_HALVINGS:
                    return total, u, False
                depth += 1  # (a cold stage Newton can fail on a step holding the stop)
                continue
            total += q
            u = u_b
            a = b
            depth = max(depth - 1, 0)
    return total, u, True


@njit(cache=True, error_model="numpy")
def misplaced_stop_error(code, params, grid, first, event, last, u_first, stages, weight_next,
                         kappa, mu_n, mu_s, p, dtau, atol):
    """The error in int u of Radau steps first..last (from u_first; ``stages`` the solution's
    row of stage values) when the nodes put a stop in step ``first`` but the solution's
    extrapolation puts it at ``event`` in step ``last`` (``_locate`` followed it there).

    Step ``first`` then ended on a spurious root of its stage equations: with
    h T^(2-p) mu > |u_n| (mu up to mu_n when the body sticks) a stage can stick while u
    is still sliding, and the collocation polynomial overshoots through zero (measured: a
    power-law point at mu_n/mu_s 3,020, scaled period 56, rtol 1e-3, stopped 1.8e-3 early,
    from u = 1.2 where h T^(2-p) F was 0.38; the grid and its bisection both did, so
    Richardson saw 0.39 rtol of an error of 1.7).  The steps are solved again from u_first,
    each in STOP_SUBSTEPS equal sub-steps, step ``last`` split at the event first, too short
    to reach a spurious root; the change of the integral plus ``weight_next`` (lambda after
    step ``last``) times the change of the end value is returned (NaN on failure).
    """
    u = u_first
    total = 0.0
    discrete = 0.0
    for n in range(first, last + 1):
        discrete += (grid[n + 1] - grid[n]) * (0.75 * stages[2 * n] + 0.25 * stages[2 * n + 1])
        split = n == last and grid[n] < event < grid[n + 1]
        cut = event if split else grid[n + 1]
        q, u, ok = _substeps_from(u, grid[n], cut, STOP_SUBSTEPS, code, params, kappa, mu_n,
                                  mu_s, p, dtau, atol)
        if ok and split:
            q_rest, u, ok = _substeps_from(u, cut, grid[n + 1], STOP_SUBSTEPS, code, params,
                                           kappa, mu_n, mu_s, p, dtau, atol)
            q += q_rest
        if not ok:
            return math.nan
        total += q
    return total - discrete + weight_next * (u - stages[2 * last + 1])


@njit(cache=True, parallel=True, error_model="numpy")
def unresolved_events(code, params, grids, n_steps, u_nodes, events, origins, kappa, mu_n, mu_s,
                      p, dtau, scale_u, min_gap, stages, weights, atol, split_steps):
    """The error of events that are not nodes of the solved grid, which Richardson is blind to.

    At a stop in a step (u decelerates to rest, then sticks), the Radau stage at a third of
    the step can stick already, and the step loses the triangle of u before the stop,
    ~ J d^2 / 2, with J the jump of u' = T^(2-p) F there and d the distance of the stop to
    the step's node; a grid and its bisection share that node and d, so they agree on
    the error (measured: a power-law point at rtol 1e-5 was 3.7 rtol off with an estimate
    of 0.32, the stop at 2.5e-4 from a shared node).  For every event of ``events`` (rows
    of ``event_times``) farther than ``min_gap`` from a node, J is taken as the change of
    T^(2-p) F between the nodes of its step; the sum of J d^2 / 2, relative to ``scale_u``,
    is returned with the index of each such event's step (-1 where none), shape
    (n, MAX_EVENTS).  Rows with n_steps 0 are skipped.

    A corner of u' (not of u) at a stale node is missed by J: where g = u + omega S / 4
    crosses zero the kink crosses the link's end and u'' jumps (by J2); with the event at
    d < h/3 past the node both stages lie beyond it and the step loses J2 d^2 / 2 whatever
    h is (measured by a helper: three harmonic points at anisotropy 57-202 and scaled period
    0.2-0.45, 1.2-3.7 rtol off with estimates of 0.45-0.64).  So with ``split_steps`` (the
    Radau solution's ``stages`` and node ``weights`` given as rows, as
    ``_periodic.solve_pairs`` returns them) each event's term is the larger of J d^2 / 2 and
    |``split_step_error``| (split steps to stage tolerance ``atol`` times scale_u).  The
    march's steps are not Radau steps: it passes ``split_steps`` False (and empty arrays).
    With ``split_steps``, an event that ``_locate`` followed past the step where the nodes
    cross (``origins``, rows of ``event_times``'s second output; -1 elsewhere) takes the
    larger of that and |``misplaced_stop_error``| (once per such step: where omega = 0 two
    event functions cross together), and its step index is that step, which stopped early.
    """
    n = grids.shape[0]
    estimate = np.zeros(n)
    steps = np.full((n, events.shape[1]), -1, dtype=np.int64)
    for i in prange(n):
        N = n_steps[i]
        if N == 0:
            continue
        grid = grids[i]
        total = 0.0
        counted = -1  # the last step whose early stop was counted
        for j in range(events.shape[1]):
            e = events[i, j]
            if not (grid[0] < e < grid[N]):
                continue
            k = np.searchsorted(grid[:N + 1], e) - 1
            t0 = grid[k]
            t1 = grid[k + 1]
            weight_next = weights[i, k + 1] if split_steps and k + 1 < N else (
                weights[i, 0] if split_steps else 0.0)
            first = origins[i, j]
            early = 0.0
            if split_steps and first >= 0 and first != counted:
                # a stop forced early in step first (on a node of this grid or not); it
                # stands for this event's own term, which re-solves a part of the same steps
                counted = first
                early = abs(misplaced_stop_error(
                    code, params[i], grid, first, e, k, u_nodes[i, first], stages[i],
                    weight_next, kappa[i], mu_n[i], mu_s[i], p[i], dtau[i], atol * scale_u[i]))
                if math.isfinite(early):
                    steps[i, j] = first  # the step to split is the one that stopped early
                else:
                    early = 0.0
            d = min(e - t0, t1 - e)
            if d <= min_gap:
                total += early
                continue
            mid = 0.5 * (t0 + t1)
            phi0, om0 = angle_and_rate(code, params[i], t0, mid)
            phi1, om1 = angle_and_rate(code, params[i], t1, mid)
            u1 = u_nodes[i, k + 1] if k + 1 < N else u_nodes[i, 0]
            F0 = force_and_slope(u_nodes[i, k], phi0, om0, mu_n[i], mu_s[i], p[i], dtau[i])[0]
            F1 = force_and_slope(u1, phi1, om1, mu_n[i], mu_s[i], p[i], dtau[i])[0]
            term = 0.5 * kappa[i] * abs(F1 - F0) * d * d
            if split_steps:
                split = split_step_error(
                    code, params[i], t0, e, t1, u_nodes[i, k], stages[i, 2 * k],
                    stages[i, 2 * k + 1], weight_next,
                    kappa[i], mu_n[i], mu_s[i], p[i], dtau[i], atol * scale_u[i])
                term = max(term, abs(split)) if math.isfinite(split) else term
            total += max(term, early)
            if steps[i, j] < 0:
                steps[i, j] = k
        estimate[i] = total / scale_u[i]
    return estimate, steps
