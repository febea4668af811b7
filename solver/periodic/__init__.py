"""The engine (method "periodic"): event-driven 3-stage Radau IIA with one-pass error control.

Files by role (as scipy's ``integrate/_ivp`` and diffrax separate them):

- ``radau``: the step kernel (Radau IIA stages, ``radau5_step``), its tableau and the
  embedded error estimate; ``defect``: the defect error estimate; ``control``: the
  step-size controller; ``steps``: one step as a pass takes it (stage kinematics, start
  values, the stage solve with its fallbacks).
- ``switching``: the kinematic stops and the switching functions with their root finder;
  ``events``: state events in a solved step (detection, location) and stop placement;
  ``traps``: the turning-point traps.
- ``record``: the step record (the one module that knows its layout); ``integrator``: one
  pass over the period, adaptive (propose, clip, step, events, accept, record) or frozen;
  ``estimators``: the error of a recorded pass's steps; ``global_error``: their estimate
  for the period integrals and the refinement it asks for.
- ``shooting``: the monodromy and Newton on u(0); ``point``: one point's solve (stops,
  loose shooting, rounds, estimate, warm starts); ``driver``: batches of points and the
  entry of ``solve.solve_periodic``.
- ``options``: every tuning constant, each the default of a field of ``EngineOptions``,
  the options passed through the kernels at run time by role (the controller's, a point's
  solve's, the traps', the kinematic stops', the state events', the step lengths', the
  stage solve's, the defect estimate's, the tolerances' factors, the batches');
  ``tolerances``: every tolerance from rtol.

"Sweep" means one thing in the engine: a chain of points solved in order, each starting
from its predecessor's orbit (``solve_periodic(..., sweeps=...)``); one integration over
the period is a "pass".

The names below are the engine's public boundary: what other packages (``solve``,
``adjoint``) use; everything else is internal.
"""
from .driver import Points, fixed_grid_points, solve, solve_points
from .options import (BatchOptions, ControlOptions, DefectOptions, EngineOptions, EventOptions,
                      PointOptions, StageOptions, StepOptions, StopOptions, ToleranceOptions,
                      TrapOptions, checked_options, engine_options)
from .radau import RADAU5_A, RADAU5_C, solve3, stage_matrix
from .record import new_workspace, set_grid_step, stage_columns
from .shooting import frozen_orbit, monodromy_factor, one_minus_monodromy

__all__ = ["Points", "fixed_grid_points", "solve", "solve_points", "ControlOptions",
           "EngineOptions", "PointOptions", "TrapOptions", "StopOptions", "EventOptions",
           "StepOptions", "StageOptions", "DefectOptions", "ToleranceOptions", "BatchOptions",
           "checked_options", "engine_options", "RADAU5_A", "RADAU5_C", "solve3", "stage_matrix",
           "new_workspace", "set_grid_step", "stage_columns", "frozen_orbit", "monodromy_factor",
           "one_minus_monodromy"]
