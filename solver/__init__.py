"""Periodic sliding of a symmetric two-link body on an anisotropic resistive surface.

The numerical core of the project: kinematic families, the force integral
over a link, two independent periodic steady-state solvers and the paper's
scalings.  Pure numerics, batched over parameter points; no file or dask I/O.

Reference: S. Alben and C. Puritz, "Intermittent sliding locomotion of a
two-link body" (``shared/paper/intermittent_sliding_two_link.tex``).
"""
from ._cache import restore_cache_dir, use_source_keyed_cache

_numba_cache_dir = use_source_keyed_cache()  # before any kernel is decorated

from .model.force import force_and_slope, power_density  # noqa: E402
from .adjoint.gradient import (DiscreteSolution, FixedGrid, GradientResult, adaptive_grid,
                        discrete_objective, discrete_solution, family_parameters,
                        force_partials, objective_gradient, with_family_parameters)
from .model.kinematics import Fourier, Harmonic, PowerLaw, period_grid
from .model.limits import fast_limit_velocity, kinematic_speed, quasi_static_velocity
from .model.physics import Physics, physical_from_scaled, scaled_from_physical
from .adjoint.optimize import OptimizeResult, OptimizerOptions, optimize_motion
from .solve import (ENGINES, METHODS, SWEEP_POINTS, Engine, SolveResult, snake_order,
                    solve_fixed_grid, solve_periodic, sweep_runs)
from .status import STATUS_REASONS, status_reason  # noqa: E402
from .periodic import (BatchOptions, ControlOptions, DefectOptions, EngineOptions,  # noqa: E402
                       EventOptions, PointOptions, StageOptions, StepOptions, StopOptions,
                       ToleranceOptions, TrapOptions)
from ._warmup import KERNEL_SETS, kernel_cache, warm_up  # noqa: E402  (compile ahead: pipeline's driver)

restore_cache_dir(_numba_cache_dir)  # other packages' kernels keep their own

__version__ = "0.1.0"

__all__ = [
    "Fourier", "Harmonic", "PowerLaw", "Physics", "SolveResult", "STATUS_REASONS", "METHODS",
    "ENGINES", "Engine", "status_reason",
    "solve_periodic", "snake_order", "sweep_runs", "SWEEP_POINTS", "solve_fixed_grid", "force_and_slope", "power_density", "period_grid", "fast_limit_velocity",
    "quasi_static_velocity", "kinematic_speed", "physical_from_scaled", "scaled_from_physical",
    "FixedGrid", "GradientResult", "adaptive_grid", "discrete_objective", "discrete_solution",
    "DiscreteSolution", "family_parameters",
    "force_partials", "objective_gradient", "with_family_parameters", "OptimizeResult",
    "optimize_motion", "OptimizerOptions", "EngineOptions", "ControlOptions", "PointOptions", "TrapOptions",
    "StopOptions", "EventOptions", "StepOptions", "StageOptions", "DefectOptions",
    "ToleranceOptions", "BatchOptions",
]
