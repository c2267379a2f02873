"""Certifiably correct pose-graph optimisation (SE-Sync, Rosen et al. 2019); DESIGN.md section 6."""
from .solver import SolveResult, solve

__all__ = ["SolveResult", "solve"]
