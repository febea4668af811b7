"""Shared registry of solver test cases, parametrised across methods.

Each case is (kinematics, physics, stiff): ``stiff`` marks cases where the
explicit march cannot be stable within its step budget by design (sticking
with friction rate ~ T^(2-p) mu / delta_tau); there only ``periodic`` is
required to converge and the march must report a failure status instead of
a wrong number.
"""
from __future__ import annotations

from dataclasses import dataclass


import solver


@dataclass(frozen=True)
class Case:
    name: str
    kinematics: object
    physics: object
    stiff: bool = False


def _scaled(ratio_log2, scaled_period_log2, p=0.0, delta=1e-5):
    return solver.Physics.from_scaled(2.0 ** ratio_log2, 2.0 ** scaled_period_log2, p=p, delta=delta)


def _harmonic(A0, A1):
    return solver.Harmonic(A0, A1)


def _burst_and_coast():
    # the paper's figure OptAllParamsMotions (A): tau0 = 0.8, closing down:10, opening up:3
    return solver.PowerLaw(1.2, 0.35, 0.8, 10.0, False, 3.0, True)


def _clapping():
    # phi passes through 0 and reaches -pi/2 (section "Optimal motions")
    return solver.Fourier([[0.3, 1.1, 0.0, 0.2]], [[0.0, -0.1, 0.05]])


AGREEMENT_CASES = [
    Case("harmonic_low_ratio", _harmonic(1.3, 0.3), _scaled(-8, 1.5)),
    Case("harmonic_high_ratio", _harmonic(0.5, 0.45), _scaled(8, 1.5)),
    Case("harmonic_short_period", _harmonic(1.0, 0.5), _scaled(-4, -3)),
    Case("harmonic_long_period", _harmonic(1.0, 0.5), _scaled(4, 4), stiff=True),
    Case("harmonic_isotropic", _harmonic(0.8, 0.6), _scaled(0, 0)),
    Case("harmonic_p0.5", _harmonic(1.0, 0.6), _scaled(-2, 1, p=0.5)),
    Case("harmonic_p1", _harmonic(1.0, 0.6), _scaled(3, 1, p=1.0)),
    Case("harmonic_p1.5", _harmonic(1.0, 0.6), _scaled(-3, 1, p=1.5)),
    Case("harmonic_delta_1e-8", _harmonic(1.2, 0.3), _scaled(-4, 0, delta=1e-8)),
    Case("linear_two_phase", solver.PowerLaw(1.0, 0.5, 0.2, 1.0, False, 1.0, False), _scaled(-6, 0)),
    Case("power_law_corners_p1.5", solver.PowerLaw(1.0, 0.4, 0.3, 3.0, False, 3.0, True), _scaled(2, 1, p=1.5)),
    Case("burst_and_coast", _burst_and_coast(), _scaled(-8, 1.5), stiff=True),
    Case("burst_and_coast_delta_1e-8", _burst_and_coast(), _scaled(-8, 1.5, delta=1e-8), stiff=True),
    Case("clapping_fourier", _clapping(), _scaled(-3, 1)),
    Case("clapping_fourier_p0.5", _clapping(), _scaled(3, 0.5, p=0.5)),
]


def by_name(name):
    return next(c for c in AGREEMENT_CASES if c.name == name)


def radau_reference(code, params, physics, t0, t1, u0, side=None):
    """u' = T^(2-p) F(u, tau) from u(t0) = u0 over [t0, t1] by scipy's Radau at rtol 1e-12,
    with the solver's own force kernel: (int_t0^t1 u dtau, u(t1)).  An independent check of
    the solver's re-solved steps; ``side`` selects the side of a corner of phi (default:
    the evaluation point itself).  physics = (T^(2-p), mu_n, mu_s, p, delta_tau)."""
    from scipy.integrate import solve_ivp
    from solver.model.force import force_and_slope
    from solver.model.kinematics import angle_and_rate
    kappa, mu_n, mu_s, p, dtau = physics

    def rhs(t, y):
        phi, om = angle_and_rate(code, params, t, t if side is None else side)
        return [kappa * force_and_slope(y[0], phi, om, mu_n, mu_s, p, dtau)[0], y[0]]

    def jac(t, y):
        phi, om = angle_and_rate(code, params, t, t if side is None else side)
        return [[kappa * force_and_slope(y[0], phi, om, mu_n, mu_s, p, dtau)[1], 0.0],
                [1.0, 0.0]]

    ref = solve_ivp(rhs, (t0, t1), [u0, 0.0], method="Radau", jac=jac, rtol=1e-12,
                    atol=[1e-14, 1e-18], first_step=1e-9)
    assert ref.success
    return ref.y[1, -1], ref.y[0, -1]


def random_harmonic(n, seed):
    """``n`` random harmonic points for the march's honesty checks: scaled period
    2^U(-2, 2), mu_n/mu_s 2^U(-4, 4), delta 1e-5, amplitudes as ``solver.tools.bench.draw_points``
    (A0 in (0, pi/2], A1 / A0 in (0, 1]).  Returns (Harmonic, Physics)."""
    import numpy as np
    rng = np.random.default_rng(seed)
    ratio = 2.0 ** rng.uniform(-4.0, 4.0, n)
    scaled_period = 2.0 ** rng.uniform(-2.0, 2.0, n)
    A0 = 0.5 * np.pi * (1.0 - rng.random(n))
    A1 = A0 * (1.0 - rng.random(n))
    return solver.Harmonic(A0, A1), solver.Physics.from_scaled(ratio, scaled_period, p=0.0,
                                                               delta=1e-5)
