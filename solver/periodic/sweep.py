"""Transitional: the names ``adjoint.gradient`` imported from the former ``periodic.sweep``
(split by role into ``periodic.record``, ``steps``, ``events``, ``traps``, ``estimators`` and
``integrator``).  Removed where the adjoint imports the engine's public boundary."""
from .integrator import frozen_pass as frozen_sweep  # noqa: F401
from .record import (COS, END_KIND, ERR, INT_P, INT_U, OMEGA, SENS, SIN, STAGE, T,  # noqa: F401
                     U, new_workspace)
