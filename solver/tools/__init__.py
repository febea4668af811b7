"""Measurements of the engines: bench (throughput against a scipy LSODA baseline),
bench_optimize (the optimiser against scipy's difference BFGS), honesty (is the error
estimate true? against the frozen references in honesty_references.npz).
"""
