"""The engine (method "periodic"): event-driven 3-stage Radau IIA with one-pass error control.

radau: the step kernel, its tableau and its local error estimates; control: the step-size
rule; switching: kinematic stops and state events (the switching functions); sweep: one
period as an adaptive or frozen-grid sweep; global_error: the estimate of the period
integrals' error and the refinement it asks for; shooting: the monodromy and the bracketed
Newton update of u(0); driver: one point from stops to estimate, batched over points.
"""
