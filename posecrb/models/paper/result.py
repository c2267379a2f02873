"""``BoundsResult``: D-optimality of a pose graph (the paper's Table I/II row), made of its parts:
the graph-only bounds (``GraphBounds``, posecrb.models.paper.bounds) and the FIM's log-det at an
estimate (``FimAtEstimate``), with the times and the orderings of both.

``to_dict()`` is the ``bounds`` command's ``--format json`` object: the parts' keys inlined in the
order of the command's columns (posecrb.core.result).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from ...core.result import KEY, NESTED, GraphKeys, Result, derived_field, inputs_field, part_field, status_field
from ...core.status import Status
from ...solver.estimate import Estimate
from .bounds import GraphBounds


@dataclass(frozen=True, kw_only=True)
class FimAtEstimate(Result):
    """The paper model's anchored FIM at an estimate, as ``bounds`` reports it: its log-det
    (D-optimality) with the status of its accuracy, its trace (T-optimality), the FIM variant and
    where the poses come from.

    ``to_dict()`` gives the keys ``fim_logdet`` (``fim_logdet_status`` when not ok), ``trace_fim``,
    ``fim_variant`` and ``estimate`` of the ``bounds`` JSON.

    Attributes
    ----------
    logdet : float or None
        log det of the anchored FIM (natural log); None when no digit of it is correct
        (``logdet_status``: a warning when its rounding-error bound exceeds 1e-6 relative).
    trace : float
        Its trace.
    variant : str
        ``"consistent"`` (the model's Fisher information) or ``"eq64"`` (eq. 64 as printed).
    estimate : Estimate
        Where the poses come from.

    Examples
    --------
    >>> import posecrb
    >>> part = posecrb.bounds("intel").fim
    >>> round(part.logdet, 3), part.variant, part.estimate.source
    (30194.332, 'consistent', 'solve')
    """

    logdet: float | None = field(metadata={KEY: "fim_logdet"})
    logdet_status: Status = status_field("FIM log-det", key="fim_logdet_status")
    trace: float = field(metadata={KEY: "trace_fim"})
    variant: str = field(metadata={KEY: "fim_variant"})
    estimate: Estimate = field(metadata={NESTED: Estimate})


def _solver_status(res: BoundsResult) -> str | None:
    """The JSON's ``status``: ``"uncertified"`` when the solver did not certify the estimate."""
    return "uncertified" if res.fim is not None and res.fim.estimate.certified is False else None


@dataclass(frozen=True, kw_only=True)
class BoundsResult(GraphKeys):
    """D-optimality of a pose graph: the paper's Table I/II row, what ``posecrb bounds`` prints.

    Two parts: ``bounds``, the graph-only bounds on the log-determinant of the paper model's
    anchored FIM (section VII-B: ``lb = d logdet(L_tau) + d_r logdet(L_w)``, eq. 75 left and
    Algorithm 1; ``ub``, the paper's Table I/II upper bound, eq. 75 middle with the measured p_ij;
    ``ub_lambda``, eq. 75 right with lambda_inf, eq. 77; Lemma 4's bound on ``fim_logdet - lb``;
    T-optimality, eq. 73 and 72), and with an estimate ``fim``, the log-det of the FIM itself
    there. Natural logarithms. Translations are in the file's length units: scaling every length
    by s moves ``lb``, ``ub``, ``ub_lambda`` and ``fim_logdet`` together by ``-2 d n_p log s``
    (n_p = n - 1). 3D rotation weights by eq. (59) or the ``"table2"`` fit.

    ``to_dict()`` is the command's JSON object, the parts' keys inlined (``status`` is
    ``"uncertified"`` when the solver did not certify the estimate, absent otherwise);
    ``to_frame()`` one row of it, so that ``pandas.concat`` of several is a table over datasets.

    Attributes
    ----------
    dataset, path, sha256 : str or None
        The graph's name, file and the file's sha256.
    dim, poses, edges, components : int
        d, n, m and the number of connected components.
    bounds : GraphBounds
        The graph-only bounds (``lb``, ``ub``, ``ub_lambda``, Lemma 4, T-optimality).
    times : dict of str to float
        Seconds per step (medians of ``repeat`` runs).
    runs : dict of str to int
        Per key of ``times``: how many runs its median is of.
    fim : FimAtEstimate or None
        The FIM's log-det and trace at the estimate (None: ``estimate=None``).
    ordering : dict of str to str
        ``requested`` and the ordering of each factorization (``lb``, ``ub``, ``fim``).
    lb, ub, ub_lambda, fim_logdet : float or None
        Shortcuts to ``bounds.lb``, ``bounds.ub``, ``bounds.ub_lambda`` and ``fim.logdet``.

    Examples
    --------
    >>> import posecrb
    >>> res = posecrb.bounds("intel")
    >>> round(res.lb, 3), round(res.ub, 3), round(res.fim_logdet, 3)
    (30155.231, 30352.516, 30194.332)
    >>> res.lb <= res.fim_logdet <= res.lb + res.bounds.gap_bound
    True
    """

    components: int
    bounds: GraphBounds = part_field(GraphBounds)
    times: dict[str, float] = field(default_factory=dict)
    runs: dict[str, int] = field(default_factory=dict)
    fim: FimAtEstimate | None = part_field(FimAtEstimate, optional=True)
    solver_status: str | None = derived_field(_solver_status, key="status", omit_none=True)
    ordering: dict[str, str] = field(default_factory=dict)
    inputs: tuple[str, ...] = inputs_field()

    @property
    def lb(self) -> float:
        """``bounds.lb``: eq. (75)'s lower bound."""
        return self.bounds.lb

    @property
    def ub(self) -> float | None:
        """``bounds.ub``: the paper's Table I/II upper bound (None when unavailable)."""
        return self.bounds.ub

    @property
    def ub_lambda(self) -> float:
        """``bounds.ub_lambda``: eq. (75) right with lambda_inf."""
        return self.bounds.ub_lambda

    @property
    def fim_logdet(self) -> float | None:
        """``fim.logdet``: the FIM's log-det at the estimate (None without one)."""
        return None if self.fim is None else self.fim.logdet
