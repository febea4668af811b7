"""``solve_periodic``: the public entry point of the solver layer.

Error control by local (h-)refinement with per-step Richardson indicators.
For the current grid G (nodes at the corners of phi) both G and its
bisection B(G) are solved; for every step j of G, delta_j is the change of
that step's contribution to the period integrals int u and int Pi between G
and B(G).  The estimate E = sum_j |delta_j| (in the norm below) bounds the
error of the coarse solution, so it is conservative for the returned
B(G) solution.  While E > rtol, the steps whose local indicator (the part of
delta_j made in step j, not carried into it: ``local_indicators``) exceeds
0.5 rtol h_j are bisected (error equidistribution; by P's delta_j where P
alone is over the tolerance), which concentrates steps at the
stick-slip and velocity-reversal events of Coulomb friction, where the
solution is not smooth and uniform refinement converges slowly and
irregularly.  A point is accepted only from the second grid on (a single
coarse grid can miss a short sticking phase altogether).  The corners of F
along the solution are nodes of every grid after the first (``_events``):
the comparison of a grid with its bisection is blind to a corner that both
sample on the same side.  It is blind as well to a body held at rest on a
turning point of phi by both grids (``_turning``): before a pair is accepted,
the steps next to the zeros of dphi/dtau are checked by their defect, weighted
by the sensitivity of U to it; that estimate is added to E, and where it is
large nodes are graded toward the turning point.  Nor does it see an event of the
solution that lies off the nodes at the same distance d from a node both grids share
(a stop in a step loses the same triangle of u on both): J d^2 / 2, J the jump of u' there,
or, for the periodic method, the change of the step split at the event weighted by the node
weight where that is larger (it also sees a corner of u'), is added to E as well
(``_events.unresolved_events``).

Cost (``python -m solver.bench``, 2000 harmonic points at rtol 1e-4, 2 cores):
about 2,400 step-sweeps per point (Radau steps times shooting sweeps, summed over
the ~3 grid pairs; 10 % of them since the turning-point check), ~0.37 us each on one core
(the stage iterations carry Pi, so a converged sweep needs no power pass: that pass had been
a quarter of the evaluations).  On one thread (profile of a 2.5 s solve) the sweeps are
76 % of the time, the turning-point check 8 %, the event search 7 %, the first guesses of
u(0) and V 4 %, the next grids 2 %, and Python ~3 %: a pass builds its pairs and next
grids in one numba call per size class (``_pair_rows``, ``_next_grids``; the Python loop over
points they replaced made solves 1.09-1.15x slower, interleaved A/B).  Two threads run it 1.73x faster than one.  B(G)
is solved after G on the same thread, from G's u(0) and collocation polynomials
(``_periodic.solve_pairs``), and the pairs alternate across threads so numba's static split
stays balanced.  A pass batches its points by size class of their grids (``_size_classes``):
one batch padded every row to the longest grid (at rtol 1e-7, 31 M steps to 139 M cells),
which had cost ~40 % of the wall time.

Error norm.  For P (always > 0) the error is relative.  U can vanish (for
example at isotropic friction and p = 1), so its error is measured relative
to max(|U T|, 1e-3 V), with V = (1/4) int |dphi/dtau| dtau the deformation
speed scale (``kinematic_speed``).  ``error_estimate`` is the larger of the
two.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, fields, replace

import numpy as np
from numba import njit, prange

from . import _march, _march_solve, _periodic, _radau5_solve
from ._events import event_times, place_events, unresolved_events
from ._kinematics import period_grid
from ._limits import fast_limit_velocity, kinematic_speed
from ._status import CONVERGED, NO_MOTION, OUT_OF_RANGE, TOLERANCE_NOT_REACHED, UNSTABLE
from ._turning import MAX_FLAGGED, grade_towards, turning_point_estimates

#: the public methods of ``solve_periodic``: the engine, and the march, its independent check
METHODS = ("periodic", "march")


@dataclass(frozen=True)
class Engine:
    """What computes a method's results: its ``name`` (the method), the ``scheme`` in words,
    and a ``version`` that changes whenever the discretisation or the error control changes
    (a store records both and refuses to resume one started by another version)."""

    name: str
    scheme: str
    version: str

    @property
    def label(self):
        return f"{self.name} {self.version}"


#: bump a version with every change of its engine's discretisation or error control
ENGINES = {
    "periodic": Engine("periodic", "event-driven 3-stage Radau IIA (order 5) with one-pass "
                       "error control (_radau5_solve)", "5.1"),
    "march": Engine("march", "explicit Heun RK2 (order 2) from rest, period by period, "
                    "grid-pair refinement", "2.0"),
}
U_FLOOR_FRACTION = 1e-3
MARCH_MAX_STEPS = 2 ** 22  # steps per solve (periods x steps per period) before giving up
MAX_BISECTIONS = 4  # per refinement pass and step
#: a pair whose estimate (relative: 1e3 times the answer, or its floor 1e-3 V) exceeds this is
#: bisected at most once where marked (at 1 it caught coarse grids of small-U points, whose
#: error of 1.6 times the floor was genuine, and one then ran out of steps at rtol 1e-8)
DISAGREEMENT = 1e3
MIN_STEP = 2.0 ** -26
#: an event this close to a node is taken to be on it (keeps steps above MIN_STEP)
EVENT_GAP = 4 * MIN_STEP
#: the smallest step graded toward a turning point of phi (``_turning``): the window there,
#: ~|u| / |phi''| wide, can be far below MIN_STEP (4e-9 measured at scaled period 2^-4.5)
#: and only its own geometric grading, a few nodes per halving, needs to resolve it
TURNING_MIN_STEP = 2.0 ** -36
#: the smallest step next to a corner of phi (the power law's tau = 0 and tau0), where
#: omega ~ z^(gamma - 1) and a step's error falls only like h^gamma for exponents gamma near
#: 1: with those steps held at MIN_STEP, 9 of 300 long-period power-law points (scaled
#: period 4 .. 128, exponents ~1.1) failed at rtol 1e-6 and 25 at 1e-8 with 220,000+ steps,
#: their estimates stuck at the error made in the corner steps (2.8e-6 at every rtol)
CORNER_MIN_STEP = 2.0 ** -40
#: ... and within this distance of it (the singular omega needs a graded mesh around it)
CORNER_REACH = 2.0 ** -10
#: the march gives up on chatter when resolving it would need this many times its budget
HOPELESS = 8
#: ... or when it still chatters after this many passes that refined the chattering steps
MAX_CHATTER_PASSES = 3
#: chatter matters when u stalled in it carries this share of rtol of int u
CHATTER_SHARE = 0.1
#: the split steps of ``_events.split_step_error`` are solved to this fraction of rtol
#: (times the norm of int u)
SPLIT_STEP_TOLERANCE = 1e-9
#: a refinement pass solves the points in classes of similar grid size (``_size_classes``),
#: each of at least this many points where the sizes allow
MIN_CLASS_POINTS = 32


@dataclass(frozen=True)
class _MethodSpec:
    order: int
    first_steps: int
    max_steps_per_period: int


_SPECS = {
    "periodic": _MethodSpec(order=_periodic.ORDER, first_steps=32, max_steps_per_period=2 ** 17),
    "march": _MethodSpec(order=_march.ORDER, first_steps=64, max_steps_per_period=2 ** 17),
}


@dataclass(frozen=True)
class SolveResult:
    """Outputs of ``solve_periodic``; every array has shape (n_points,) unless noted.

    U : mean velocity (eq. U); P : mean power (eqs. power, powerp);
    efficiency : lambda = sign(U) |U|^(p+1) / P (eqs. lambda, lambdap);
    scaled_speed : (mu_n mu_s)^(1/(2p-4)) U; scaled_power : (mu_n mu_s)^(3/(2p-4)) P;
    scaled_efficiency : sqrt(mu_n mu_s) lambda; efficiency_upper_bound : 1/min(mu_n, mu_s);
    relative_efficiency : lambda / lambda_ub (eq. relefficiency);
    status (int8, 0 = converged; ``STATUS_REASONS``), converged (bool),
    error_estimate (relative, see module docstring), iterations (shooting
    iterations for ``periodic``, periods marched for ``march``, summed over
    grids), n_tau (steps per period of the final grid);
    u : u(tau) at the final grid's nodes, shape (n_points, n_tau), or None;
    tau : those nodes, shape (n_points, n_tau), or None.
    force_evaluations : evaluations of F per point by phase (``radau5`` only: loose shooting,
    target sweeps, frozen-grid sweeps, estimates; shape (n_points, 4)), or None.
    Failed points have NaN in every float output.
    """

    U: np.ndarray
    P: np.ndarray
    efficiency: np.ndarray
    scaled_speed: np.ndarray
    scaled_power: np.ndarray
    scaled_efficiency: np.ndarray
    efficiency_upper_bound: np.ndarray
    relative_efficiency: np.ndarray
    status: np.ndarray
    converged: np.ndarray
    error_estimate: np.ndarray
    iterations: np.ndarray
    n_tau: np.ndarray
    mean_u: np.ndarray
    u: np.ndarray | None = None
    tau: np.ndarray | None = None
    seconds: float = 0.0
    method: str = "periodic"
    force_evaluations: np.ndarray | None = None

    def point(self, i):
        """Dict of the scalar outputs of point ``i``."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray) and v.ndim == 1:
                out[f.name] = v[i].item()
        return out


