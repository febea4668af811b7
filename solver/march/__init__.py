"""The march (method "march"), the independent check: heun: the explicit RK2 kernel and one
grid's march to the periodic state; driver: doubled uniform grids with a Richardson estimate.
"""
