"""One step as the passes take it: the kinematics at the stages and at the defect's
samples, the start values (F, dF/du, Pi, dPi/du) at a node, and ``solve_step``, the Radau IIA
stage solve (``periodic.radau.radau5_step``) with its fallbacks.  (The step-size limits
that every module judging a step's length shares are ``periodic.options.StepOptions``.)
"""
from __future__ import annotations

import math

from numba import njit

from ..model.force import force_slope_power_sc
from ..model.kinematics import angle_and_rate
from .defect import THETA_LATE, THETA_MID, SampleKinematics
from .radau import C1, C2, StageKinematics, radau5_step


@njit(cache=True, error_model="numpy")
def stage_kinematics(code, params, t0, h):
    """sin phi, cos phi, dphi/dtau at the stages tau_0 + c_i h (inside the step at corners)."""
    side = t0 + 0.5 * h
    phi1, om1 = angle_and_rate(code, params, t0 + C1 * h, side)
    phi2, om2 = angle_and_rate(code, params, t0 + C2 * h, side)
    phi3, om3 = angle_and_rate(code, params, t0 + h, side)
    return StageKinematics(math.sin(phi1), math.sin(phi2), math.sin(phi3),
                           math.cos(phi1), math.cos(phi2), math.cos(phi3), om1, om2, om3)


@njit(cache=True, error_model="numpy")
def sample_kinematics(code, params, t0, h):
    """sin phi, cos phi, dphi/dtau at the defect estimate's samples (``periodic.radau``)."""
    side = t0 + 0.5 * h
    phi_m, om_m = angle_and_rate(code, params, t0 + THETA_MID * h, side)
    phi_l, om_l = angle_and_rate(code, params, t0 + THETA_LATE * h, side)
    return SampleKinematics(math.sin(phi_m), math.cos(phi_m), om_m, math.sin(phi_l),
                            math.cos(phi_l), om_l)


@njit(cache=True, error_model="numpy")
def start_values(code, params, t, side, u, phys):
    """(kappa F, kappa dF/du, Pi, dPi/du) at (t, u) on the side ``side`` of t."""
    phi, om = angle_and_rate(code, params, t, side)
    F, d, P, Pu = force_slope_power_sc(u, math.sin(phi), math.cos(phi), om, phys.mu_n,
                                       phys.mu_s, phys.p, phys.dtau)
    return phys.kappa * F, phys.kappa * d, P, Pu


@njit(cache=True, error_model="numpy")
def solve_step(u_n, U1, U2, U3, h, kin, phys, atol, options, rate=math.inf, slope=math.nan):
    """``radau5_step`` from the predicted stages (with the carried Newton ``rate`` and
    ``slope``; ``options``: the ``StageOptions``); where its Newton fails, again from u_n,
    then from rest (a step into a stop can defeat a prediction: the former engine measured
    it at a burst-and-coast corner).  Returns (StepSolution, iterations summed)."""
    sol = radau5_step(u_n, U1, U2, U3, h, kin, phys, atol, options, rate, slope)
    its = sol.iterations
    if not sol.ok:
        sol = radau5_step(u_n, u_n, u_n, u_n, h, kin, phys, atol, options, math.inf, math.nan)
        its += sol.iterations
    if not sol.ok and u_n != 0.0:
        sol = radau5_step(u_n, 0.0, 0.0, 0.0, h, kin, phys, atol, options, math.inf, math.nan)
        its += sol.iterations
    return sol, its