def _outputs(int_u, int_pi, physics):
    """Every output from the period integrals int u and int Pi.  The efficiency and the scaled
    outputs are formed without U and P, whose powers of T can leave the floating-point range
    (p = 1.99, sqrt(mu_n mu_s) = 1e-2: T = 1e200) when theirs do not: T cancels in lambda, and
    scaled_speed = int u / Ts, scaled_power = kappa int Pi / Ts^3 (kappa = T^(2-p), Ts the
    scaled period, from logarithms)."""
    T, p = physics.period, physics.p
    geo = physics.mu_n * physics.mu_s
    with np.errstate(invalid="ignore", divide="ignore", over="ignore", under="ignore"):
        U = int_u / T
        P = int_pi * T ** -(p + 1.0)
        efficiency = np.sign(int_u) * np.abs(int_u) ** (p + 1.0) / int_pi
        log_scaled_period = np.log(geo) / (4.0 - 2.0 * p) + np.log(T)
        scaled_speed = int_u * np.exp(-log_scaled_period)
        scaled_power = int_pi * np.exp((2.0 - p) * np.log(T) - 3.0 * log_scaled_period)
    lam_ub = 1.0 / np.minimum(physics.mu_n, physics.mu_s)
    return dict(
        U=U, P=P, efficiency=efficiency,
        scaled_speed=scaled_speed,
        scaled_power=scaled_power,
        scaled_efficiency=np.sqrt(geo) * efficiency,
        efficiency_upper_bound=lam_ub,
        relative_efficiency=efficiency / lam_ub,
        mean_u=int_u,
    )


def _representable(out, int_u):
    """Points whose U and P are finite floats: P > 0 did not underflow or overflow, nor U
    (to 0 from a nonzero int u)."""
    U, P = out["U"], out["P"]
    return np.isfinite(U) & np.isfinite(P) & (P > 0) & ((U != 0) | (int_u == 0))


@njit(cache=True, error_model="numpy")
def local_indicators(u_coarse, u_fine, step_derivative, integral_change, h):
    """Where each step's error originates, not where it is carried to.

    With e_n = u_fine - u_coarse at the coarse nodes (periodic: e_N = e_0), the
    error made in step n is e_{n+1} - m_n e_n (m_n = du_{n+1}/du_n of the coarse
    step); the part of the step's integral change not explained by the node
    differences is the step's own quadrature error.
    """
    N = h.size
    out = np.empty(N)
    for n in range(N):
        e = u_fine[n] - u_coarse[n]
        k = n + 1 if n + 1 < N else 0
        e_next = u_fine[k] - u_coarse[k]
        out[n] = (abs(e_next - step_derivative[n] * e) * h[n]
                  + abs(integral_change[n] - 0.5 * h[n] * (e + e_next)))
    return out


