"""The model: kinematic families phi(tau), the force integral F over a link and its power density (eq. Newtonu), the physics of a point (eq. tau) and the limits T -> 0, T -> inf.
"""
