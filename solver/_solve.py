"""``solve_periodic``: the public entry point of the solver layer.

Both methods refine the tau-grid by doubling until an error estimate is
below ``rtol``.  With Q_k the period integrals on the k-th grid (N_k = N_0 2^k
steps) and D_k = |Q_k - Q_{k-1}| in the norm below, the error of Q_k is
estimated as max(D_k, D_{k-1} / 2^order) (see ``_estimate``).  Three
successful levels are needed before a point can be accepted.

Error norm.  For P (always > 0) the error is relative.  U can vanish (for
example at isotropic friction and p = 1), so its error is measured relative
to max(|U T|, 1e-3 V), with V = (1/4) int |dphi/dtau| dtau the deformation
speed scale (``kinematic_speed``).  ``error_estimate`` is the larger of the
two.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, fields

import numpy as np

from . import _march, _periodic
from ._kinematics import period_grid
from ._limits import fast_limit_velocity, kinematic_speed
from ._physics import Physics
from ._status import CONVERGED, NO_MOTION, TOLERANCE_NOT_REACHED, UNSTABLE

METHODS = ("periodic", "march")
U_FLOOR_FRACTION = 1e-3
MARCH_MAX_STEPS = 2 ** 22  # steps per level (periods x steps per period) before giving up


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

    def point(self, i):
        """Dict of the scalar outputs of point ``i``."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray) and v.ndim == 1:
                out[f.name] = v[i].item()
        return out


