"""The s-integral against a 40-digit reference, at and near the kink, and dF/du against differences."""
import math

import mpmath as mp
import numpy as np
import pytest

import solver
from solver import force_and_slope, power_density



def reference(u, phi, omega, mu_n, mu_s, p, delta_tau):
    """F and Pi by adaptive mpmath quadrature split at the point where v_n = 0 (40 digits)."""
    with mp.workdps(40):
        return _reference(u, phi, omega, mu_n, mu_s, p, delta_tau)


def _reference(u, phi, omega, mu_n, mu_s, p, delta_tau):
    u, phi, omega, mu_n, mu_s, p, dt = map(mp.mpf, (u, phi, omega, mu_n, mu_s, p, delta_tau))
    S, C = mp.sin(phi), mp.cos(phi)
    a, b, c = -u * S - omega * S * S / 4, omega, C * (u + omega * S / 4)

    def weight(s):
        w = a + b * s
        return w, (w * w + c * c + dt * dt) ** ((p - 1) / 2)

    pts = [mp.mpf(0), mp.mpf(1) / 2]
    if b != 0 and 0 < -a / b < mp.mpf(1) / 2:
        pts = [mp.mpf(0), -a / b, mp.mpf(1) / 2]
    F = 2 * mp.quad(lambda s: (mu_n * S * weight(s)[0] - mu_s * C * c) * weight(s)[1], pts)
    Pi = 2 * mp.quad(lambda s: (mu_n * weight(s)[0] ** 2 + mu_s * c * c) * weight(s)[1], pts)
    return float(F), float(Pi)


def _kink_inputs(rng, n):
    """Inputs concentrated where the integrand is hardest: kink inside the link, c ~ 0, tiny omega."""
    out = []
    for k in range(n):
        phi = rng.uniform(-1.0, 4.0)
        omega = rng.normal() * [1e-8, 1e-3, 1.0, 10.0][k % 4]
        u = rng.normal() * [1e-9, 1e-4, 1.0][k % 3]
        if k % 5 == 0:
            u = -omega * math.sin(phi) / 4  # c = 0: the apex is at rest, kink at s = 0
        if k % 7 == 0:
            s_kink = rng.uniform(0, 0.5)  # v_n = 0 at an interior point of the link
            u = (omega * s_kink - omega * math.sin(phi) ** 2 / 4) / math.sin(phi)
        out.append((u, phi, omega))
    return out


@pytest.mark.parametrize("p", [0.0, 0.01, 0.5, 1.0, 1.5, 1.9])
@pytest.mark.parametrize("delta_tau", [1e-2, 1e-5, 1e-9])
def test_force_and_power_match_high_precision_reference(p, delta_tau):
    rng = np.random.default_rng(int(p * 100) + int(-math.log10(delta_tau)))
    for u, phi, omega in _kink_inputs(rng, 12):
        F, _ = force_and_slope(u, phi, omega, 0.3, 1.7, p, delta_tau)
        Pi = power_density(u, phi, omega, 0.3, 1.7, p, delta_tau)
        F_ref, Pi_ref = reference(u, phi, omega, 0.3, 1.7, p, delta_tau)
        assert abs(F - F_ref) <= 1e-11 * abs(F_ref) + 1e-300, (u, phi, omega)
        assert abs(Pi - Pi_ref) <= 1e-11 * abs(Pi_ref) + 1e-300, (u, phi, omega)


@pytest.mark.parametrize("p", [0.0, 0.5, 1.0, 1.5])
def test_slope_matches_central_differences(p):
    rng = np.random.default_rng(7)
    for _ in range(40):
        u, phi, omega = rng.normal(), rng.uniform(-1, 4), rng.normal() * 3
        dt = 1e-2
        h = 1e-6 * max(abs(u), 1.0)
        fd = (force_and_slope(u + h, phi, omega, 0.4, 1.3, p, dt)[0]
              - force_and_slope(u - h, phi, omega, 0.4, 1.3, p, dt)[0]) / (2 * h)
        slope = force_and_slope(u, phi, omega, 0.4, 1.3, p, dt)[1]
        assert abs(slope - fd) <= 1e-6 * (abs(fd) + 1.0)