@njit(cache=True, error_model="numpy")
def refinement_levels(indicators, h, rtol, order=2):
    """How many times to bisect each step: enough that its local error per unit
    length, shrinking like h^order, meets its share 0.5 rtol h_j of the tolerance;
    at most MAX_BISECTIONS per pass.  ``order`` is the method's: with the corners of
    F on nodes (``_events``) the steps keep it, and where they do not the next pass
    refines again (assuming order 2 here over-resolved by ~2x in n_tau).  When no step is
    over its share (the estimate is dominated by propagation), the steps holding
    half of the total indicator are bisected once (Doerfler marking)."""
    N = indicators.size
    levels = np.zeros(N, dtype=np.int64)
    marked = False
    total = 0.0
    for n in range(N):
        total += indicators[n]
        ratio = indicators[n] / (0.5 * rtol * h[n])
        if ratio > 1.0:  # (NaN: not marked here)
            levels[n] = min(int(math.ceil(math.log2(ratio) / order)), MAX_BISECTIONS) \
                if math.isfinite(ratio) else MAX_BISECTIONS
        marked = marked or levels[n] > 0
    if marked:
        return levels
    if not math.isfinite(total) or total == 0.0:
        levels[:] = 1
        return levels
    order_desc = np.argsort(-indicators)
    running = 0.0
    for n in order_desc:  # the largest indicators until half of the total is covered
        levels[n] = 1
        running += indicators[n]
        if running >= 0.5 * total:
            break
    return levels


@njit(cache=True, error_model="numpy")
def bisect(grid, levels):
    """Nodes of ``grid`` with step j split into 2^levels[j] equal steps."""
    size = 1
    for j in range(levels.size):
        size += 1 << levels[j]
    out = np.empty(size)
    pos = 0
    for j in range(levels.size):
        pieces = 1 << levels[j]
        step = (grid[j + 1] - grid[j]) / pieces
        for k in range(pieces):
            out[pos] = grid[j] + k * step
            pos += 1
    out[pos] = grid[-1]
    return out


@njit(cache=True, error_model="numpy")
def bisect_all(grid):
    """Nodes of ``grid`` with every step split once."""
    out = np.empty(2 * grid.size - 1)
    out[0::2] = grid
    out[1::2] = 0.5 * (grid[:-1] + grid[1:])
    return out


def _size_classes(points, grids):
    """``points`` split into classes whose grids differ in size by up to a factor 2, smaller
    classes merged into the next until they hold MIN_CLASS_POINTS (a remainder of the
    largest into the last); each class keeps the points' order (the kernels split their
    rows statically over threads: sorted by size, one thread would get the small grids and
    the other the large)."""
    sizes = np.array([grids[i].size - 1 for i in points])
    octave = np.floor(np.log2(sizes)).astype(np.int64)
    classes = []
    members = np.zeros(0, dtype=np.int64)
    for value in np.unique(octave):
        members = np.concatenate([members, np.flatnonzero(octave == value)])
        if members.size >= MIN_CLASS_POINTS:
            classes.append(points[np.sort(members)])
            members = np.zeros(0, dtype=np.int64)
    if members.size and classes:  # the largest grids: to the last class, not a thread alone
        classes[-1] = np.sort(np.concatenate([classes[-1], points[members]]))
    elif members.size:
        classes.append(points[np.sort(members)])
    return classes


def _pad(grids):
    """Rows of node arrays -> (padded array (n, max_nodes), steps per row)."""
    n_steps = np.array([g.size - 1 for g in grids], dtype=np.int64)
    out = np.ones((len(grids), n_steps.max() + 1))
    for i, g in enumerate(grids):
        out[i, :g.size] = g
    return out, n_steps


def pad_previous(solutions):
    """(grids, steps, nodes, stages) padded over points from (grid, nodes, stages) or None
    (steps 0: no previous solution)."""
    width = max([s[0].size for s in solutions if s is not None], default=2)
    grids = np.ones((len(solutions), width))
    steps = np.zeros(len(solutions), dtype=np.int64)
    nodes = np.zeros((len(solutions), width - 1))
    stages = np.zeros((len(solutions), 2 * (width - 1)))
    for j, s in enumerate(solutions):
        if s is not None:
            grid, u, st = s
            grids[j, :grid.size] = grid
            steps[j] = grid.size - 1
            nodes[j, :u.size] = u
            stages[j, :st.size] = st
    return grids, steps, nodes, stages


@njit(cache=True, error_model="numpy")
def _pair_estimate(coarse_u, fine_u, coarse_pi, fine_pi, n_coarse, scale_u, scale_p):
    """Per coarse step the change of its integrals of u and Pi from the coarse to the fine
    grid (two half steps), and the estimates sum |change| of U and P in the norm of the
    module docstring: returns (estimate_u, estimate_p, change_u, change_p)."""
    change_u = np.empty(n_coarse)
    change_p = np.empty(n_coarse)
    sum_u = 0.0
    sum_p = 0.0
    for n in range(n_coarse):
        change_u[n] = fine_u[2 * n] + fine_u[2 * n + 1] - coarse_u[n]
        change_p[n] = fine_pi[2 * n] + fine_pi[2 * n + 1] - coarse_pi[n]
        sum_u += abs(change_u[n])
        sum_p += abs(change_p[n])
    return sum_u / scale_u, sum_p / scale_p, change_u, change_p


@njit(cache=True, error_model="numpy")
def step_floors(grid, N, corners):
    """The smallest step each of the N steps of ``grid`` may be split into: CORNER_MIN_STEP
    for the steps within CORNER_REACH of a corner of phi (``corners``, in [0, 1); a corner
    at 0 is also one at 1), MIN_STEP for the others."""
    floors = np.full(N, MIN_STEP)
    for c in corners:
        for n in range(N):
            # distance from the step [grid[n], grid[n + 1]] to c, or to c + 1
            d = min(max(c - grid[n + 1], grid[n] - c, 0.0),
                    max(c + 1.0 - grid[n + 1], grid[n] - c - 1.0, 0.0))
            if d <= CORNER_REACH:
                floors[n] = CORNER_MIN_STEP
    return floors


@njit(cache=True, error_model="numpy")
def _marked_levels(grid, change_u, change_p, u_coarse, u_fine, step_m, scale_u, scale_p, rtol,
                   order, floors):
    """Bisection levels of the coarse steps from the local indicators (``refinement_levels``)
    of u (``local_indicators``, relative to scale_u), or, with ``scale_p`` > 0, the larger of
    those and each step's change of int Pi relative to scale_p.  The caller passes scale_p
    only when P alone is over the tolerance: P's changes include errors carried from
    upstream (marking by them everywhere adds ~30 % of steps without gaining accuracy), but
    where U vanishes u's indicators are rounding noise (a p = 1 isotropic Fourier point kept
    one step holding 5e-7 of P's change while 19,541 others were split).  Steps at their
    floor (``step_floors``) cannot be split, so marking is among the others."""
    n_coarse = change_u.size
    h = grid[1:n_coarse + 1] - grid[:n_coarse]
    indicators = local_indicators(u_coarse[:n_coarse], u_fine[:2 * n_coarse:2],
                                  step_m[:n_coarse], change_u, h)
    for n in range(n_coarse):
        by_power = abs(change_p[n]) / scale_p if scale_p > 0.0 else 0.0
        indicators[n] = max(indicators[n] / scale_u, by_power) if h[n] >= 2 * floors[n] else 0.0
    return refinement_levels(indicators, h, rtol, order)