def _outputs(int_u, int_pi, physics):
    T, p = physics.period, physics.p
    U = int_u / T
    P = int_pi * T ** -(p + 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        efficiency = np.sign(U) * np.abs(U) ** (p + 1.0) / P
    geo = physics.mu_n * physics.mu_s
    lam_ub = 1.0 / np.minimum(physics.mu_n, physics.mu_s)
    return dict(
        U=U, P=P, efficiency=efficiency,
        scaled_speed=geo ** (1.0 / (2.0 * p - 4.0)) * U,
        scaled_power=geo ** (3.0 / (2.0 * p - 4.0)) * P,
        scaled_efficiency=np.sqrt(geo) * efficiency,
        efficiency_upper_bound=lam_ub,
        relative_efficiency=efficiency / lam_ub,
        mean_u=int_u,
    )


def _estimate(history_u, history_pi, k, u_floor, order):
    """Error estimate of level k from levels k-2, k-1, k (arrays over the active points).

    max(D_k, D_{k-1} / 2^order): the last difference bounds the error once the
    sequence converges at order >= 1, and the previous difference reduced by
    the method's order guards against a D_k that is small by chance (the
    sticking and velocity-reversal events of Coulomb friction make the
    convergence irregular, so a ratio-based extrapolation is not trusted).
    """
    scale_u = np.maximum(np.abs(history_u[k]), u_floor)
    scale_p = np.abs(history_pi[k])

    def diff(j):
        return np.maximum(np.abs(history_u[j] - history_u[j - 1]) / scale_u,
                          np.abs(history_pi[j] - history_pi[j - 1]) / scale_p)

    return np.maximum(diff(k), diff(k - 1) / 2.0 ** order)


def _run_level(method, code, params, grids, physics, u0, vscale, rtol, return_series, index):
    """One grid level for the points ``index``: (int_u, int_pi, u0, status, iterations, series)."""
    args = (code, params[index], grids, physics.inertia_factor[index], physics.mu_n[index],
            physics.mu_s[index], physics.p[index], physics.delta_tau[index], u0[index],
            np.maximum(vscale[index], 1e-300), float(rtol))
    if method == "periodic":
        iu, ip, u0_new, st, its, _stage_its, ser = _periodic.solve_points(*args, return_series)
    else:
        iu, ip, u0_new, st, its, ser = _march.march_points(*args, MARCH_MAX_STEPS, return_series)
    return iu, ip, u0_new, st, its, ser


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
    iu, ip, _, st, _, _ = _run_level(method, code, params, grids, physics, u0, vscale, rtol,
                                     False, np.arange(n))
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
        "periodic": Radau IIA (order 3, L-stable) on the periodic grid, solved by Newton on u(0).
        "march": explicit RK2 (Heun, order 2) from rest until periodic.
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
    spec = _SPECS[method]
    max_steps = max_steps_per_period or spec.max_steps_per_period
    n = len(kinematics)
    if len(physics) not in (1, n):
        raise ValueError(f"physics: length {len(physics)} does not match the kinematics' {n} points")
    if len(physics) == 1 and n > 1:
        physics = physics.take(np.zeros(n, dtype=int))
    start = time.perf_counter()
    code, params = kinematics.kernel_encoding()
    vscale = kinematic_speed(kinematics)
    u_floor = U_FLOOR_FRACTION * vscale

    int_u = np.full(n, np.nan)
    int_pi = np.full(n, np.nan)
    status = np.full(n, TOLERANCE_NOT_REACHED, dtype=np.int8)
    estimate = np.full(n, np.inf)
    iterations = np.zeros(n, dtype=np.int64)
    n_tau = np.zeros(n, dtype=np.int64)
    series = [None] * n if return_series else None
    series_tau = [None] * n if return_series else None

    still = vscale > 0
    status[~still] = NO_MOTION
    int_u[~still] = 0.0
    int_pi[~still] = 0.0
    estimate[~still] = 0.0
    active = np.flatnonzero(still)
    if method == "periodic":
        u0 = np.zeros(n)
        if active.size:
            u0[active] = fast_limit_velocity(kinematics.take(active), physics.take(active))
    else:
        u0 = np.zeros(n)  # from rest

    hist_u, hist_pi = [], []
    last_status = np.full(n, CONVERGED, dtype=np.int8)
    n_steps = spec.first_steps
    level = 0
    while active.size and n_steps <= max_steps:
        kin = kinematics.take(active)
        grids = period_grid(kin, n_steps)
        iu, ip, u0_new, st, its, ser = _run_level(method, code, params, grids, physics, u0,
                                                  vscale, rtol, return_series, active)
        iterations[active] += its
        last_status[active] = st
        ok = st == CONVERGED
        u0[active[ok]] = u0_new[ok]
        lvl_u = np.full(n, np.nan)
        lvl_pi = np.full(n, np.nan)
        lvl_u[active] = np.where(ok, iu, np.nan)
        lvl_pi[active] = np.where(ok, ip, np.nan)
        hist_u.append(lvl_u)
        hist_pi.append(lvl_pi)
        n_tau[active] = n_steps
        int_u[active] = lvl_u[active]
        int_pi[active] = lvl_pi[active]
        if return_series:
            for j, i in enumerate(active):
                series[i] = ser[j]
                series_tau[i] = grids[j, :-1]
        if level >= 2:
            est = _estimate([h[active] for h in hist_u], [h[active] for h in hist_pi], level,
                            u_floor[active], spec.order)
            est = np.where(np.isnan(est), np.inf, est)
            estimate[active] = est
            done = est <= rtol
            status[active[done]] = CONVERGED
            active = active[~done]
        level += 1
        n_steps *= 2

    failed = status != CONVERGED
    # report the kernel's own reason where the last grid failed outright
    kernel_failed = failed & (last_status != CONVERGED) & (status != NO_MOTION)
    status[kernel_failed] = last_status[kernel_failed]
    keep_nan = failed & (status != NO_MOTION)
    int_u[keep_nan] = np.nan
    int_pi[keep_nan] = np.nan
    out = _outputs(int_u, int_pi, physics)
    if np.any(~still):
        out["efficiency"][~still] = np.nan
        out["scaled_efficiency"][~still] = np.nan
        out["relative_efficiency"][~still] = np.nan
    u_arr = tau_arr = None
    if return_series:
        u_arr = [s if s is not None else np.array([]) for s in series]
        tau_arr = [s if s is not None else np.array([]) for s in series_tau]
        if len({len(s) for s in u_arr}) == 1:
            u_arr, tau_arr = np.array(u_arr), np.array(tau_arr)
    return SolveResult(
        **out, status=status, converged=status == CONVERGED, error_estimate=estimate,
        iterations=iterations, n_tau=n_tau, u=u_arr, tau=tau_arr,
        seconds=time.perf_counter() - start, method=method)
