"""The ``march`` method's own driver: the explicit march on uniformly doubled grids, with
the error of the period integrals estimated by Richardson extrapolation.

For each parameter point:

1. **Grid.** ``model.kinematics.period_grid(kinematics, N)``: N steps per period, uniform
   inside each phase of phi, its corners on nodes; doubling N bisects every step.
2. **March.** The discrete periodic state on that grid by ``march.heun.march_level``: Heun's
   explicit RK2 (order 2) marched period by period until the change of u(0) over a period,
   divided by one minus the observed contraction, is below 1e-5 rtol V (Aitken jumps
   where the contraction is slow).  The first grid starts from rest, every later one from
   the previous grid's periodic u(0).
3. **Estimate.** With I in {int_0^1 u dtau, int_0^1 Pi dtau} on N/4, N/2, N and 2N steps,
   the changes d0, d1, d2 between successive grids and their ratios r1 = d0 / d1,
   r2 = d1 / d2 (4 for order 2):

   * both ratios in (1.5, 8] (the changes shrink geometrically on two doublings in a row):
     err(I_2N) = |d2| max(1, 1 / (r2 - 1)), the last change itself, or the geometric tail
     at the observed ratio where that is larger (orders below 1, e.g. a corner of phi with a
     weak singularity).  In the asymptotic regime of order 2 (r = 4) the error is |d2| / 3:
     the factor 3 is the margin of an estimate that is simple rather than sharp.  A single
     ratio is not enough: where the friction stops the body inside a step, the uniform
     grids' errors wander with N (harmonic, mu_n/mu_s 2^-3, delta 1e-7: errors 7e-7, 1.7e-6,
     1.9e-6, 4e-7 of the norm on 512 .. 4,096 steps), and one ratio of 4.45 between two of
     them accepted 2,048 steps 1.9 rtol off at rtol 1e-6 (``tests/test_study.py``'s tiny
     study); with |d2| / 3 on a single ratio in [3, 6], 1 of 40 random harmonic points was
     1.8 rtol off at rtol 1e-3 (docs/validation.md);
   * otherwise (no asymptotic regime yet, or the changes at the periodicity test's noise):
     err(I_2N) = max(|d1|, |d2|), which only passes when both changes are below rtol.

   The estimate is for I_2N, the value returned (not the extrapolated one, whose error
   would have no estimate of its own).  It is taken in the solver's norm
   e = max(err(int u) / max(|int u|, 1e-3 V), err(int Pi) / |int Pi|),
   V = ``kinematic_speed``.  The point is converged when e <= rtol on a grid whose march
   does not chatter (below); otherwise N doubles.
4. **Stiffness.** The explicit step is stable only while h T^(2-p) |dF/du| stays below
   about 2; across a sticking band (|dF/du| ~ mu / delta_tau) a larger step chatters
   (``march.heun.step_jumps`` on consecutive steps), u stalls at ~h T^(2-p) mu instead of
   ~delta_tau, and that error falls only like h.  A grid whose chatter carries more than
   CHATTER_SHARE rtol of int u is not accepted.  The point is UNSTABLE when the finest grid
   still chatters, or earlier when two grids in turn chattered, resolving the band would
   need more than HOPELESS times ``max_steps`` steps (``march.heun.band_stiffness``), and the
   chatter's mass does not fall fast enough to become negligible by then (``_hopeless``).

Statuses: CONVERGED; UNSTABLE (chatter, or the march left every bound on the finest grid);
NON_FINITE; STEP_BUDGET_EXCEEDED (the march on the finest grid did not become periodic
within its period budget: MAX_PERIODS, at most MARCH_STEP_BUDGET steps, at least
MIN_PERIODS); TOLERANCE_NOT_REACHED (the finest grid allowed, N <=
``max_steps``, marched fine but its estimate is above rtol).  Every failure has NaN
integrals.
"""
from __future__ import annotations

import numpy as np

from ..model.kinematics import period_grid
from ..model.limits import kinematic_speed
from .heun import PhysicsColumns, march_level
from ..status import CONVERGED, NO_MOTION, TOLERANCE_NOT_REACHED, UNSTABLE

#: steps per period of the first grid (a multiple of 8: ``model.kinematics.phase_steps``)
FIRST_STEPS = 16
#: periods marched on one grid before STEP_BUDGET_EXCEEDED: MAX_PERIODS, but at most
#: MARCH_STEP_BUDGET steps, and never fewer than MIN_PERIODS (a coarse grid can settle on a
#: 2-cycle through a sticking band instead of a fixed point: harmonic_short_period burnt 2^22
#: steps on each of N = 16 .. 128; a fine grid of 2^20 steps needs tens of periods to become
#: periodic at short scaled periods, which 2^22 steps, 4 periods, cut off)
MAX_PERIODS = 4096
MARCH_STEP_BUDGET = 2 ** 22
MIN_PERIODS = 64
#: outside these ratios of successive differences no geometric tail is assumed at all (a
#: ratio far above 4 is as likely a change of sign passing through zero as fast convergence)
RATIO_FLOOR, RATIO_CEILING = 1.5, 8.0
#: the u floor of int u's norm, as a share of V (as ``solve.U_FLOOR_FRACTION``)
U_FLOOR_FRACTION = 1e-3
#: chatter matters when the |u| stalled in it carries this share of rtol of int u
CHATTER_SHARE = 0.1
#: give up on chatter when resolving the band needs this many times ``max_steps``
HOPELESS = 4
#: a step chatters from h T^(2-p) |dF/du| above about this (``march.heun.JUMP_LIMIT``)
CHATTER_STIFFNESS = 1.5


