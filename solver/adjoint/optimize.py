"""Optimal motions (section "Optimal motions"): BFGS with exact adjoint gradients and Newton steps.

Variables.  The family's continuous parameters (Fourier A_0..A_K, B_2..B_K with
B_1 = 0 fixing the phase; harmonic A0, A1; power law A0, A1, tau0, gamma_c,
gamma_o in their boxes) and log T at fixed mu_n, mu_s, p, delta.  The objective
is minimised as f = -s lambda (or -s U), s = sign at the start: the optimiser
keeps the direction of travel and maximises |lambda| (|U|), as the paper does by
minimising lambda.  For |U| at fixed mean power ("speed_at_power") T is not a
variable: the constraint P(theta, T) = P_target is solved for T(theta) at every
evaluation and the gradient is the exact one along it (``speed_at_power``).

Every evaluation is the discretised problem on a fixed grid (``FixedGrid``),
so f is smooth and its gradient (``objective_gradient``, adjoint method) is exact
for it.  Smooth but stiff: with Coulomb friction its curvature still changes
visibly over parameter steps of 1e-7 (``HESSIAN_STEP``).  The discretisation is the
order-5 engine's 3-stage Radau IIA on the step sequence of its converged solve at the start
(``adaptive_grid``: corners of phi and state events are step ends); after convergence it is
re-adapted at the optimum and the search is repeated from there while the grid changes
(``grid_rounds``).

Iteration (explicit state: ``initial_state``, ``optimizer_step``, ``_terminate``).
- BFGS on the free variables (those not held at a bound by an outward gradient),
  the inverse-Hessian update skipped when the curvature condition y.s > 0 fails.
- Damped line search: the step is first cut to ``max_step`` in the variables, then
  cut by quadratic interpolation (to [0.1, 0.5] of itself; halved after a failed
  solve, which counts as +inf) until Armijo's condition holds.  Trial points are
  solved without their gradient; only the accepted one is differentiated.  A full step
  accepted at once along negative curvature (y.s <= 0) is extrapolated (doubled)
  while f keeps falling.  A full Newton step is also accepted when f changes by less
  than its noise (1e-12 relative) and the gradient norm falls: close to the optimum
  Armijo cannot resolve the decrease.
- Near convergence (projected gradient norm below ``newton_switch`` times the first
  one), when a BFGS step stalls (keeps more than ``STALL_RATIO`` of the gradient norm,
  or fails: then the step is retried as Newton's instead of stopping), a Newton step
  with the Hessian from forward differences of the exact gradient (n gradients: at the
  step 1e-8 the gradient's own error, not the O(step) truncation, limits either
  difference, so central ones buy nothing); its inverse
  also restarts the BFGS approximation.  Not positive definite: BFGS, and no new
  difference Hessian for ``HESSIAN_WAIT`` iterations.
- Stop when the projected gradient norm is below ``gtol`` (the paper used 1e-7).

Grid rounds.  The frozen steps are re-adapted where a round ends (converged, a failed line
search, or creeping, below) and the search goes on from there, up to ``grid_rounds`` grids.
The three devices below are options, off by default (``OptimizerOptions``; measured in
docs/validation.md, issue 35: fewer solves, but other best optima in some cells).
- Creeping: a step accepted at below ``CREEP_FRACTION`` of its first trial is a search pushed
  against a jump of the discrete objective on steps made far from where it stands (a stiff
  step's stage equations with another root, a fold); ``creep_steps`` such steps in a row end
  the round, and in the last round the search ("line_search_failed", ``creep_final``).
  Before, such runs went on until the step fell below ``MIN_STEP_FRACTION`` (tens of
  iterations of 5-13 solves each) and then ended the round by the failed line search anyway.
- A round that is not the last stops at ``max(gtol, early_gtol)``: its steps are re-adapted
  anyway, so converging to gtol on them is wasted; where the new steps equal the old the
  search goes on to gtol on them.
- ``warm_rounds``: the first round starts from the sign probe's solution (the same point on
  the same steps) and a later one from u(0) of the last round's end, not from the fast-motion
  limit (``model.limits.fast_limit_velocity``, ~3 solves' worth of work each time).

Ill-conditioning.  At p = 2 the ODE in tau no longer depends on T (kappa = T^0)
and lambda is invariant under T: the Hessian is singular along log T and the
problem is ill-conditioned as p -> 2 (section "Other power laws"; the optimal scaled
periods grow without bound there).  T is boxed (``period_range``); ending at that
bound sets ``ill_conditioned`` and names "period" in ``at_bounds``.  The condition
number of every difference Hessian is kept; above ``max_condition``, or when the
line search finds f flat to rounding along a descent direction, the search stops
with reason "ill_conditioned" (never loops), and ``ill_conditioned`` is set.  A
search that ends unconverged is diagnosed by a difference Hessian at its end.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from .gradient import (FixedGrid, adaptive_grid, discrete_solution, family_parameters,
                        objective_gradient, speed_at_power, with_family_parameters,
                        with_period)
from ..model.kinematics import Fourier, Harmonic, PowerLaw
from ..solve import solve_periodic

STOP_REASONS = {
    "gradient_tolerance": "projected gradient norm below gtol",
    "max_iterations": "iteration budget exhausted",
    "line_search_failed": "no decrease along the search direction (gradient above gtol)",
    "ill_conditioned": "Hessian condition number above max_condition, or no decrease possible "
                       "at rounding level (p near 2: lambda nearly invariant under T)",
    "solve_failed": "the periodic solve failed at the starting point",
    "no_progress": "accepted steps at rounding level: gtol is below the noise of the objective",
}

DUTY_CYCLE_MARGIN = 1e-3
#: relative step of the difference Hessian of the exact gradient
HESSIAN_STEP = 1e-8
#: relative noise of the discrete objective (nonlinear tolerances, closed-form switches)
F_NOISE = 1e-12
#: BFGS iterations after an indefinite difference Hessian before the next one
HESSIAN_WAIT = 5
#: close to the optimum a BFGS step that keeps more than this share of the gradient norm
#: (or fails) has stalled: the next step is Newton's
STALL_RATIO = 0.5
#: the line search gives up below this fraction of the (damped) step: x + alpha d must
#: still differ from x, else Armijo "holds" at alpha -> 0 and a non-descent direction
#: would end as no_progress instead of line_search_failed
MIN_STEP_FRACTION = 2.0 ** -39
#: a step accepted at below this fraction of its first trial creeps: the search stands at a
#: jump of the discrete objective (``creep_steps``)
CREEP_FRACTION = 1e-3
#: rtol of the engine's solve of the final motion (``OptimizeResult.engine_value``): far
#: below any grid_rtol, so that grid_error measures the fixed grid's error, not the engine's
CHECK_RTOL = 1e-8


@dataclass(frozen=True)
class OptimizeResult:
    """Outcome of ``optimize_motion`` (one start).

    kinematics, physics : the optimum (one point each)
    names : family parameter names then "period"; parameters : their values
    value : the objective (lambda, U or P) on the final fixed grid; U, P, efficiency likewise
    gradient : d value / d parameters (period last, d/dT), exact for the final grid; for
        "speed_at_power" dU/dtheta along P = power and nan for the period (not a variable)
    gradient_norm : projected norm in the optimisation variables (log T for the period)
    iterations, newton_steps, gradient_evaluations, solves : counts over all grid rounds
        (gradient_evaluations: adjoint gradients; solves: periodic solves, one per line-search
        trial and per gradient, since trial points are solved without their gradient).  For
        "speed_at_power" both count constrained evaluations, each a root search for T with
        a solve and gradient per root iteration.
    stop_reason : a key of ``STOP_REASONS``; converged : stop_reason == "gradient_tolerance"
    ill_conditioned : bool; condition_number : of the last difference Hessian (nan if none)
    n_steps : steps of the final grid; grid_rounds : grids used; seconds : wall time
    at_bounds : names of the variables held at a bound at the end (e.g. "period" running off)
    engine_value, engine_U, engine_P, engine_efficiency : the same outputs of the final motion
        solved by the order-5 engine at rtol ``CHECK_RTOL`` (``solve_periodic``, its own
        steps and error control): the motion's true outputs to that rtol, where ``value``
        etc. are those of the final fixed grid, which the search may have exploited (it
        maximises the discrete objective, steps made elsewhere); nan where the engine fails
    grid_error : |value - engine_value| / |engine_value| (for "speed_at_power" the larger of
        that and P's): the discretisation error of the reported optimum on its fixed grid
    certified : grid_error <= ``certify_tolerance`` (``OptimizerOptions``; against
        ``certify_floor`` below it): the optimum of the frozen steps is the engine's to that tolerance
    certify_rounds : searches on finer steps that certification took (0: none was needed)
    coarse_iterations : accepted steps of the coarse stage (``fidelity``; 0 without one)
    cpu_seconds : CPU time of this thread [s] (the solves of one point run on the calling
        thread, ``solver._threads``), the per-start cost ``compare_optima`` compares
    """

    kinematics: object
    physics: object
    names: list
    parameters: np.ndarray
    value: float
    U: float
    P: float
    efficiency: float
    gradient: np.ndarray
    gradient_norm: float
    iterations: int
    newton_steps: int
    gradient_evaluations: int
    stop_reason: str
    converged: bool
    ill_conditioned: bool
    condition_number: float
    n_steps: int
    grid_rounds: int
    seconds: float
    at_bounds: tuple = ()
    solves: int = 0
    engine_value: float = math.nan
    engine_U: float = math.nan
    engine_P: float = math.nan
    engine_efficiency: float = math.nan
    grid_error: float = math.nan
    certified: bool = False
    certify_rounds: int = 0
    coarse_iterations: int = 0
    cpu_seconds: float = math.nan


@dataclass(frozen=True)
class Problem:
    """Map between the optimisation variables x and (kinematics, physics); the fixed grid."""

    template: object
    physics: object
    grid: FixedGrid
    objective: str
    sign: float
    free: np.ndarray      # indices of the full parameter vector that are variables
    full_start: np.ndarray  # family parameters then T; fixed entries taken from here
    lower: np.ndarray     # bounds of x (family entries; log T unbounded)
    upper: np.ndarray
    #: work done: periodic solves (``solve``) and adjoint gradients (``differentiate``)
    counts: dict = field(default_factory=lambda: {"solves": 0, "gradients": 0})

    def full(self, x):
        full = self.full_start.copy()
        full[self.free] = x
        full[-1] = math.exp(x[-1])
        return full

    def kinematics(self, full):
        """The family at the full parameter vector, or None outside its domain."""
        try:
            return with_family_parameters(self.template, full[:-1])
        except ValueError:
            return None

    def evaluate(self, x, u0=None):
        """(f, grad f in x, GradientResult)."""
        f, trial = self.solve(x, u0)
        if not math.isfinite(f):
            return math.inf, None, None
        return (f,) + self.differentiate(trial)

    def solve(self, x, u0=None):
        """(f, trial) without the gradient; f = inf where x is outside the family or the
        solve fails.  ``differentiate(trial)`` then gives (grad f, GradientResult)."""
        self.counts["solves"] += 1
        full = self.full(x)
        kin = self.kinematics(full)
        if kin is None:
            return math.inf, None
        phys = with_period(self.physics, full[-1])
        sol = discrete_solution(kin, phys, self.grid, u0=u0)
        U, P, lam = sol.outputs()
        value = {"efficiency": lam, "speed": U}[self.objective]
        if sol.status != 0 or not math.isfinite(value):
            return math.inf, None
        return -self.sign * value, (full, sol)

    def differentiate(self, trial):
        self.counts["gradients"] += 1
        full, sol = trial
        res = objective_gradient(sol.kinematics, sol.physics, self.grid,
                                 objective=self.objective, solution=sol)
        g_full = res.gradient.copy()
        g_full[-1] *= full[-1]  # d/dlog T
        return -self.sign * g_full[self.free], res


@dataclass(frozen=True)
class _PowerConstrainedProblem(Problem):
    """|U| at fixed mean power: the variables are the family's; T(x) solves P = ``power``.

    ``periods`` remembers T(x) of every evaluated x (and the latest under "last", the first
    guess of the next root), so ``full`` returns the period the constraint gave.
    """

    power: float = math.nan
    periods: dict = field(default_factory=dict)

    def full(self, x):
        full = self.full_start.copy()
        full[self.free] = x
        full[-1] = self.periods.get(np.asarray(x, dtype=float).tobytes(), full[-1])
        return full

    def solve(self, x, u0=None):
        # the constraint's root for T needs gradients: nothing to defer
        f, g, res = self.evaluate(x, u0)
        return f, (g, res)

    def differentiate(self, trial):
        return trial  # counted by ``evaluate``

    def evaluate(self, x, u0=None):
        self.counts["solves"] += 1
        full = self.full(x)
        kin = self.kinematics(full)
        if kin is None:
            return math.inf, None, None
        guess = self.periods.get("last", full[-1])
        res = speed_at_power(kin, with_period(self.physics, guess), self.grid, self.power, u0=u0)
        if res.status != 0 or not math.isfinite(res.value):
            return math.inf, None, res
        self.counts["gradients"] += 1
        self.periods[np.asarray(x, dtype=float).tobytes()] = res.period
        self.periods["last"] = res.period
        return -self.sign * res.value, -self.sign * res.gradient[self.free], res


OBJECTIVES = ("efficiency", "speed", "speed_at_power")


def _outputs(res):
    """(value, U, P, efficiency, gradient with the period last) of an evaluation's result."""
    if hasattr(res, "at"):  # U at fixed P: the period is not a variable (gradient entry nan)
        return (res.value, res.at.U, res.at.P, res.at.efficiency,
                np.append(res.gradient, math.nan))
    return res.value, res.U, res.P, res.efficiency, res.gradient


@dataclass(frozen=True)
class State:
    x: np.ndarray
    f: float
    g: np.ndarray
    hinv: np.ndarray
    result: object
    iteration: int = 0
    newton_steps: int = 0
    stop_reason: str = ""
    condition_number: float = math.nan
    ill_conditioned: bool = False
    first_gradient_norm: float = math.nan
    hessian_wait: int = 0  # iterations before the next difference Hessian (after an indefinite one)
    stalled: bool = False  # BFGS stalled close to the optimum: the next step is Newton's
    creeping: int = 0  # consecutive steps accepted at below CREEP_FRACTION of their first trial


def _bounds(template, names):
    n = len(names)
    lower = np.full(n, -np.inf)
    upper = np.full(n, np.inf)
    if isinstance(template, (Harmonic, PowerLaw)):
        lower[1] = 0.0  # A1 >= 0
    if isinstance(template, PowerLaw):
        lower[2], upper[2] = DUTY_CYCLE_MARGIN, 1.0 - DUTY_CYCLE_MARGIN
        lower[3] = lower[4] = 1.0
    return lower, upper


def _projected(problem, x, g):
    """Gradient with the components held at a bound (pointing outward) set to zero."""
    pg = g.copy()
    at_lower = (x <= problem.lower) & (g > 0)
    at_upper = (x >= problem.upper) & (g < 0)
    pg[at_lower | at_upper] = 0.0
    return pg


def _difference_hessian(problem, state, free_mask, u0):
    """Forward differences of the exact gradient on the free variables (from ``state.g``),
    symmetrised; None if a solve fails."""
    idx = np.flatnonzero(free_mask)
    n = idx.size
    H = np.zeros((n, n))
    for j, i in enumerate(idx):
        # small: the regularised Coulomb objective changes its curvature by ~10% over 1e-4
        # and still visibly over 1e-7 (stick-slip features: F_uu ~ 1/delta_tau^2); Newton
        # converges quadratically with 1e-8, where the gradient (exact to ~1e-10) still
        # gives the Hessian to ~1e-5
        eps = HESSIAN_STEP * max(1.0, abs(state.x[i]))
        xp = state.x.copy()
        xp[i] += eps
        fp, gp, _ = problem.evaluate(xp, u0)
        if gp is None:
            return None
        H[:, j] = (gp[idx] - state.g[idx]) / eps
    return 0.5 * (H + H.T)


def initial_state(problem, x0, u0=None, result=None):
    """The state at x0: evaluated from ``u0`` (default: the fast-motion limit), or taken from
    ``result``, a ``GradientResult`` of the problem's objective at x0 on its grid."""
    if result is not None and result.status == 0 and not hasattr(problem, "power"):
        full = problem.full(x0)
        g_full = result.gradient.copy()
        g_full[-1] *= full[-1]  # d/dlog T
        f, g, res = -problem.sign * result.value, -problem.sign * g_full[problem.free], result
    else:
        f, g, res = problem.evaluate(x0, u0)
    n = x0.size
    gnorm = float(np.linalg.norm(_projected(problem, x0, g))) if g is not None else math.nan
    return State(x=x0, f=f, g=g, hinv=np.eye(n), result=res, first_gradient_norm=gnorm,
                 stop_reason="" if g is not None else "solve_failed")


def optimizer_step(problem, state, *, max_step, newton_switch, max_condition, c1=1e-4,
                   creep_limit=0):
    """One accepted step (BFGS or Newton), or the state with a stop reason.  With
    ``creep_limit`` > 0 the step that makes ``creep_limit`` creeping steps in a row (accepted
    at below ``CREEP_FRACTION`` of the first trial) is taken and the state gets the stop
    reason "creeping" (``optimize_motion`` then adapts the steps there)."""
    x, f, g = state.x, state.f, state.g
    u0 = state.result.u0
    pg = _projected(problem, x, g)
    free = pg != 0.0
    gnorm = float(np.linalg.norm(pg))
    newton = False
    cond = state.condition_number
    hinv = state.hinv
    wait = max(state.hessian_wait - 1, 0)
    close = gnorm < newton_switch * state.first_gradient_norm
    if close and state.stalled and state.hessian_wait == 0:
        H = _difference_hessian(problem, state, free, u0)
        if H is not None:
            eig = np.linalg.eigvalsh(H)
            cond = float(abs(eig).max() / max(abs(eig).min(), 1e-300))
            if cond > max_condition:
                return replace(state, stop_reason="ill_conditioned", condition_number=cond,
                               ill_conditioned=True)
            if eig.min() > 0:
                newton = True
                d = np.zeros_like(x)
                d[free] = -np.linalg.solve(H, g[free])
                hinv = np.eye(x.size)
                hinv[np.ix_(free, free)] = np.linalg.inv(H)
            else:
                wait = HESSIAN_WAIT
    if not newton:
        d = np.zeros_like(x)
        d[free] = -(hinv[np.ix_(free, free)] @ g[free])
        if d @ g >= 0:  # not a descent direction: restart from steepest descent
            hinv = np.eye(x.size)
            d = -pg
    size = np.linalg.norm(d)
    if size > max_step:
        d *= max_step / size
    slope = float(d @ g)
    alpha = 1.0
    accepted = None
    # trial points are solved without their gradient (the adjoint sweep): only the
    # accepted one is differentiated
    tried = alpha
    while alpha >= MIN_STEP_FRACTION:
        tried = alpha
        xt = np.clip(x + alpha * d, problem.lower, problem.upper)
        ft, trial = problem.solve(xt, u0)
        if ft <= f + c1 * alpha * slope:
            accepted = (xt, ft) + problem.differentiate(trial)
            break
        if newton and alpha == 1.0 and ft <= f + F_NOISE * abs(f):
            # near the optimum the decrease of f is below the objective's noise (~1e-13):
            # a full Newton step that reduces the gradient is accepted on that
            gt, rt = problem.differentiate(trial)
            if gt is not None and np.linalg.norm(_projected(problem, xt, gt)) < gnorm:
                accepted = (xt, ft, gt, rt)
                break
        if math.isfinite(ft) and ft > f + slope * alpha:
            # the minimiser of the quadratic through f, the slope and ft, kept in
            # [0.1, 0.5] alpha (Nocedal & Wright 3.5): far fewer cuts than halving when
            # the step overshoots a sharp valley by orders of magnitude
            alpha *= min(max(-0.5 * slope * alpha / (ft - f - slope * alpha), 0.1), 0.5)
        else:
            alpha *= 0.5
    if (accepted is not None and alpha == 1.0 and not newton
            and float((accepted[0] - x) @ (accepted[2] - g)) <= 0.0):
        # the full step was accepted at once along negative curvature, where BFGS cannot
        # learn a step length: extrapolate while f keeps falling
        best = None
        while 2.0 * alpha * np.linalg.norm(d) <= max_step:
            xt = np.clip(x + 2.0 * alpha * d, problem.lower, problem.upper)
            ft, trial = problem.solve(xt, u0)
            best_f = accepted[1] if best is None else best[1]
            if ft > best_f or ft > f + c1 * 2.0 * alpha * slope:
                break
            alpha *= 2.0
            best = (xt, ft, trial)
        if best is not None:
            accepted = best[:2] + problem.differentiate(best[2])
    if accepted is None and close and not newton and not state.stalled:
        return replace(state, stalled=True)  # BFGS failed close to the optimum: try Newton
    if accepted is None:
        # no decrease at any step: rounding-level flatness (ill-conditioned) or a bad direction
        flat = abs(slope) * tried < 1e-14 * max(abs(f), 1e-300)
        reason = "ill_conditioned" if flat else "line_search_failed"
        return replace(state, stop_reason=reason, ill_conditioned=flat, condition_number=cond)
    xt, ft, gt, rt = accepted
    s = xt - x
    if np.linalg.norm(s) <= 1e-14 * (1.0 + np.linalg.norm(x)):
        if close and not newton and not state.stalled:
            return replace(state, stalled=True)
        return replace(state, stop_reason="no_progress", condition_number=cond)
    y = gt - g
    sy = float(s @ y)
    if not newton and sy > 1e-12 * np.linalg.norm(s) * np.linalg.norm(y):
        if state.iteration == 0 and np.allclose(hinv, np.eye(x.size)):
            hinv = hinv * (sy / float(y @ y))  # scale the first approximation (Nocedal-Wright 6.20)
        rho = 1.0 / sy
        V = np.eye(x.size) - rho * np.outer(s, y)
        hinv = V @ hinv @ V.T + rho * np.outer(s, s)
    new_norm = float(np.linalg.norm(_projected(problem, xt, gt)))
    creeping = state.creeping + 1 if alpha < CREEP_FRACTION else 0
    return State(x=xt, f=ft, g=gt, hinv=hinv, result=rt, iteration=state.iteration + 1,
                 newton_steps=state.newton_steps + int(newton),
                 condition_number=cond, first_gradient_norm=state.first_gradient_norm,
                 hessian_wait=wait, stalled=not newton and new_norm > STALL_RATIO * gnorm,
                 creeping=creeping,
                 stop_reason="creeping" if 0 < creep_limit <= creeping else "")


def _terminate(problem, state, gtol, max_iterations):
    if state.stop_reason:
        return True
    if float(np.linalg.norm(_projected(problem, state.x, state.g))) < gtol:
        return True
    return state.iteration >= max_iterations


def _same_grid(new_grid, grid, template, full):
    """Whether two step sequences are the same at the family parameters of ``full``."""
    kin = with_family_parameters(template, full[:-1])
    return new_grid.n_steps == grid.n_steps and np.allclose(new_grid.nodes(kin), grid.nodes(kin))


def _drain(problem, totals):
    """Move the problem's work counts into the totals over grid rounds."""
    totals["solves"] += problem.counts["solves"]
    totals["gradient_evaluations"] += problem.counts["gradients"]
    problem.counts.update(solves=0, gradients=0)


def variables(template, physics, start, period_range=(1e-3, 1e4)):
    names, values = family_parameters(template)
    if start is None:
        full = np.append(values, physics.period[0])
    else:
        full = np.asarray(start, dtype=float).copy()
    if full.size != len(names) + 1:
        raise ValueError(f"start: expected {len(names) + 1} values ({names} and the period), "
                         f"got {full.size}")
    if not np.all(np.isfinite(full)) or full[-1] <= 0:
        raise ValueError("start: values must be finite and the period > 0")
    free = np.ones(full.size, dtype=bool)
    if isinstance(template, Fourier) and template.max_wavenumber >= 1:
        free[names.index("B1")] = False
        full[names.index("B1")] = 0.0  # the phase
    lower, upper = _bounds(template, names)
    log_t = math.log(full[-1])
    return (names, full, np.flatnonzero(free), np.append(lower, log_t + math.log(period_range[0])),
            np.append(upper, log_t + math.log(period_range[1])))


@dataclass(frozen=True)
class OptimizerOptions:
    """The settings of ``optimize_motion`` (each also a keyword of it, which overrides these).

    objective : {"efficiency", "speed", "speed_at_power"}
        Maximise |lambda| (eq. lambdap), |U| (eq. U), or |U| subject to P = ``power``
        (eq. powerp), keeping the sign of the start.  "speed_at_power" eliminates the
        constraint exactly: the variables are the family's parameters only and T(theta)
        solves P(theta, T) = power (``speed_at_power`` in ``adjoint.gradient``); the gradient is
        the exact one along the constraint.  At fixed P, maximising |U| is maximising
        |lambda| = |U|^(p+1)/P on that surface, a different problem from the unconstrained
        maximum of |lambda| (which picks its own P).
    power : float, optional
        The fixed mean power of "speed_at_power" (default: P at the start).
    direction : {None, -1, +1}
        Sign of U sought: None keeps the sign at the start (maximise |objective| in its
        basin); -1 minimises the objective as the paper does ("by minimizing lambda, the
        algorithm chooses motions with U < 0"), so a start moving forwards crosses U = 0.
    gtol : float
        Stop when the projected gradient norm (variables: parameters, log T) is below it.
    max_iterations : int
        Accepted steps per grid round.
    grid_rtol, grid_rounds : float, int
        Without a ``grid`` the steps are those of the order-5 engine's solve at ``grid_rtol``
        (``adaptive_grid``), re-adapted at the optimum up to ``grid_rounds`` times.
    max_step : float
        Longest step in the variables (the damping of the line search).
    newton_switch : float
        Newton steps are tried once the projected gradient norm has fallen below this
        fraction of its value at the start of the grid round, and there only when BFGS
        stalls (a step keeps more than ``STALL_RATIO`` of the gradient norm, or fails).
        Each difference Hessian costs n gradients; switching late (1e-5 rather than 1e-3)
        lets BFGS do the descent and Newton only finish: measured at Kmax = 7,
        mu_n/mu_s = 2^-4, three starts, 542 instead of 713 gradient evaluations to the same
        optima (gradient norm < 1e-7).  Newton only on a stall: 8 starts, 1,289 instead of
        1,348 solves and 1,039 instead of 1,114 gradients, the same 8 optima, all to gtol
        (BFGS alone left 4 of them at |g| ~ 1e-7 with no progress).
    max_condition : float
        Hessian condition number at which the search stops as ill-conditioned.
    ill_condition_threshold : float
        A search that ends unconverged, or at a bound, is diagnosed from the difference
        Hessian at its end: ill-conditioned above this condition number.
    period_range : (float, float)
        Box for T relative to the starting period (T runs away as p -> 2).
    creep_steps : int
        Creeping steps in a row (accepted at below ``CREEP_FRACTION`` of their first trial)
        that end a grid round (0: never); measured on fourier_optima, docs/validation.md.
        This and the next three are off by default: with them on (3, True, 1e-4, True) the
        ensembles did 0.87-0.88 of the gradient evaluations, but the best optimum of 7 of 23
        complete cells fell by more than 1e-4 (docs/validation.md, issue 35).
    creep_final : bool
        In the last round (or on a fixed grid) creeping ends the search as a failed line
        search; else the last round creeps on until its line search fails.
    early_gtol : float
        Gradient tolerance of the rounds before the last (the larger of it and gtol).
    warm_rounds : bool
        Start the first round from the probe's solution and a later one from the last
        round's u(0) instead of re-solving from the fast-motion limit.
    certify_tolerance, certify_rounds : float, int
        Certification of the optimum (adaptive steps only; a fixed ``grid`` is reported, not
        certified): the final motion is solved again by the engine at ``CHECK_RTOL`` and its
        value compared with the frozen steps' (``grid_error``).  Above ``certify_tolerance``
        the frozen steps flatter the optimum (the search exploits their error: issue 47, at
        mu_n/mu_s = 2^-8, Kmax 1 one start ended at lambda/lambda_ub 0.234152 on its steps,
        0.233817 by the engine), and the search goes on from there on steps adapted at
        ``grid_rtol`` / 10, then / 100, up to ``certify_rounds`` times, until the error is
        within the tolerance.  ``certified`` says whether it is.  The default 1e-4 is issue
        47's: the paper prints relative efficiencies to three digits.
    certify_floor : float
        Where |the engine's value| is below this, the error is measured against the floor
        instead (certified: |value - engine value| <= certify_tolerance x certify_floor): a value
        at rounding level (isotropic friction at p >= 1: lambda ~ 1e-35) has no relative
        error to certify.  The optima pipeline passes 1e-6 lambda_ub (``_optima.STILL_EFFICIENCY``).
    certify_gradient_norm : float
        Searches on finer steps only for an end whose projected gradient norm is at most this
        (a start that is no candidate optimum is judged, ``certified``, but not searched again):
        the optima pipeline passes its acceptance (``keep.accept_gradient_norm`` or gtol).
    fidelity, fidelity_gtol : float
        Coarse stage (off at ``fidelity`` = 1).  Switching rule: the descent starts on steps
        adapted at ``fidelity`` x ``grid_rtol`` (at most 0.1) and stays there, one round,
        while the projected gradient norm is above ``fidelity_gtol`` (or until that round
        ends otherwise); from where it stands the fine rounds (``grid_rtol``, Newton near the
        optimum) go on as without it, and certification after them.  Measured in
        docs/validation.md (issue 47): no saving, so off.
    """

    objective: str = "efficiency"
    power: float | None = None
    direction: int | None = None
    gtol: float = 1e-7
    max_iterations: int = 200
    grid_rtol: float = 1e-6
    grid_rounds: int = 3
    max_step: float = 0.5
    newton_switch: float = 1e-5
    max_condition: float = 1e12
    ill_condition_threshold: float = 1e6
    period_range: tuple = (1e-3, 1e4)
    creep_steps: int = 0
    creep_final: bool = False
    early_gtol: float = 0.0
    warm_rounds: bool = False
    certify_tolerance: float = 1e-4
    certify_rounds: int = 2
    certify_floor: float = 0.0
    certify_gradient_norm: float = math.inf
    fidelity: float = 1.0
    fidelity_gtol: float = 1e-2


def optimize_motion(family_template, physics_template, start=None, *, grid=None, options=None,
                    **settings):
    """Maximise |lambda| (or |U|, or |U| at fixed P) over a family's parameters and the period.

    Parameters
    ----------
    family_template : Harmonic | Fourier | PowerLaw
        One point; fixes the structure (K, concavity flags) and the default start.
    physics_template : Physics
        One point; mu_n, mu_s, p, delta are fixed, its period is the default start.
    start : array_like, optional
        Family parameters (``family_parameters`` order) then the period T.
        For Fourier B1 is set to 0 (phase).
    grid : FixedGrid or int, optional
        A fixed grid (no re-adaptation), or a number of uniform steps; default: the step
        sequence of the order-5 engine's solve at ``grid_rtol`` (``adaptive_grid``),
        re-adapted at the optimum up to ``grid_rounds`` times.
    options : OptimizerOptions, optional
        The settings (default ``OptimizerOptions()``).
    **settings
        Fields of ``OptimizerOptions`` by name (objective=..., gtol=..., ...), replacing
        those of ``options``; another name is a TypeError.

    Returns
    -------
    OptimizeResult
    """
    unknown = sorted(set(settings) - set(OptimizerOptions.__dataclass_fields__))
    if unknown:
        raise TypeError(f"optimize_motion: unknown setting(s) {', '.join(unknown)} (the fields "
                        f"of OptimizerOptions)")
    opts = replace(options if options is not None else OptimizerOptions(), **settings)
    objective, power, direction = opts.objective, opts.power, opts.direction
    gtol, max_iterations = opts.gtol, opts.max_iterations
    grid_rtol, grid_rounds = opts.grid_rtol, opts.grid_rounds
    if objective not in OBJECTIVES:
        raise ValueError(f"objective: expected one of {OBJECTIVES}, got {objective!r}")
    constrained = objective == "speed_at_power"
    if len(family_template) != 1 or len(physics_template) != 1:
        raise ValueError("one parameter point at a time")
    t_start = time.perf_counter()
    cpu_start = time.thread_time()
    names, full, free, lower, upper = variables(family_template, physics_template, start,
                                                opts.period_range)
    if constrained:  # the period is fixed by P = power, not a variable
        free, lower, upper = free[:-1], lower[:-1], upper[:-1]
    kin = with_family_parameters(family_template, full[:-1])
    phys = with_period(physics_template, full[-1])
    fixed_grid = grid is not None
    if isinstance(grid, (int, np.integer)):
        grid = FixedGrid.uniform(kin, int(grid))
    elif grid is None:
        grid = adaptive_grid(kin, phys, rtol=grid_rtol)
    totals = dict(iterations=0, newton_steps=0, gradient_evaluations=0, solves=0)
    state = problem = probe = None
    sign = None
    hinv = None
    rounds = 0

    def descend(grid, rtol, n_rounds, fixed, stage_gtol):
        """Grid rounds from ``full`` on ``grid`` (re-adapted at ``rtol`` where a round ends, up
        to ``n_rounds`` grids, none when ``fixed``) to ``stage_gtol``; the last grid."""
        nonlocal state, problem, sign, hinv, rounds, full, kin, phys, power, probe
        for k in range(n_rounds):
            rounds += 1
            x0 = full[free].copy()
            if not constrained:
                x0[-1] = math.log(full[-1])
            if sign is None:
                probe = objective_gradient(kin, phys, grid,
                                           objective="speed" if constrained else objective)
                if probe.status != 0:
                    break
                sign = 1.0 if probe.value >= 0 else -1.0
                if direction is not None:
                    sign = math.copysign(1.0, direction)
                power = probe.P if power is None else float(power)
            if constrained:
                problem = _PowerConstrainedProblem(family_template, phys, grid, objective, sign,
                                                   free, full, lower[free], upper[free],
                                                   power=power)
            else:
                problem = Problem(family_template, physics_template, grid, objective, sign, free,
                                  full, lower[free], upper[free])
            if opts.warm_rounds and not constrained:
                # the first round starts from the probe (the same point on the same steps), a
                # later one from u(0) of the last round's end (the same point on the old steps)
                state = (initial_state(problem, x0, result=probe) if rounds == 1
                         else initial_state(problem, x0, u0=state.result.u0))
            else:
                state = initial_state(problem, x0)
            if hinv is not None and state.g is not None:
                state = replace(state, hinv=hinv)
            # creeping ends a round (not the last): the steps are adapted where the search stands;
            # in the last round it ends the search (``creep_final``) as a failed line search
            last = fixed or k == n_rounds - 1
            limit = opts.creep_steps if not last or opts.creep_final else 0
            round_gtol = stage_gtol if last else max(stage_gtol, opts.early_gtol)
            new_grid = None
            while True:
                while not _terminate(problem, state, round_gtol, max_iterations):
                    state = optimizer_step(problem, state, max_step=opts.max_step,
                                           newton_switch=opts.newton_switch,
                                           max_condition=opts.max_condition, creep_limit=limit)
                if state.stop_reason == "creeping" and last:
                    state = replace(state, stop_reason="line_search_failed")
                    break
                loose = (round_gtol > stage_gtol and not state.stop_reason
                         and state.iteration < max_iterations)
                if state.stop_reason != "creeping" and not loose:
                    break
                at = problem.full(state.x)
                new_grid = adaptive_grid(with_family_parameters(family_template, at[:-1]),
                                         with_period(physics_template, at[-1]), rtol=rtol)
                if not _same_grid(new_grid, grid, family_template, at):
                    break
                # the steps would not change: go on on them to gtol, as without the limit
                state, limit, round_gtol, new_grid = replace(state, stop_reason=""), 0, stage_gtol, None
            totals["iterations"] += state.iteration
            totals["newton_steps"] += state.newton_steps
            _drain(problem, totals)
            if state.g is None:
                return grid
            full = problem.full(state.x)
            kin = with_family_parameters(family_template, full[:-1])
            phys = with_period(physics_template, full[-1])
            hinv = state.hinv
            # a failed line search on the frozen steps is most often a fold of their stage
            # equations far from where the steps were adapted (the discrete objective jumps
            # there): adapt the steps where the search stands and go on (measured on the
            # fourier_optima scene, Kmax 7 and 10 at mu_n/mu_s >= 16: 10-12 of 12 starts ended
            # "line_search_failed" on the start's steps)
            # (a search that creeps, ``creep_steps``, stands at such a jump too: measured on the
            # same scene, 42 of 107 runs of creeping steps went on for more than 10 steps, and 41
            # of them ended by a failed line search, 35 % of all solves)
            if fixed or (state.stop_reason
                          and state.stop_reason not in ("line_search_failed", "creeping")):
                return grid
            if new_grid is None:
                new_grid = adaptive_grid(kin, phys, rtol=rtol)
            if _same_grid(new_grid, grid, family_template, full):
                return grid
            grid = new_grid
        return grid

    coarse_iterations = 0
    if opts.fidelity > 1.0 and not fixed_grid and not constrained:
        # coarse stage: the descent far from an optimum on steps adapted at a looser rtol, until
        # the projected gradient norm falls below ``fidelity_gtol`` (or the coarse round ends)
        coarse_rtol = min(grid_rtol * opts.fidelity, 0.1)
        grid = descend(adaptive_grid(kin, phys, rtol=coarse_rtol), coarse_rtol, 1, False,
                       max(gtol, opts.fidelity_gtol))
        coarse_iterations = totals["iterations"]
        if state is not None and state.g is not None:
            grid = adaptive_grid(kin, phys, rtol=grid_rtol)
    if state is None or state.g is not None:
        grid = descend(grid, grid_rtol, 1 if fixed_grid else grid_rounds, fixed_grid, gtol)
    certify_rounds = 0
    check = None
    if state is not None and state.g is not None:
        value, _, P, _, _ = _outputs(state.result)
        check = _engine_check(kin, phys, objective, value, P)
        # certification: an optimum of the frozen steps whose value is off the engine's by more
        # than ``certify_tolerance`` is searched again on steps adapted at rtol / 10 (then / 100)
        # from where it stands; what it ends with is what the engine certifies, or not
        while (not fixed_grid and certify_rounds < opts.certify_rounds
               and not _certified(check, opts)
               and float(np.linalg.norm(_projected(problem, state.x, state.g))) <= opts.certify_gradient_norm):
            certify_rounds += 1
            fine_rtol = grid_rtol * 10.0 ** -certify_rounds
            try:
                grid = adaptive_grid(kin, phys, rtol=fine_rtol)
            except RuntimeError:  # no converged solve to adapt the steps to: stays uncertified
                break
            try:
                grid = descend(grid, fine_rtol, grid_rounds, False, gtol)
            except RuntimeError:
                # the steps could not be re-adapted where a round ended (e.g. a body nearly at
                # rest): the state is that round's end on its own steps, judged as it is
                pass
            if state.g is None:
                break
            value, _, P, _, _ = _outputs(state.result)
            check = _engine_check(kin, phys, objective, value, P)
    res = state.result if state is not None else None
    if res is None or state.g is None:
        nan = np.full(len(names) + 1, np.nan)
        return OptimizeResult(kin, phys, names + ["period"], full, math.nan, math.nan, math.nan,
                              math.nan, nan, math.nan, totals["iterations"],
                              totals["newton_steps"], totals["gradient_evaluations"],
                              "solve_failed", False, False, math.nan, grid.n_steps, rounds,
                              time.perf_counter() - t_start, solves=totals["solves"],
                              coarse_iterations=coarse_iterations,
                              cpu_seconds=time.thread_time() - cpu_start)
    gnorm = float(np.linalg.norm(_projected(problem, state.x, state.g)))
    reason = state.stop_reason or ("gradient_tolerance" if gnorm < gtol else "max_iterations")
    all_names = names + ["period"]
    bound_names = tuple(all_names[i] for j, i in enumerate(free)
                        if state.x[j] <= problem.lower[j] or state.x[j] >= problem.upper[j])
    cond = state.condition_number
    ill = state.ill_conditioned
    if not ill and (reason != "gradient_tolerance" or bound_names):
        # diagnose why it did not converge (or sits at a bound): the curvature at the end
        H = _difference_hessian(problem, state, np.ones(state.x.size, dtype=bool), res.u0)
        _drain(problem, totals)
        if H is not None:
            eig = np.abs(np.linalg.eigvalsh(H))
            cond = float(eig.max() / max(eig.min(), 1e-300))
            ill = cond > opts.ill_condition_threshold
        # T at its bound: the optimum runs off to T -> infinity (p -> 2, where lambda becomes
        # invariant under T): the paper's ill-conditioned regime, reported rather than chased
        ill = ill or "period" in bound_names
    value, U, P, efficiency, gradient = _outputs(res)
    return OptimizeResult(
        kinematics=kin, physics=phys, names=all_names, parameters=full, value=value,
        U=U, P=P, efficiency=efficiency, gradient=gradient, gradient_norm=gnorm,
        iterations=totals["iterations"], newton_steps=totals["newton_steps"],
        gradient_evaluations=totals["gradient_evaluations"], stop_reason=reason,
        converged=reason == "gradient_tolerance", ill_conditioned=bool(ill),
        condition_number=cond, n_steps=grid.n_steps, grid_rounds=rounds,
        seconds=time.perf_counter() - t_start, at_bounds=bound_names, solves=totals["solves"],
        certified=_certified(check, opts), certify_rounds=certify_rounds,
        coarse_iterations=coarse_iterations, cpu_seconds=time.thread_time() - cpu_start, **check)


def _certified(check, opts) -> bool:
    """grid_error within ``certify_tolerance``, measured against ``certify_floor`` where the
    engine's value is smaller (``OptimizerOptions``)."""
    scale = max(1.0, opts.certify_floor / abs(check["engine_value"])) if check["engine_value"] else math.inf
    return bool(check["grid_error"] <= opts.certify_tolerance * scale)


def _engine_check(kinematics, physics, objective, value, P):
    """The final motion's outputs by the engine at ``CHECK_RTOL`` and the fixed grid's error
    against them (``OptimizeResult``'s engine_* fields and grid_error)."""
    r = solve_periodic(kinematics, physics, rtol=CHECK_RTOL)
    U_e, P_e, lam_e = float(r.U[0]), float(r.P[0]), float(r.efficiency[0])
    value_e = lam_e if objective == "efficiency" else U_e
    error = abs(value - value_e) / abs(value_e)
    if objective == "speed_at_power":
        error = max(error, abs(P - P_e) / abs(P_e))
    return dict(engine_value=value_e, engine_U=U_e, engine_P=P_e, engine_efficiency=lam_e,
                grid_error=float(error) if math.isfinite(error) else math.nan)
