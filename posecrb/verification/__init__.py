"""Judging an estimate that another program computed: is it the global optimum of the model, how far
from it, in map units and in units of its uncertainty (``posecrb verify``; docs/design.md#verify)."""