@njit(cache=True, error_model="numpy")
def _next_grid(grid, levels, events, corners):
    """``grid`` bisected by ``levels`` (never below the steps' floors, ``step_floors``: tiny
    steps at events are fine, bisecting them is not), with nodes on ``events``
    (``place_events``)."""
    clipped = np.empty(levels.size, dtype=np.int64)
    floors = step_floors(grid, levels.size, corners)
    for n in range(levels.size):
        ratio = (grid[n + 1] - grid[n]) / floors[n]
        room = int(math.floor(math.log2(ratio))) if ratio >= 1.0 else 0
        clipped[n] = max(0, min(levels[n], room))
    return place_events(bisect(grid, clipped), events, corners, EVENT_GAP), clipped.any()


@njit(cache=True, parallel=True, error_model="numpy")
def _assess_pairs(grids, n_steps, int_u, int_pi, status, step_u, step_pi, step_m, nodes,
                  u_floor, rtol, order, may_accept, forced, corners):
    """Every pair of a ``solve_pairs`` batch (rows 2j: grid G, 2j + 1: B(G)) at once.

    Returns (estimate, accepted, levels): the estimate of the module docstring (inf where
    either solve failed), whether it is accepted (``may_accept[j]`` and estimate <= rtol),
    and otherwise the bisection levels of G's steps (``_marked_levels``; steps ``forced``
    get MAX_BISECTIONS; a failed pair is bisected everywhere once), shape (m, width - 1).
    ``corners`` (m, k): the corners of phi of pair j's point (``step_floors``).
    """
    m = n_steps.size // 2
    estimate = np.full(m, np.inf)
    accepted = np.zeros(m, dtype=np.bool_)
    levels = np.zeros((m, grids.shape[1] - 1), dtype=np.int64)
    for j in prange(m):
        c = 2 * j
        f = c + 1
        N = n_steps[c]
        if status[c] != CONVERGED or status[f] != CONVERGED:
            levels[j, :N] = 1
            continue
        scale_u = max(abs(int_u[f]), u_floor[j])
        scale_p = abs(int_pi[f])
        estimate_u, estimate_p, change_u, change_p = _pair_estimate(
            step_u[c], step_u[f], step_pi[c], step_pi[f], N, scale_u, scale_p)
        estimate[j] = max(estimate_u, estimate_p)
        if may_accept[j] and estimate[j] <= rtol:
            accepted[j] = True
            continue
        hot = _marked_levels(grids[c, :N + 1], change_u, change_p, nodes[c], nodes[f], step_m[c],
                             scale_u, scale_p if estimate_u <= rtol < estimate_p else 0.0, rtol,
                             order, step_floors(grids[c], N, corners[j]))
        # grids that disagree by more than the answer itself are no asymptotic pair (spurious
        # discrete solutions at extreme corners: estimates of 1e68 .. 1e242): their indicators
        # do not size steps, and splitting the marked ones 16-fold took a rtol-1e-3 point to
        # 79,564 steps where rtol 1e-5 needed 1,000; they are bisected once
        cap = 1 if not estimate[j] <= DISAGREEMENT else MAX_BISECTIONS
        for n in range(N):
            levels[j, n] = MAX_BISECTIONS if forced[j, n] else min(hot[n], cap)
    return estimate, accepted, levels


def _check_turning_points(code, params, active, padded, steps, int_u, nodes, stages, step_m,
                          step_weights, physics, u_floor, rtol, estimate, accepted, collocated,
                          corners):
    """``_turning``'s check of the bisected solutions of the pairs Richardson accepts: adds
    its estimate and withdraws the acceptance where the sum exceeds rtol.  ``collocated``:
    the stages are Radau stages (the periodic method), not the march's pseudo-stages;
    ``corners`` (pairs, k): the corners of phi of each pair's point (their layers are checked).

    Returns (estimate, withdrawn, flagged): the pairs whose acceptance it withdraws, and
    flagged (pairs, MAX_FLAGGED, 3), the nodes to grade toward each turning point, or forward
    into a corner's layer (``grade_towards``), NaN where none."""
    flagged = np.full((active.size, MAX_FLAGGED, 3), np.nan)
    check = np.flatnonzero(accepted)
    if check.size == 0:
        return estimate, check, flagged
    rows = 2 * check + 1
    points = active[check]
    scale_u = np.maximum(np.abs(int_u[rows]), u_floor[points])
    extra, flagged[check] = turning_point_estimates(
        code, params[points], padded[rows], steps[rows], nodes[rows], stages[rows],
        step_m[rows], step_weights[rows], physics.inertia_factor[points], physics.mu_n[points],
        physics.mu_s[points], physics.p[points], physics.delta_tau[points], scale_u,
        float(rtol), TURNING_MIN_STEP, collocated, corners[check])
    estimate = estimate.copy()
    estimate[check] += extra
    withdrawn = check[estimate[check] > rtol]
    return estimate, withdrawn, flagged


def _check_events(code, params, bucket, padded, steps, int_u, nodes, events, origins, physics,
                  u_floor, rtol, estimate, accepted, stages=None, weights=None):
    """``_events.unresolved_events`` for the bisected solutions of the accepted pairs (with
    the Radau ``stages`` and node ``weights``, its split-step term too): adds its estimate
    and withdraws the acceptance where the sum exceeds rtol.

    Returns (estimate, withdrawn, event_steps): the pairs withdrawn, and for every pair the
    bisected grid's steps holding the events counted, or for a stop forced early the step
    that stopped (``unresolved_events``; -1 elsewhere)."""
    F = slice(1, None, 2)
    points = params[bucket]
    scale_u = np.maximum(np.abs(int_u[F]), u_floor[bucket])
    split_steps = stages is not None
    if split_steps:
        stages, weights = stages[F], weights[F]
    else:
        stages, weights = np.zeros((0, 0)), np.zeros((0, 0))
    extra, event_steps = unresolved_events(
        code, points, padded[F], np.where(accepted, steps[F], 0), nodes[F], events, origins,
        physics.inertia_factor[bucket], physics.mu_n[bucket], physics.mu_s[bucket],
        physics.p[bucket], physics.delta_tau[bucket], scale_u, EVENT_GAP, stages, weights,
        SPLIT_STEP_TOLERANCE * rtol, split_steps)
    estimate = np.where(accepted, estimate + extra, estimate)
    withdrawn = np.flatnonzero(accepted & (estimate > rtol))
    return estimate, withdrawn, event_steps