def richardson_error(d0, d1, d2):
    """The error of I_2N from the changes d0 = I_(N/2) - I_(N/4), d1 = I_N - I_(N/2) and
    d2 = I_2N - I_N (the module docstring's rule, step 3), elementwise; inf where d1 or d2
    is not finite (d0 NaN: no ratio r1 yet, so no geometric tail is assumed)."""
    d0, d1, d2 = (np.asarray(d, dtype=float) for d in (d0, d1, d2))
    with np.errstate(divide="ignore", invalid="ignore"):
        r1 = d0 / d1
        r2 = d1 / d2
        geometric = ((r1 > RATIO_FLOOR) & (r1 <= RATIO_CEILING)
                     & (r2 > RATIO_FLOOR) & (r2 <= RATIO_CEILING))
        tail = np.abs(d2) * np.maximum(1.0, 1.0 / (r2 - 1.0))
        err = np.where(geometric, tail, np.maximum(np.abs(d1), np.abs(d2)))
    return np.where(np.isfinite(d1) & np.isfinite(d2), err, np.inf)


def _norm(err_u, err_pi, int_u, int_pi, vscale):
    """(e_u, e_p): err_u / max(|int u|, 1e-3 V) and err_pi / |int Pi| (the estimate e is the
    larger)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return (err_u / np.maximum(np.abs(int_u), U_FLOOR_FRACTION * vscale),
                err_pi / np.abs(int_pi))


def _hopeless(N, stiffness, mass, last_mass, threshold, max_steps):
    """Points whose chatter will outlast the finest grid: resolving the band needs more
    than HOPELESS max_steps steps (N z / CHATTER_STIFFNESS, z = ``band_stiffness``), and so
    does waiting for its mass to fall below ``threshold`` at the rate observed between the
    last two grids (both chattered; an unknown or non-falling rate counts as never)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        rate = np.log2(last_mass / mass)
        grids_needed = np.where(rate > 0.5, np.log2(mass / threshold) / rate, np.inf)
        fading = N * 2.0 ** np.minimum(grids_needed, 60.0) <= HOPELESS * max_steps
    unresolvable = N * stiffness / CHATTER_STIFFNESS > HOPELESS * max_steps
    return unresolvable & ~fading & np.isfinite(last_mass)


def _march_grid(kinematics, physics, index, N, u_init, vscale, rtol):
    """``march_level`` for the points ``index`` on their N-step grids; returns its outputs
    and the grids (len(index), N + 1)."""
    code, params = kinematics.kernel_encoding()
    grids = period_grid(kinematics.take(index), N)
    columns = PhysicsColumns(physics.inertia_factor[index], physics.mu_n[index],
                             physics.mu_s[index], physics.p[index], physics.delta_tau[index])
    out = march_level(code, params[index], grids, columns, u_init,
                      np.maximum(vscale[index], 1e-300), float(rtol),
                      max(min(MARCH_STEP_BUDGET, MAX_PERIODS * N), MIN_PERIODS * N))
    return out, grids


def fixed_grid(kinematics, physics, n_steps, *, rtol=1e-10):
    """The march's periodic state on one grid of ``n_steps`` steps (a multiple of 8), no
    error control: for order studies.  ``rtol`` only sets the periodicity test.

    Returns
    -------
    int_u, int_pi : ndarray, shape (n_points,)
        int_0^1 u dtau and int_0^1 Pi dtau of the discrete periodic solution (NaN on failure).
    status : ndarray of int8, shape (n_points,)
    """
    n = len(kinematics)
    if len(physics) == 1 and n > 1:
        physics = physics.take(np.zeros(n, dtype=int))
    vscale = kinematic_speed(kinematics)
    out, _ = _march_grid(kinematics, physics, np.arange(n), n_steps, np.zeros(n), vscale, rtol)
    return out[0], out[1], out[3]


