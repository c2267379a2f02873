"""Every choice of the library and the command line, defined once (docs/design.md#choices).

Each choice is a ``Literal`` type (what the library's signatures say) and the tuple of its values
(``typing.get_args`` of it: what ``click.Choice`` and the argument checks read). This module
imports only ``typing``, so the command line reads it at start-up without loading numpy.
"""
from __future__ import annotations

from typing import Literal, get_args

#: The estimation model: the paper's on (R^d x SO(d))^n, the thesis's on SE(d)^n.
Model = Literal["paper", "sed"]
#: The paper model's FIM: eq. (64) as printed, or the Fisher information of the model the data follow.
FimVariant = Literal["eq64", "consistent"]
#: The 3D rotation weight: eq. (59), or the empirical fit to the paper's printed Table II.
RotationWeight = Literal["eq59", "table2"]
#: The sed model's coordinates: the thesis's (about the world origin) or GTSAM's and g2o's (body).
Frame = Literal["world", "body"]
#: The fill-reducing ordering of the sparse Cholesky factorizations.
Ordering = Literal["auto", "amd", "colamd", "metis", "nesdis"]
#: What a measurement selection maximises.
Objective = Literal["tree", "fim", "fiedler"]
#: How a measurement selection chooses.
Method = Literal["greedy", "relax", "random", "naive"]
#: How the log-det greedy evaluates gains: ``auto`` (the incremental greedy, every gain exact at
#: every step; the round greedy for more than 4096 steps on graphs of 20,000 poses or more),
#: ``exact`` (the incremental greedy whatever the size), ``rounds`` (the round greedy: exact gains
#: once per round, local corrections within it), ``lazy`` (a priority queue; random projections
#: seed it above 50,000 candidates), ``lazy-exact`` (the lazy greedy, never random projections) or
#: ``jl`` (the lazy greedy seeded by random projections).
Gains = Literal["auto", "exact", "rounds", "lazy", "lazy-exact", "jl"]
#: Where the poses of an evaluation come from (besides a path, a ``SolveResult`` or an ``Estimate``).
EstimateSource = Literal["solve", "vertices"]
#: The same, or no estimate at all (graph-only results).
EstimateSourceOrNone = Literal["solve", "vertices", "none"]
#: The solver's initial rotations.
Init = Literal["chordal", "vertices"]
#: How 3D edge quaternions become rotations: normalised, or as written (SE-Sync's reading).
Quaternions = Literal["normalize", "raw"]
#: The edges a selection always keeps (besides a file of pose-id pairs).
FixedRule = Literal["odometry"]
#: Where datasets or trials run: in this process or a local process pool, or on a Dask cluster.
Executor = Literal["local", "dask"]
#: The synthetic graphs of ``posecrb datasets synth`` (posecrb.sim.generators).
SynthKind = Literal["grid2d", "grid3d", "sphere", "torus", "octagon", "demo"]
#: What a Monte Carlo noise level k_c multiplies: both precisions, or only kappa (eq. 80 as printed).
NoiseScale = Literal["both", "rotation"]
#: The format of an estimate file: read from the content, or g2o/TORO VERTEX lines, Ceres' pose-graph
#: lines, TUM's timestamped lines or KITTI's 3x4 matrices (posecrb.io.estimates).
EstimateFormat = Literal["auto", "g2o", "toro", "ceres", "tum", "kitti"]
#: Which pose a TUM or KITTI row is: row k the k-th smallest id, or (TUM) the timestamp as the id.
RowOrder = Literal["order", "timestamps"]
#: What ``posecrb verify`` concludes about an estimate, strongest first.
Verdict = Literal["certified-optimal", "global-basin", "local-minimum", "uncertified"]
#: The verdicts ``posecrb verify --require`` can insist on.
RequiredVerdict = Literal["certified-optimal", "global-basin"]
#: Output formats of the commands (``tables`` adds LaTeX).
Format = Literal["table", "json", "csv", "markdown"]
TableFormat = Literal["table", "markdown", "csv", "json", "latex"]

MODELS: tuple[str, ...] = get_args(Model)
FIM_VARIANTS: tuple[str, ...] = get_args(FimVariant)
ROTATION_WEIGHTS: tuple[str, ...] = get_args(RotationWeight)
FRAMES: tuple[str, ...] = get_args(Frame)
ORDERINGS: tuple[str, ...] = get_args(Ordering)
OBJECTIVES: tuple[str, ...] = get_args(Objective)
METHODS: tuple[str, ...] = get_args(Method)
GAINS: tuple[str, ...] = get_args(Gains)
ESTIMATE_SOURCES: tuple[str, ...] = get_args(EstimateSource)
ESTIMATE_SOURCES_OR_NONE: tuple[str, ...] = get_args(EstimateSourceOrNone)
INITS: tuple[str, ...] = get_args(Init)
QUATERNION_MODES: tuple[str, ...] = get_args(Quaternions)
FIXED_RULES: tuple[str, ...] = get_args(FixedRule)
EXECUTORS: tuple[str, ...] = get_args(Executor)
SYNTH_KINDS: tuple[str, ...] = get_args(SynthKind)
NOISE_SCALES: tuple[str, ...] = get_args(NoiseScale)
ESTIMATE_FORMATS: tuple[str, ...] = get_args(EstimateFormat)
ROW_ORDERS: tuple[str, ...] = get_args(RowOrder)
VERDICTS: tuple[str, ...] = get_args(Verdict)
REQUIRED_VERDICTS: tuple[str, ...] = get_args(RequiredVerdict)
FORMATS: tuple[str, ...] = get_args(Format)
TABLE_FORMATS: tuple[str, ...] = get_args(TableFormat)

# What each gain strategy is for the selection driver: (greedy strategy, gains mode)
# (posecrb.selection.greedy.STRATEGIES, GAINS).
GAIN_MODES: dict[str, tuple[str, str]] = {
    "auto": ("auto", "auto"), "exact": ("incremental", "exact"), "rounds": ("rounds", "exact"),
    "lazy": ("lazy", "auto"), "lazy-exact": ("lazy", "exact"), "jl": ("lazy", "jl"),
}

__all__ = [
    "ESTIMATE_FORMATS", "REQUIRED_VERDICTS", "ROW_ORDERS", "VERDICTS", "EstimateFormat", "RequiredVerdict",
    "RowOrder", "Verdict",
    "ESTIMATE_SOURCES", "ESTIMATE_SOURCES_OR_NONE", "EXECUTORS", "FIM_VARIANTS", "FIXED_RULES", "FORMATS", "FRAMES",
    "GAINS", "GAIN_MODES", "INITS", "METHODS", "MODELS", "NOISE_SCALES", "OBJECTIVES", "ORDERINGS",
    "QUATERNION_MODES", "ROTATION_WEIGHTS", "SYNTH_KINDS", "TABLE_FORMATS", "EstimateSource", "EstimateSourceOrNone",
    "Executor", "FimVariant", "FixedRule", "Format", "Frame", "Gains", "Init", "Method", "Model", "NoiseScale",
    "Objective", "Ordering", "Quaternions", "RotationWeight", "SynthKind", "TableFormat",
]