def _chatter(stiff_coarse, stiff_fine, u_coarse, h, threshold):
    """The coarse steps where the march chatters (on either grid of the pair), or None when
    the u stalled in them carries at most ``threshold`` of int u: a short chatter (a brief
    stop at a turning point) costs nothing measurable."""
    n_coarse = h.size
    steps = stiff_coarse[:n_coarse] | stiff_fine[:2 * n_coarse].reshape(n_coarse, 2).any(1)
    mass = np.sum(np.abs(u_coarse[:n_coarse][steps]) * h[steps])
    return steps if mass > threshold else None


def _steps_to_resolve(kinematics, physics, i, tau, h):
    """Steps an explicit method needs on the intervals [tau, tau + h) to resolve sticking:
    h T^(2-p) |dF/du| each, with the slope of F across the band of a link at rest,
    2 (mu_n sin^2 phi + mu_s cos^2 phi) int_0^(1/2) r^(p-1) ds, r ~ delta_tau."""
    phi = kinematics.take([i]).angle(tau + 0.5 * h)[0]
    dtau = max(physics.delta_tau[i], 1e-300)
    slope = (physics.mu_n[i] * np.sin(phi) ** 2 + physics.mu_s[i] * np.cos(phi) ** 2) \
        * dtau ** (physics.p[i] - 1.0)
    return float(np.sum(h * physics.inertia_factor[i] * slope))


def _run_level(method, code, params, grids, n_steps, physics, u0, vscale, rtol, index,
               paired=False, previous=None):
    """Solve the points ``index`` on padded ``grids``.

    Returns (int_u, int_pi, u0, status, iterations, step_u, step_pi, step_m, u_nodes,
    step_stiff, stages, weights, step_weights); step_stiff (march only, else None) flags the
    steps that do not resolve the friction's time scale (chatter, ``_march.step_jumps``).
    ``paired``: rows 2j + 1 bisect rows 2j (``_periodic.solve_pairs`` then starts each from
    its partner, and pair j's coarse grid from ``previous``, the padded (grids, steps, nodes,
    stages) of an earlier solution); stages: the stages of every row (the march's
    pseudo-stages, ``_march._check_inputs``), weights and step_weights: the node weights and
    the step weights they are formed from (``_periodic.node_weights``) of the bisected rows
    (the march: of every row), for the event and turning-point checks.
    """
    args = (code, params[index], grids, n_steps, physics.inertia_factor[index],
            physics.mu_n[index], physics.mu_s[index], physics.p[index],
            physics.delta_tau[index], u0[index], np.maximum(vscale[index], 1e-300), float(rtol))
    if method == "periodic" and paired:
        out = _periodic.solve_pairs(*args, *previous)
        return out[:9] + (None,) + out[9:]
    if method == "periodic":
        return _periodic.solve_points(*args) + (None, None, None, None)
    return _march.march_points(*args, MARCH_MAX_STEPS)


def solve_fixed_grid(kinematics, physics, n_steps, *, method="periodic", rtol=1e-12):
    """Period integrals on one grid of ``n_steps`` steps, without refinement.

    For convergence studies (order tests, work-precision).  ``rtol`` only sets the
    tolerances of the nonlinear iterations (shooting, stage Newton, periodicity).

    Returns
    -------
    mean_u, mean_power_density, status : ndarray, shape (n_points,)
        int_0^1 u dtau, int_0^1 Pi dtau (so U = mean_u / T, P = T^-(p+1) mean_power_density).
    """
    n = len(kinematics)
    if len(physics) == 1 and n > 1:
        physics = physics.take(np.zeros(n, dtype=int))
    code, params = kinematics.kernel_encoding()
    vscale = kinematic_speed(kinematics)
    u0 = fast_limit_velocity(kinematics, physics) if method == "periodic" else np.zeros(n)
    grids = period_grid(kinematics, n_steps)
    if method == "march":
        return _march_solve.fixed_grid(kinematics, physics, n_steps, rtol=rtol)
    if method == "periodic":
        return _radau5_solve.fixed_grid_points(
            code, params, grids, physics.inertia_factor, physics.mu_n, physics.mu_s, physics.p,
            physics.delta_tau, float(rtol), np.maximum(vscale, 1e-300), u0)
    steps = np.full(n, n_steps, dtype=np.int64)
    iu, ip, _, st, *_ = _run_level(method, code, params, grids, steps, physics, u0, vscale, rtol,
                                   np.arange(n))
    return iu, ip, st


def solve_periodic(kinematics, physics, *, method="periodic", rtol=1e-6, return_series=False,
                   max_steps_per_period=None):
    """Periodic steady state u(tau) of eq. (Newtonu) and its mean speed, power and efficiency.

    Parameters
    ----------
    kinematics : Harmonic | PowerLaw | Fourier
        phi(tau) for n_points parameter points.
    physics : Physics
        T, mu_n, mu_s, p, delta; length 1 or n_points.
    method : {"periodic", "march"}
        "periodic": the engine: event-driven 3-stage Radau IIA (order 5, L-stable) with
        one-pass error control, Newton on u(0) (``_radau5_solve``).
        "march": explicit RK2 (Heun, order 2) from rest until periodic: the independent
        check (reports UNSTABLE on stiff sticking instead of a wrong number).
    rtol : float
        Target relative error of U and P (see the module docstring for the norm).
    return_series : bool
        Also return u(tau) on the final grid.
    max_steps_per_period : int, optional
        Finest grid allowed (default 2^17).

    Returns
    -------
    SolveResult
    """
    if method not in METHODS:
        raise ValueError(f"method: expected one of {METHODS}, got {method!r}")
    if not (np.isfinite(rtol) and 0 < rtol < 1):
        raise ValueError(f"rtol: must lie in (0, 1), got {rtol}")
    n = len(kinematics)
    if len(physics) not in (1, n):
        raise ValueError(f"physics: length {len(physics)} does not match the kinematics' {n} points")
    if len(physics) == 1 and n > 1:
        physics = physics.take(np.zeros(n, dtype=int))
    start = time.perf_counter()
    driver = _radau5_solve.solve if method == "periodic" else _march_solve.solve
    out = driver(kinematics, physics, rtol,
                 max_steps_per_period or _SPECS[method].max_steps_per_period, return_series)
    return _result(out, physics, method, start)


