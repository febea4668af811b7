"""``solve_periodic``: the public entry point of the solver layer.

Two methods, each a driver that returns the period integrals int_0^1 u dtau and
int_0^1 Pi dtau of every point with an error estimate and a status:

- ``"periodic"``, the engine (``periodic.driver``): event-driven 3-stage Radau IIA (order 5,
  L-stable, stiffly accurate), steps ending at the corners of phi and at the state events
  of the friction, Newton on u(0) by frozen-grid passes with the exact monodromy, and one
  pass of error control from the collocation polynomial's defect carried to the period
  integrals by the node weights (the discrete adjoint of the shooting);
- ``"march"``, the independent check (``march.driver``): explicit Heun RK2 from rest, period
  by period, on uniformly doubled corner-aligned grids, with a Richardson estimate; it
  reports UNSTABLE on stiff sticking rather than a wrong number.

``ENGINES`` names each method's scheme and version: a store records them and refuses to
resume one computed by another version.

Error norm.  For P (always > 0) the error is relative.  U can vanish (for example at
isotropic friction and p = 1), so its error is measured relative to max(|U T|, 1e-3 V), with
V = (1/4) int |dphi/dtau| dtau the deformation speed scale (``kinematic_speed``).
``error_estimate_U`` and ``error_estimate_P`` are the two estimates; ``error_estimate``, the
larger, is the one rtol bounds.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, fields

import numpy as np
from numba import get_num_threads

from .march import driver as march_driver
from . import periodic
from .model.kinematics import period_grid
from .model.limits import fast_limit_velocity, kinematic_speed
from .status import CONVERGED, NO_MOTION, OUT_OF_RANGE, TOLERANCE_NOT_REACHED

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
                       "error control (periodic.driver)", "5.3"),
    "march": Engine("march", "explicit Heun RK2 (order 2) from rest, period by period, on "
                    "doubled uniform grids with a Richardson estimate (march.driver)", "2.1"),
}
#: the u floor of U's error norm, as a share of V (module docstring)
U_FLOOR_FRACTION = 1e-3
#: the default ``max_steps_per_period``: steps of one pass (periodic), the finest grid (march)
MAX_STEPS_PER_PERIOD = 2 ** 17


@dataclass(frozen=True)
class SolveResult:
    """Outputs of ``solve_periodic``; every array has shape (n_points,) unless noted.

    U : mean velocity (eq. U); P : mean power (eqs. power, powerp);
    efficiency : lambda = sign(U) |U|^(p+1) / P (eqs. lambda, lambdap);
    scaled_speed : (mu_n mu_s)^(1/(2p-4)) U; scaled_power : (mu_n mu_s)^(3/(2p-4)) P;
    scaled_efficiency : sqrt(mu_n mu_s) lambda; efficiency_upper_bound : 1/min(mu_n, mu_s);
    relative_efficiency : lambda / lambda_ub (eq. relefficiency);
    status (int8, 0 = converged; ``status_reason``), converged (bool),
    error_estimate_U, error_estimate_P : the estimated error of U (relative to
    max(|U T|, 1e-3 V)) and of P (relative), see the module docstring;
    error_estimate : the larger of the two (the one ``rtol`` bounds; inf where none was
    formed, 0 for NO_MOTION);
    iterations (passes over the period for ``periodic``, periods marched for ``march``,
    summed over grids), n_tau (steps per period of the final step sequence);
    u : u(tau) at the final steps' nodes, the period closed: tau from 0 to 1 with u(1) =
    u(0), n_tau + 1 values per point; shape (n_points, n_tau + 1) where every point has as
    many, else a list of arrays (empty for a point that failed before any pass), or None
    (``return_series`` False).  The nodes are the engine's step ends (order-5 steps, few
    and long): a trapezoid over them is a second-order rule, not the engine's, and misses
    int u by O(h^2) (about 1e-3 of it at rtol 1e-6); ``mean_u`` is int_0^1 u dtau to rtol.
    tau : those nodes, same shape, or None.
    force_evaluations : evaluations of F per point: ``periodic`` by phase (loose shooting,
    target passes, frozen-grid passes, estimates; shape (n_points, 4)), ``march`` in all
    (shape (n_points, 1)).
    method : the method that computed it.
    start : how each point's solve started (``periodic``; None for ``march``): 0 cold,
    1 warm from its sweep's previous point, 2 warm failed, then cold
    (``periodic.point.START_*``).
    options : the ``EngineOptions`` the engine ran with (``periodic``, the defaults where
    none were given; None for ``march``); ``periodic.options.engine_options(options)``
    lists them flat.
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
    error_estimate_U: np.ndarray
    error_estimate_P: np.ndarray
    iterations: np.ndarray
    n_tau: np.ndarray
    mean_u: np.ndarray
    u: np.ndarray | None = None
    tau: np.ndarray | None = None
    seconds: float = 0.0
    method: str = "periodic"
    force_evaluations: np.ndarray | None = None
    start: np.ndarray | None = None
    options: object | None = None

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


