"""Exact gradients of the engine's discretisation (gradient: the discrete adjoint of the
3-stage Radau IIA on a frozen step sequence) and the motion optimiser (optimize: BFGS +
Newton).
"""