def solve_order3(kinematics, physics, *, rtol=1e-6, return_series=False,
                 max_steps_per_period=None):
    """The former default engine (2-stage Radau IIA, order 3, grid-pair refinement), kept
    only until the gradient stands on the new engine; not a method of ``solve_periodic``."""
    n = len(kinematics)
    if len(physics) == 1 and n > 1:
        physics = physics.take(np.zeros(n, dtype=int))
    result = _solve_by_refinement(kinematics, physics, "order3", rtol, return_series,
                                  max_steps_per_period, time.perf_counter())
    return replace(result, method="order3")


def _solve_by_refinement(kinematics, physics, method, rtol, return_series,
                         max_steps_per_period, start):
    method = "periodic" if method == "order3" else method  # (the old engine's kernels' name)
    run = _Refinement(kinematics, physics, method, rtol, return_series,
                      max_steps_per_period or _SPECS[method].max_steps_per_period)
    active = run.active
    level = 0
    while active.size:
        # one batch per size class: rows are padded to the batch's longest grid, and one
        # batch over all points padded 2000 rows of ~31 M steps to 139 M at rtol 1e-7
        survivors = [run.refine(bucket, level) for bucket in _size_classes(active, run.grids)]
        active = np.sort(np.concatenate(survivors))
        level += 1
    return run.result(time.perf_counter() - start)


def _result(out, physics, method, start):
    """The ``SolveResult`` of a driver's output dict (``_radau5_solve.solve``,
    ``_march_solve.solve``: int_u, int_pi, status, estimate, n_tau, iterations, still,
    series, evaluations): the physical outputs, NaN where not converged, phi constant as
    NO_MOTION with U = P = 0, and U or P beyond the float range as OUT_OF_RANGE."""
    status = out["status"]
    still = out["still"]
    status[still] = NO_MOTION
    int_u = np.where(status == CONVERGED, out["int_u"], np.nan)
    int_pi = np.where(status == CONVERGED, out["int_pi"], np.nan)
    int_u[still] = 0.0
    int_pi[still] = 0.0
    estimate = out["estimate"]
    estimate[still] = 0.0
    outputs = _outputs(int_u, int_pi, physics)
    beyond = (status == CONVERGED) & ~_representable(outputs, int_u)
    if beyond.any():
        status[beyond] = OUT_OF_RANGE
        for key in outputs:
            if key != "efficiency_upper_bound":
                outputs[key] = np.where(beyond, np.nan, outputs[key])
    for key in ("efficiency", "scaled_efficiency", "relative_efficiency"):
        outputs[key][still] = np.nan
    u_arr = tau_arr = None
    if out["series"] is not None:
        u_arr = [s[0] for s in out["series"]]
        tau_arr = [s[1] for s in out["series"]]
        if len({len(s) for s in u_arr}) == 1:
            u_arr, tau_arr = np.array(u_arr), np.array(tau_arr)
    return SolveResult(
        **outputs, status=status, converged=status == CONVERGED, error_estimate=estimate,
        iterations=out["iterations"], n_tau=out["n_tau"], u=u_arr, tau=tau_arr,
        seconds=time.perf_counter() - start, method=method,
        force_evaluations=out["evaluations"])


@njit(cache=True, error_model="numpy")
def _pair_rows(coarse, steps):
    """Rows 2j: the grids G of ``coarse`` (row j valid for ``steps[j]`` steps); rows 2j + 1:
    their bisections B(G) (``bisect_all``); padded with 1.  Returns (rows, steps per row).

    Coarse and fine rows alternate so that the kernels' static split over threads gets equal
    work (coarse rows first would give one thread a third, the other two)."""
    m, width = coarse.shape
    rows = np.ones((2 * m, 2 * width - 1))
    pair_steps = np.empty(2 * m, dtype=np.int64)
    for j in range(m):
        N = steps[j]
        rows[2 * j, :N + 1] = coarse[j, :N + 1]
        rows[2 * j + 1, :2 * N + 1] = bisect_all(coarse[j, :N + 1])
        pair_steps[2 * j] = N
        pair_steps[2 * j + 1] = 2 * N
    return rows, pair_steps


@njit(cache=True, error_model="numpy")
def _next_grids(rows, steps, levels, events, corners, flagged, pairs):
    """The next grids of the ``pairs`` of a pass: G (``rows[2j]``) bisected by ``levels[j]``
    with nodes on ``events[j]`` (``_next_grid``), then graded toward the turning points
    ``flagged[j]`` (``grade_towards``; none where its first entry is NaN).

    Returns (nodes of all new grids concatenated, offsets (pairs.size + 1,), refined): grid k
    is nodes[offsets[k]:offsets[k + 1]]; refined[k] is False where nothing changed."""
    grids = []
    refined = np.zeros(pairs.size, dtype=np.bool_)
    offsets = np.zeros(pairs.size + 1, dtype=np.int64)
    for k in range(pairs.size):
        j = pairs[k]
        N = steps[2 * j]
        new, changed = _next_grid(rows[2 * j, :N + 1], levels[j, :N], events[j], corners[j])
        if math.isfinite(flagged[j, 0, 0]):
            graded = grade_towards(new, flagged[j], 0.25 * TURNING_MIN_STEP)
            changed = changed or graded.size > new.size
            new = graded
        refined[k] = changed
        grids.append(new)
        offsets[k + 1] = offsets[k] + new.size
    nodes = np.empty(offsets[-1])
    for k in range(pairs.size):
        nodes[offsets[k]:offsets[k + 1]] = grids[k]
    return nodes, offsets, refined