def solve_fixed_grid(kinematics, physics, n_steps, *, method="periodic", rtol=1e-12,
                     options=None):
    """Period integrals on one grid of ``n_steps`` steps, without refinement.

    For convergence studies (order tests, work-precision): the engine's 3-stage Radau IIA
    (``method="periodic"``) or the march's Heun steps (``"march"``; ``n_steps`` a multiple of
    8) on ``model.kinematics.period_grid``'s grid, uniform inside each phase of phi with its
    corners on nodes.  ``rtol`` only sets the tolerances of the nonlinear iterations
    (shooting, stage Newton, periodicity); ``options`` (``periodic`` only) the engine's
    ``EngineOptions`` (its tolerances', stage solve's and frozen passes' are used here).

    Returns
    -------
    mean_u, mean_power_density, status : ndarray, shape (n_points,)
        int_0^1 u dtau, int_0^1 Pi dtau (so U = mean_u / T, P = T^-(p+1) mean_power_density).
    """
    if method not in METHODS:
        raise ValueError(f"method: expected one of {METHODS}, got {method!r}")
    n = len(kinematics)
    if len(physics) == 1 and n > 1:
        physics = physics.take(np.zeros(n, dtype=int))
    if options is not None and method != "periodic":
        raise ValueError(f"options: the engine's options are for method 'periodic', not {method!r}")
    if method == "march":
        return march_driver.fixed_grid(kinematics, physics, n_steps, rtol=rtol)
    options = periodic.checked_options(options)
    code, params = kinematics.kernel_encoding()
    vscale = kinematic_speed(kinematics)
    u0 = fast_limit_velocity(kinematics, physics)
    grids = period_grid(kinematics, n_steps)
    points = periodic.Points(code, params, np.zeros((n, 0)), physics.inertia_factor,
                                    physics.mu_n, physics.mu_s, physics.p, physics.delta_tau, u0)
    return periodic.fixed_grid_points(points, grids, float(rtol),
                                             np.maximum(vscale, 1e-300), get_num_threads(),
                                             options)


