"""Certifiably correct pose-graph optimisation (SE-Sync, Rosen et al. 2019); docs/design.md#solver."""
from .solve import SolveResult, SolverOptions, solve

__all__ = ["SolveResult", "SolverOptions", "solve"]