@dataclass(frozen=True)
class _PassOutputs:
    """One size class's pairs solved (``_run_level`` with ``paired``): rows 2j hold G, rows
    2j + 1 hold B(G) of the class's point j; ``stiff`` only for the march; ``stages``,
    ``weights`` and ``step_weights`` (``_run_level``) are the march's pseudo-ones there."""

    rows: np.ndarray
    steps: np.ndarray
    int_u: np.ndarray
    int_pi: np.ndarray
    u0: np.ndarray
    status: np.ndarray
    iterations: np.ndarray
    step_u: np.ndarray
    step_pi: np.ndarray
    step_m: np.ndarray
    nodes: np.ndarray
    stiff: np.ndarray | None
    stages: np.ndarray | None
    weights: np.ndarray | None
    step_weights: np.ndarray | None

    @property
    def ok(self):
        """Both solves of each pair converged."""
        return (self.status[0::2] == CONVERGED) & (self.status[1::2] == CONVERGED)

    def fine_series(self, j):
        """(u at B(G)'s nodes, those nodes without tau = 1) of pair j."""
        N = self.steps[2 * j + 1]
        return self.nodes[2 * j + 1, :N].copy(), self.rows[2 * j + 1, :N].copy()


@dataclass(frozen=True)
class _Verdict:
    """What the checks of a pass decided for each pair of a size class: its estimate, whether
    it is accepted, the bisection levels of G's steps, the events found on B(G) (NaN padded),
    the turning points to grade toward (``_turning``; NaN where none), and for the march the
    chattering steps that must be split (``forced``) and whether the pair may be accepted."""

    estimate: np.ndarray
    accepted: np.ndarray
    levels: np.ndarray
    events: np.ndarray
    flagged: np.ndarray
    forced: np.ndarray