def solve_periodic(kinematics, physics, *, method="periodic", rtol=1e-6, return_series=False,
                   max_steps_per_period=None, sweeps=None, options=None,
                   keep_unconverged=False):
    """Periodic steady state u(tau) of eq. (Newtonu) and its mean speed, power and efficiency.

    Parameters
    ----------
    kinematics : Harmonic | PowerLaw | Fourier
        phi(tau) for n_points parameter points.
    physics : Physics
        T, mu_n, mu_s, p, delta; length 1 or n_points.
    method : {"periodic", "march"}
        "periodic": the engine: event-driven 3-stage Radau IIA (order 5, L-stable) with
        one-pass error control, Newton on u(0) (``periodic.driver``).
        "march": explicit RK2 (Heun, order 2) from rest until periodic: the independent
        check (reports UNSTABLE on stiff sticking instead of a wrong number).
    rtol : float
        Target relative error of U and P (see the module docstring for the norm).
    return_series : bool
        Also return u(tau) at the final grid's nodes, the period closed (tau = 0 .. 1 with
        u(1) = u(0); ``SolveResult.u``, ``SolveResult.tau``).
    max_steps_per_period : int, optional
        Finest grid allowed (default 2^17).
    sweeps : array of int, optional
        Solve the points as sweeps (``periodic`` only): (n_sweeps + 1,) increasing offsets
        from 0 to n_points; points sweeps[k] .. sweeps[k + 1] - 1 form one sweep, solved in
        that order, each point starting from its predecessor's periodic orbit (its u(0),
        node weights and norm; ``periodic.point.warm_start``), the first cold.  Order the
        points so that neighbours follow each other (``snake_order``).  Every result is
        judged by the same error estimate as a cold solve; where the warm start fails the
        point is solved cold.  A sweep's results depend on its own points only.  Default:
        every point cold.
    options : EngineOptions, optional
        The engine's options passed at run time (``periodic`` only; ``periodic.options``:
        every tuning constant of the engine, by role: the step-size controller's,
        ``ControlOptions``, one point's solve's, ``PointOptions``, the turning-point
        traps', ``TrapOptions``, the kinematic stops', ``StopOptions``, the state events',
        ``EventOptions``, the step lengths', ``StepOptions``, the stage solve's,
        ``StageOptions``, the defect estimate's, ``DefectOptions``, the tolerances'
        factors, ``ToleranceOptions``, and the batches', ``BatchOptions``), e.g.
        ``EngineOptions(control=ControlOptions(max_factor=2.0))``.  Default: the documented
        defaults.  Any values run on the same compiled kernels; the result records them
        (``SolveResult.options``).
    keep_unconverged : bool
        ``march`` only.  Where the finest grid allowed marched to a periodic state but its
        error estimate stayed above rtol (status TOLERANCE_NOT_REACHED), return that grid's
        U, P and efficiency instead of NaN, keeping the status and ``error_estimate`` (the
        estimate of those values, in the norm above).  Default False: every point that is
        not converged is NaN, so that reductions (maxima, contours) cannot pick it up.

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
    if sweeps is not None:
        sweeps = _checked_sweeps(sweeps, n, method)
    if options is not None and method != "periodic":
        raise ValueError(f"options: the engine's options are for method 'periodic', not {method!r}")
    options = periodic.checked_options(options) if method == "periodic" else None
    if keep_unconverged and method != "march":
        raise ValueError(f"keep_unconverged: only method 'march' returns the values of its "
                         f"finest grid, not {method!r}")
    start = time.perf_counter()
    max_steps = max_steps_per_period or MAX_STEPS_PER_PERIOD
    if method == "periodic":
        out = periodic.solve(kinematics, physics, rtol, max_steps, return_series, sweeps, options)
    else:
        out = march_driver.solve(kinematics, physics, rtol, max_steps, return_series)
    return _result(out, physics, method, start, keep_unconverged)


#: points of one sweep where a caller cuts a batch into sweeps (``sweep_runs``): the
#: pipeline's chunks, ``tools.bench_sweep``, ``tools.honesty --sweeps``
SWEEP_POINTS = 64


def sweep_runs(n_points, length=SWEEP_POINTS):
    """``solve_periodic``'s ``sweeps`` offsets that cut ``n_points`` points, in order, into
    sweeps of ``length`` (the last shorter): (n_sweeps + 1,) int64 from 0 to n_points.

    >>> sweep_runs(150).tolist()
    [0, 64, 128, 150]
    """
    return np.unique(np.r_[np.arange(0, n_points, length), n_points]).astype(np.int64)


def snake_order(shape: tuple[int, ...]) -> np.ndarray:
    """The flat C-order indices of a grid of ``shape`` in snake (boustrophedon) order: the
    last axis runs forward, then backward, ..., each axis reversing whenever the axis before
    it steps, so that consecutive points are grid neighbours (they differ by one step along
    one axis).

    >>> snake_order((2, 3)).tolist()
    [0, 1, 2, 5, 4, 3]
    """
    order = np.arange(int(np.prod(shape, dtype=np.int64))).reshape(shape)
    for axis in range(len(shape) - 1):
        # reverse axis + 1 wherever the flat index of the axes up to ``axis`` is odd in
        # snake order: by parity of the (already snaked) outer position
        outer = int(np.prod(shape[:axis + 1], dtype=np.int64))
        flat = order.reshape(outer, -1, *shape[axis + 2:]) if axis + 2 < len(shape) else order.reshape(outer, -1)
        flat[1::2] = flat[1::2, ::-1].copy()
        order = flat.reshape(shape)
    return order.ravel()



def _checked_sweeps(sweeps, n, method):
    """``solve_periodic``'s ``sweeps`` as int64 offsets, or ValueError naming what is wrong."""
    if method != "periodic":
        raise ValueError(f"sweeps: only method 'periodic' starts points from their neighbours, "
                         f"not {method!r}")
    offsets = np.asarray(sweeps)
    if offsets.ndim != 1 or offsets.size < 2 or not np.issubdtype(offsets.dtype, np.integer):
        raise ValueError("sweeps: expected a 1-d integer array of offsets (n_sweeps + 1,)")
    if offsets[0] != 0 or offsets[-1] != n or np.any(np.diff(offsets) <= 0):
        raise ValueError(f"sweeps: offsets must rise strictly from 0 to n_points = {n}")
    return offsets.astype(np.int64)