@pytest.mark.parametrize("p", [0.0, 0.5, 1.0, 1.5])
def test_power_carried_by_the_stage_iterations(p):
    # the stage Newton iterations evaluate F, dF/du, Pi and dPi/du together: the first three
    # are the standalone kernels' to the bit, dPi/du matches central differences of Pi
    from solver.model.force import force_slope_power_sc
    rng = np.random.default_rng(11)
    for _ in range(40):
        u, phi, omega = rng.normal(), rng.uniform(-1, 4), rng.normal() * 3
        dt = 10.0 ** rng.uniform(-8, -2)
        F, slope, Pi, Pi_u = force_slope_power_sc(u, math.sin(phi), math.cos(phi), omega, 0.4,
                                                  1.3, p, dt)
        assert (F, slope) == force_and_slope(u, phi, omega, 0.4, 1.3, p, dt)
        assert Pi == power_density(u, phi, omega, 0.4, 1.3, p, dt)
        h = 1e-6 * max(abs(u), 1.0)
        fd = (power_density(u + h, phi, omega, 0.4, 1.3, p, dt)
              - power_density(u - h, phi, omega, 0.4, 1.3, p, dt)) / (2 * h)
        assert abs(Pi_u - fd) <= 1e-6 * (abs(fd) + 1.0), (u, phi, omega, dt)


def _uses_quadrature(u, phi, omega, delta_tau):
    """Whether ``link_moments`` takes its Gauss-Legendre branch (the rule of _force)."""
    from solver.model.force import SWITCH_RATIO, link_setup
    _, _, a, b, _, e2 = link_setup(u, phi, omega, delta_tau, 0.0)
    h = 0.25 * abs(b)
    gap = max(abs(a + 0.25 * b) - h, 0.0)
    return gap * gap + e2 >= (SWITCH_RATIO * h) ** 2


def test_force_is_continuous_across_the_quadrature_switch():
    # omega sweeps through the closed-form / Gauss-Legendre switch at fixed u: both sides of
    # it agree with the 30-digit reference, and the sampled curve has no jump anywhere
    omegas = np.geomspace(1e-7, 1e1, 4001)
    F = np.array([force_and_slope(0.01, 1.1, om, 0.3, 1.7, 0.0, 1e-5)[0] for om in omegas])
    branch = np.array([_uses_quadrature(0.01, 1.1, om, 1e-5) for om in omegas])
    switches = np.flatnonzero(np.diff(branch))
    assert switches.size >= 1  # the sweep crosses it
    for k in switches:
        near = [k - 1, k, k + 1, k + 2]
        F_ref = [reference(0.01, 1.1, omegas[i], 0.3, 1.7, 0.0, 1e-5)[0] for i in near]
        np.testing.assert_allclose(F[near], F_ref, rtol=1e-11)
    jumps = np.abs(np.diff(F)) / (np.abs(F[1:]) + 1e-300)
    assert np.all(jumps < 2e-3)  # the largest step of this sampling is ~1e-3
    F_ref = [reference(0.01, 1.1, om, 0.3, 1.7, 0.0, 1e-5)[0] for om in omegas[::400]]
    np.testing.assert_allclose(F[::400], F_ref, rtol=1e-11)


def _moment_reference(a, b, e2, p):
    """m_k^j = int_0^{1/2} w^k r^(p-1-2j) ds, w = a + b s, r^2 = w^2 + e2 (30 digits), and the
    integrals of their absolute values (the integrands keep their sign on each side of the
    kink w = 0, where the quadrature is split)."""
    with mp.workdps(30):
        a, b, e2, p = map(mp.mpf, (a, b, e2, p))
        pts = [mp.mpf(0), mp.mpf(1) / 2]
        if 0 < -a / b < pts[1]:
            pts = [pts[0], -a / b, pts[1]]
        values, sizes = [], []
        for k, j in [(0, 0), (1, 0), (2, 0), (0, 1), (1, 1), (2, 1)]:
            pieces = [mp.quad(lambda s: (a + b * s) ** k * ((a + b * s) ** 2 + e2)
                              ** ((p - 1) / 2 - j), [lo, hi]) for lo, hi in zip(pts, pts[1:])]
            values.append(float(sum(pieces)))
            sizes.append(float(sum(abs(x) for x in pieces)))
    return np.array(values), np.array(sizes)