class _Refinement:
    """The per-point state of ``solve_periodic`` over its refinement passes.

    Every pass solves, for each active point, its grid G and the bisection B(G); a point
    leaves when a pair is accepted, or when its next grid would exceed the budget or not
    change.  ``grids[i]`` is point i's next G; ``previous[i]`` (B(G), its nodes' u, its
    stages) of its last converged fine solve starts the next coarse solve (periodic method).
    """

    def __init__(self, kinematics, physics, method, rtol, return_series, max_steps):
        n = len(kinematics)
        self.kinematics, self.physics, self.method, self.rtol = kinematics, physics, method, rtol
        self.spec = _SPECS[method]
        self.max_steps = max_steps
        self.code, self.params = kinematics.kernel_encoding()
        self.vscale = kinematic_speed(kinematics)
        self.u_floor = U_FLOOR_FRACTION * self.vscale
        self.int_u = np.full(n, np.nan)
        self.int_pi = np.full(n, np.nan)
        self.status = np.full(n, TOLERANCE_NOT_REACHED, dtype=np.int8)
        self.last_status = np.full(n, CONVERGED, dtype=np.int8)  # of the last grid's solves
        self.estimate = np.full(n, np.inf)
        self.iterations = np.zeros(n, dtype=np.int64)
        self.n_tau = np.zeros(n, dtype=np.int64)
        self.chatter_passes = np.zeros(n, dtype=np.int64)
        self.series = [None] * n if return_series else None
        self.still = self.vscale <= 0
        self.status[self.still] = NO_MOTION
        self.int_u[self.still] = 0.0
        self.int_pi[self.still] = 0.0
        self.estimate[self.still] = 0.0
        self.active = np.flatnonzero(~self.still)
        self.u0 = np.zeros(n)  # the march starts from rest
        if method == "periodic" and self.active.size:
            self.u0[self.active] = fast_limit_velocity(kinematics.take(self.active),
                                                       physics.take(self.active))
        self.grids = list(period_grid(kinematics, self.spec.first_steps))
        self.corners = kinematics.corners()
        self.previous = [None] * n

    def refine(self, bucket, level):
        """One pass over the points ``bucket``: solve, check, advance.  Returns the points
        that go on to the next pass."""
        out = self._solve(bucket)
        self._record(bucket, out)
        verdict = self._assess(bucket, out, level)
        return self._advance(bucket, out, verdict)

    def _solve(self, bucket):
        rows, steps = _pair_rows(*_pad([self.grids[i] for i in bucket]))
        results = _run_level(self.method, self.code, self.params, rows, steps, self.physics,
                             self.u0, self.vscale, self.rtol, np.repeat(bucket, 2), paired=True,
                             previous=pad_previous([self.previous[i] for i in bucket]))
        return _PassOutputs(rows, steps, *results)

    def _record(self, bucket, out):
        """The fine solutions' integrals (NaN where a pair failed), u(0) and counts."""
        C, F = slice(0, None, 2), slice(1, None, 2)
        ok = out.ok
        self.iterations[bucket] += out.iterations[C] + out.iterations[F]
        self.last_status[bucket] = np.where(out.status[F] != CONVERGED, out.status[F],
                                            out.status[C])
        fine_ok = out.status[F] == CONVERGED
        self.u0[bucket[fine_ok]] = out.u0[F][fine_ok]
        self.int_u[bucket] = np.where(ok, out.int_u[F], np.nan)
        self.int_pi[bucket] = np.where(ok, out.int_pi[F], np.nan)
        self.n_tau[bucket] = out.steps[F]

    def _assess(self, bucket, out, level):
        """Richardson's estimate and marking (``_assess_pairs``), then the turning-point
        check (periodic) and the event check, each of which can withdraw an acceptance."""
        m = bucket.size
        rtol, physics = self.rtol, self.physics
        may_accept = np.full(m, level >= 1)  # a single coarse grid can miss a short stop
        forced = np.zeros((m, out.rows.shape[1] - 1), dtype=bool)
        if out.stiff is not None:
            self._mark_chatter(bucket, out, may_accept, forced)
        assess_args = (out.rows, out.steps, out.int_u, out.int_pi, out.status, out.step_u,
                       out.step_pi, out.step_m, out.nodes)
        estimate, accepted, levels = _assess_pairs(
            *assess_args, self.u_floor[bucket], rtol, self.spec.order, may_accept, forced,
            self.corners[bucket])
        flagged = np.full((m, MAX_FLAGGED, 3), np.nan)
        if out.weights is not None:  # the check at turning points of phi (``_turning``)
            richardson = estimate
            estimate, withdrawn, flagged = _check_turning_points(
                self.code, self.params, bucket, out.rows, out.steps, out.int_u, out.nodes,
                out.stages, out.step_m, out.step_weights, physics, self.u_floor, rtol, estimate,
                accepted, self.method == "periodic", self.corners[bucket])
            accepted[withdrawn] = False
            # withdrawn pairs are graded toward their turning points; Richardson's marking
            # (Doerfler's, its estimate being below rtol) only where that estimate is large
            marked = withdrawn[richardson[withdrawn] > 0.5 * rtol]
            if marked.size:
                pair_rows = np.stack([2 * marked, 2 * marked + 1], axis=1).ravel()
                levels[marked] = _assess_pairs(
                    *(a[pair_rows] for a in assess_args), self.u_floor[bucket[marked]], rtol,
                    self.spec.order, np.zeros(marked.size, dtype=bool), forced[marked],
                    self.corners[bucket[marked]])[2]
        F = slice(1, None, 2)
        events, origins = event_times(
            self.code, self.params[bucket], out.rows[F], out.steps[F], out.nodes[F],
            physics.inertia_factor[bucket], physics.mu_n[bucket], physics.mu_s[bucket],
            physics.p[bucket], physics.delta_tau[bucket], self.corners[bucket])
        # events off the nodes of an accepted pair: their error is added, and where that
        # withdraws the pair its steps holding them are bisected (and they become nodes)
        estimate, withdrawn, event_steps = _check_events(
            self.code, self.params, bucket, out.rows, out.steps, out.int_u, out.nodes, events,
            origins, physics, self.u_floor, rtol, estimate, accepted,
            out.stages if self.method == "periodic" else None, out.weights)
        accepted[withdrawn] = False
        for j in withdrawn:
            held = event_steps[j][event_steps[j] >= 0] // 2  # B(G)'s step -> G's
            levels[j, held] = np.maximum(levels[j, held], 1)
        ok = out.ok
        self.estimate[bucket[ok]] = estimate[ok]
        return _Verdict(estimate, accepted, levels, events, flagged, forced)

    def _mark_chatter(self, bucket, out, may_accept, forced):
        """The march: steps too long for stiff friction must be split (``_chatter``)."""
        ok = out.ok
        for j, i in enumerate(bucket):
            if not ok[j]:
                continue
            unresolved = _chatter(out.stiff[2 * j], out.stiff[2 * j + 1], out.nodes[2 * j],
                                  np.diff(out.rows[2 * j, :out.steps[2 * j] + 1]),
                                  CHATTER_SHARE * self.rtol
                                  * max(abs(out.int_u[2 * j + 1]), self.u_floor[i]))
            if unresolved is not None:
                self.last_status[i] = UNSTABLE
                forced[j, :unresolved.size] = unresolved
                may_accept[j] = False

    def _hopeless_chatter(self, i, coarse, unresolved):
        """The march chattered again: give up (UNSTABLE) after MAX_CHATTER_PASSES, or when
        resolving the friction's time scale would need HOPELESS times the step budget."""
        self.chatter_passes[i] += 1
        return self.chatter_passes[i] > MAX_CHATTER_PASSES or _steps_to_resolve(
            self.kinematics, self.physics, i, coarse[:-1][unresolved],
            np.diff(coarse)[unresolved]) > HOPELESS * self.max_steps

    def _advance(self, bucket, out, verdict):
        """Accept, give up on, or re-grid every point of the pass; returns those re-gridded."""
        ok = out.ok
        accepted = verdict.accepted
        self.status[bucket[accepted]] = CONVERGED
        go_on = ~accepted
        if out.stiff is not None:
            for j in np.flatnonzero(go_on & ok & verdict.forced.any(axis=1)):
                N = out.steps[2 * j]
                if self._hopeless_chatter(bucket[j], out.rows[2 * j, :N + 1],
                                          verdict.forced[j, :N]):
                    go_on[j] = False
        pairs = np.flatnonzero(go_on)
        nodes, offsets, refined = _next_grids(out.rows, out.steps, verdict.levels,
                                              verdict.events, self.corners[bucket],
                                              verdict.flagged, pairs)
        sizes = np.diff(offsets)
        # out of budget, or nothing left to refine: TOLERANCE_NOT_REACHED or the kernel's reason
        stop = (sizes - 1 > self.max_steps) | ~refined
        if self.series is not None:
            for j in np.flatnonzero(accepted | ok & np.isin(np.arange(bucket.size), pairs[stop])):
                self.series[bucket[j]] = out.fine_series(j)
        for k in np.flatnonzero(~stop):
            j = pairs[k]
            i = bucket[j]
            self.grids[i] = nodes[offsets[k]:offsets[k + 1]]
            if self.method == "periodic" and out.status[2 * j + 1] == CONVERGED:
                N = out.steps[2 * j]
                # views into this pass's arrays: ``pad_previous`` copies them
                self.previous[i] = (out.rows[2 * j + 1, :2 * N + 1], out.nodes[2 * j + 1, :2 * N],
                                    out.stages[2 * j + 1, :4 * N])
        return bucket[pairs[~stop]]

    def result(self, seconds):
        status, int_u, int_pi = self.status, self.int_u, self.int_pi
        failed = status != CONVERGED
        # report the kernel's own reason where the last grid failed outright
        kernel_failed = failed & (self.last_status != CONVERGED) & (status != NO_MOTION)
        status[kernel_failed] = self.last_status[kernel_failed]
        keep_nan = failed & (status != NO_MOTION)
        int_u[keep_nan] = np.nan
        int_pi[keep_nan] = np.nan
        out = _outputs(int_u, int_pi, self.physics)
        # never a silent 0 or inf: a converged point whose U or P a float cannot hold fails
        beyond = (status == CONVERGED) & ~_representable(out, int_u)
        if beyond.any():
            status[beyond] = OUT_OF_RANGE
            for key in out:
                if key != "efficiency_upper_bound":  # (a property of mu alone, as for any failure)
                    out[key] = np.where(beyond, np.nan, out[key])
        for key in ("efficiency", "scaled_efficiency", "relative_efficiency"):
            out[key][self.still] = np.nan
        u_arr = tau_arr = None
        if self.series is not None:
            empty = (np.array([]), np.array([]))
            u_arr = [(s or empty)[0] for s in self.series]
            tau_arr = [(s or empty)[1] for s in self.series]
            if len({len(s) for s in u_arr}) == 1:
                u_arr, tau_arr = np.array(u_arr), np.array(tau_arr)
        return SolveResult(
            **out, status=status, converged=status == CONVERGED, error_estimate=self.estimate,
            iterations=self.iterations, n_tau=self.n_tau, u=u_arr, tau=tau_arr,
            seconds=seconds, method=self.method)