def _result(out, physics, method, start, keep_unconverged=False):
    """The ``SolveResult`` of a driver's output dict (``periodic.solve``,
    ``march.driver.solve``: int_u, int_pi, status, estimate, n_tau, iterations, still,
    series, evaluations): the physical outputs, NaN where not converged, phi constant as
    NO_MOTION with U = P = 0, and U or P beyond the float range as OUT_OF_RANGE; with
    ``keep_unconverged`` the driver's ``unconverged`` values where it has them."""
    status = out["status"]
    still = out["still"]
    status[still] = NO_MOTION
    int_u = np.where(status == CONVERGED, out["int_u"], np.nan)
    int_pi = np.where(status == CONVERGED, out["int_pi"], np.nan)
    if keep_unconverged:
        kept = (status == TOLERANCE_NOT_REACHED) & np.isfinite(out["unconverged"][:, 0])
        int_u = np.where(kept, out["unconverged"][:, 0], int_u)
        int_pi = np.where(kept, out["unconverged"][:, 1], int_pi)
    int_u[still] = 0.0
    int_pi[still] = 0.0
    estimate = out["estimate"]
    estimate_U, estimate_P = out["estimate_u"], out["estimate_p"]
    for e in (estimate, estimate_U, estimate_P):
        e[still] = 0.0
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
        # the period closed: tau = 1 appended with u(1) = u(0), so that the series covers [0, 1]
        u_arr = [np.append(s[0], s[0][0]) if len(s[0]) else s[0] for s in out["series"]]
        tau_arr = [np.append(s[1], 1.0) if len(s[1]) else s[1] for s in out["series"]]
        if len({len(s) for s in u_arr}) == 1:
            u_arr, tau_arr = np.array(u_arr), np.array(tau_arr)
    return SolveResult(
        **outputs, status=status, converged=status == CONVERGED, error_estimate=estimate,
        error_estimate_U=estimate_U, error_estimate_P=estimate_P,
        iterations=out["iterations"], n_tau=out["n_tau"], u=u_arr, tau=tau_arr,
        seconds=time.perf_counter() - start, method=method,
        force_evaluations=out["evaluations"], start=out.get("start"), options=out.get("options"))
