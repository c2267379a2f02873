"""Certifiably correct pose-graph optimisation (SE-Sync, Rosen et al. 2019); docs/design.md#solver."""
from .options import Preconditioner, PreconditionerSettings, SolverOptions
from .solve import SolveResult, solve

__all__ = ["Preconditioner", "PreconditionerSettings", "SolveResult", "SolverOptions", "solve"]
