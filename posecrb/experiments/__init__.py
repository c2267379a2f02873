"""The paper's and the thesis's experiments.

* ``crlb_sweep``: Monte Carlo MSE of the certified MLE vs the CRLB (paper sec. IX-C, Fig. 6/7);
* ``thesis``: empirical covariance of the intrinsic MLE vs anchored / quotient CRBs (thesis ch. 6);
* ``octagon``: T- vs D-optimality on the 8-pose octagon (paper sec. IX-A, Fig. 4/5);
"""
from .crlb_sweep import CrlbLevel, CrlbSweepResult, crlb_sweep, parse_levels
from .octagon import OctagonResult, octagon_experiment
from .thesis import ThesisResult, thesis_experiment

__all__ = ["CrlbLevel", "CrlbSweepResult", "crlb_sweep", "parse_levels", "OctagonResult",
           "octagon_experiment", "ThesisResult", "thesis_experiment"]
