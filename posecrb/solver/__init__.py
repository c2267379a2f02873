"""Certifiably correct pose-graph optimisation (SE-Sync, Rosen et al. 2019); DESIGN.md section 6."""
from .solve import SolveResult, solve

__all__ = ["SolveResult", "solve"]
