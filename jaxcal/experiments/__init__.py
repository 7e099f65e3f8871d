"""Experiments built on the solvers: Monte Carlo studies and the paper's reproduction."""