@pytest.mark.parametrize("p", [0.0, 0.5, 1.5])
def test_link_moments_in_the_closed_form_regime(p):
    """All six moments (dF/du needs the j = 1 ones) where the closed forms are used, down to
    e ~ 1e-12 with the kink off the link: at p = 0, m_0^1 = [w/r] / e^2 once lost every digit
    there (w/r -> sign(w) cancels)."""
    from solver.model.force import SWITCH_RATIO, link_moments

    rng = np.random.default_rng(int(10 * p))
    checked = 0
    while checked < 15:
        e2 = 10 ** rng.uniform(-24, 0)
        a = rng.normal() * 10 ** rng.uniform(-8, 0)
        b = rng.normal() * 10 ** rng.uniform(-8, 1)
        h = 0.25 * abs(b)
        gap = max(abs(a + 0.25 * b) - h, 0.0)
        if gap * gap + e2 >= (SWITCH_RATIO * h) ** 2:
            continue  # the Gauss-Legendre regime
        checked += 1
        ref, size = _moment_reference(a, b, e2, p)
        got = np.array(link_moments(a, b, e2, p))
        assert np.all(np.abs(got - ref) <= 1e-13 * size), (a, b, e2, got, ref)


def test_coulomb_moments_with_the_kink_on_the_link_match_the_reference():
    """p = 0 with w of opposite signs at the link's ends (the kink on the link): m_0^0 =
    (asinh(w2/e) - asinh(w1/e)) / b as one log of a product (``_moments_closed_coulomb``),
    against 30 digits, over 12 decades of e / |b|; and a |u| ~ 1e100 iterate, whose product
    overflows, by the asinh form (finite, not inf)."""
    from solver.model.force import SWITCH_RATIO, link_moments

    rng = np.random.default_rng(7)
    checked = 0
    while checked < 40:
        b = rng.choice([-1.0, 1.0]) * 10 ** rng.uniform(-6, 1)
        a = -b * rng.uniform(0.0, 0.5)  # w1 = a and w2 = a + b / 2 of opposite signs
        e2 = (abs(b) * 10 ** rng.uniform(-12, 0)) ** 2
        gap = max(abs(a + 0.25 * b) - 0.25 * abs(b), 0.0)
        if gap * gap + e2 >= (SWITCH_RATIO * 0.25 * abs(b)) ** 2:
            continue
        checked += 1
        ref, size = _moment_reference(a, b, e2, 0.0)
        got = np.array(link_moments(a, b, e2, 0.0))
        assert abs(got[0] - ref[0]) <= 4e-15 * abs(ref[0]), (a, b, e2, got[0], ref[0])
        assert np.all(np.abs(got - ref) <= 1e-13 * size), (a, b, e2, got, ref)
    a, b, e2 = -1e100, 4e100, 1e-120  # ((|w| + r) / e)^2 ~ 4e320 overflows
    factor = (abs(a) + math.hypot(a, 1e-60)) / 1e-60
    assert factor * factor == math.inf
    expected = 2.0 * math.asinh(1e160) / b
    assert link_moments(a, b, e2, 0.0)[0] == pytest.approx(expected, rel=1e-14)


def test_link_moments_of_a_nan_iterate_at_zero_rate_are_nan_not_an_exception():
    """omega = 0 (b = 0) with a NaN stage iterate (a diverged Newton step, delta 1e-10 at
    power-law corners) took the closed forms and their 1 / b, which raised
    ZeroDivisionError out of the compiled solver; it must give NaN for the Newton to report."""
    from solver.model.force import link_moments

    for p in (0.0, 0.5):
        moments = link_moments(math.nan, 0.0, 1e-20, p)
        assert all(math.isnan(m) for m in moments), moments


def test_power_law_corners_at_tiny_delta_solve_without_an_exception():
    """One of three points of a stress sweep (mu_n/mu_s 2^-12 .. 2^12, delta 1e-10) on which
    solve_periodic raised ZeroDivisionError (``link_moments``); now it converges, honestly."""
    kin = solver.PowerLaw(0.511646074393324, 0.43780610553700355, 0.05016145039000145,
                          1.1104818468195743, True, 11.514216747091353, False)
    phys = solver.Physics(0.29019658422967287, 6.195989242315322, 0.16139472824945048, 0.0,
                          1e-10)
    from solver.tools.bench import relative_u_error

    ref = solver.solve_periodic(kin, phys, rtol=1e-7)
    res = solver.solve_periodic(kin, phys, rtol=1e-3)
    assert ref.converged[0] and res.converged[0]
    assert relative_u_error(res.U, ref.U, phys.period, solver.kinematic_speed(kin))[0] <= 1e-3
    assert abs(res.P[0] - ref.P[0]) <= 1e-3 * ref.P[0]
