"""Step-size control of the engine: the policy apart from the step (scipy
``radau.py``'s ``predict_factor``; diffrax ``adapt_step_size``).

The error of a step is measured per unit length: ``ratio`` = weighted local error /
(tolerance x h), so that steps whose ratio is <= 1 keep the sum of their errors over the
period below the tolerance.  With an estimate of order ERROR_ORDER (``periodic.radau``), the
error per unit length scales like h^ERROR_ORDER, so a step's ratio of r asks for the factor
r^(-1 / ERROR_ORDER); Gustafsson's predictive controller (Hairer & Wanner IV.8, eq. (8.21))
corrects it by the last two steps' history.
"""
from __future__ import annotations

import math

from numba import njit

from .radau import ERROR_ORDER

_EXPONENT = 1.0 / ERROR_ORDER


@njit(cache=True, error_model="numpy")
def predict_factor(h, h_old, ratio, ratio_old, control):
    """The factor for the next step size from this step's error ``ratio`` (<= 1 accepted) and
    the previous accepted step's (``h_old``, ``ratio_old``; h_old <= 0 when there is none):
    Gustafsson's predictive controller, times ``control.safety``, clipped to
    [``control.min_factor``, ``control.max_factor``] (``periodic.options.ControlOptions``)."""
    if ratio <= 0.0:
        return control.max_factor
    if not math.isfinite(ratio):
        return control.min_factor
    factor = ratio ** -_EXPONENT
    if h_old > 0.0 and ratio_old > 0.0:
        factor *= min(1.0, h / h_old * (ratio_old / ratio) ** _EXPONENT)
    return min(control.max_factor, max(control.min_factor, control.safety * factor))