def solve(kinematics, physics, rtol, max_steps, return_series):
    """The periodic steady state of eq. (Newtonu) by the explicit march with Richardson error
    control (module docstring), for ``solve.solve_periodic(method="march")``.

    Parameters
    ----------
    kinematics : Harmonic | PowerLaw | Fourier
        phi(tau) for n_points points.
    physics : Physics
        length 1 or n_points.
    rtol : float
        Target error in the norm e above.
    max_steps : int
        Finest grid allowed (steps per period).
    return_series : bool
        Also return u at the nodes of each converged point's returned grid.

    Returns
    -------
    dict with, each of shape (n_points,) unless noted:
        int_u, int_pi : int_0^1 u dtau and int_0^1 Pi dtau on the returned grid (2N steps:
            the finer of the last pair), NaN unless converged;
        unconverged : (n_points, 2), int_u and int_pi of the finest grid marched where the
            status is TOLERANCE_NOT_REACHED with a finite estimate (``estimate`` is their
            error estimate), NaN elsewhere (``solve_periodic(keep_unconverged=True)``);
        status : int8 ``status`` code;
        estimate : e of the returned value (inf where none was formed);
        estimate_u, estimate_p : its parts of int u and int Pi (``_norm``);
        n_tau : steps per period of the returned (or last tried) grid;
        iterations : periods marched, summed over grids;
        still : phi is constant (V = 0): nothing was solved (status NO_MOTION, NaN);
        series : None, or per point (u at the nodes, the nodes tau) without tau = 1 (empty
            arrays for failed points);
        evaluations : (n_points, 1) int64, the evaluations of F (two per Heun step, two per
            step of the final chatter check), summed over grids.
    """
    n = len(kinematics)
    if len(physics) == 1 and n > 1:
        physics = physics.take(np.zeros(n, dtype=int))
    vscale = kinematic_speed(kinematics)
    int_u = np.full(n, np.nan)
    int_pi = np.full(n, np.nan)
    status = np.full(n, TOLERANCE_NOT_REACHED, dtype=np.int8)
    estimate = np.full(n, np.inf)
    estimate_u = np.full(n, np.inf)
    estimate_p = np.full(n, np.inf)
    n_tau = np.zeros(n, dtype=np.int64)
    iterations = np.zeros(n, dtype=np.int64)
    evaluations = np.zeros((n, 1), dtype=np.int64)
    still = vscale == 0.0
    series = [(np.array([]), np.array([])) for _ in range(n)] if return_series else None
    # the last two grids' integrals (NaN: that grid failed or was not marched yet)
    last = np.full((n, 2), np.nan)
    before = np.full((n, 2), np.nan)
    earlier = np.full((n, 2), np.nan)
    u_start = np.zeros(n)
    last_mass = np.full(n, np.nan)  # the chatter mass of the last grid (NaN: none)
    active = np.flatnonzero(~still)
    N = FIRST_STEPS
    while active.size and N <= max_steps:
        out, grids = _march_grid(kinematics, physics, active, N, u_start[active], vscale, rtol)
        iu, ip, u0, st, periods, evals, chatter_mass, stiffness, nodes = out
        iterations[active] += periods
        evaluations[active, 0] += evals
        n_tau[active] = N
        ok = st == CONVERGED
        u_start[active[ok]] = u0[ok]
        current = np.column_stack([iu, ip])
        d0 = before[active] - earlier[active]
        d1 = last[active] - before[active]
        d2 = current - last[active]
        e_u, e_p = _norm(richardson_error(d0[:, 0], d1[:, 0], d2[:, 0]),
                         richardson_error(d0[:, 1], d1[:, 1], d2[:, 1]),
                         iu, ip, vscale[active])
        e = np.maximum(e_u, e_p)
        scale_u = np.maximum(np.abs(iu), U_FLOOR_FRACTION * vscale[active])
        chatters = ok & (chatter_mass > CHATTER_SHARE * rtol * scale_u)
        e = np.where(ok & ~chatters, e, np.inf)
        estimate[active] = np.where(ok, e, estimate[active])
        estimate_u[active] = np.where(ok, np.where(ok & ~chatters, e_u, np.inf), estimate_u[active])
        estimate_p[active] = np.where(ok, np.where(ok & ~chatters, e_p, np.inf), estimate_p[active])
        # the kernel's failure, chatter, or (not yet known) the tolerance
        status[active] = np.where(~ok, st, np.where(chatters, UNSTABLE, TOLERANCE_NOT_REACHED))
        hopeless = chatters & _hopeless(N, stiffness, chatter_mass, last_mass[active],
                                        CHATTER_SHARE * rtol * scale_u, max_steps)
        last_mass[active] = np.where(chatters, chatter_mass, np.nan)
        done = (e <= rtol) | hopeless
        accepted = done & (e <= rtol)
        status[active[accepted]] = CONVERGED
        int_u[active[accepted]] = iu[accepted]
        int_pi[active[accepted]] = ip[accepted]
        if series is not None:
            for j in np.flatnonzero(accepted):
                series[active[j]] = (nodes[j].copy(), grids[j, :-1].copy())
        earlier[active] = before[active]
        before[active] = last[active]
        last[active] = current
        active = active[~done]
        N *= 2
    status[still] = NO_MOTION
    failed = status != CONVERGED
    int_u[failed] = np.nan
    int_pi[failed] = np.nan
    # the finest grid's values where only the tolerance was missed (its estimate is theirs)
    short = (status == TOLERANCE_NOT_REACHED) & np.isfinite(estimate)
    unconverged = np.where(short[:, None], last, np.nan)
    return dict(int_u=int_u, int_pi=int_pi, status=status, estimate=estimate, estimate_u=estimate_u,
                estimate_p=estimate_p, n_tau=n_tau,
                iterations=iterations, still=still, series=series, evaluations=evaluations,
                unconverged=unconverged)
