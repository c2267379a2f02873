"""The two estimation models behind one protocol: ``Model.fim`` and ``Model.crlb`` at an estimate.

``PaperModel`` (``PaperSettings``): Chen et al.'s anchored FIM on (R^d x SO(d))^n
(docs/design.md#paper-fim) and its CRLB (docs/design.md#crlb). ``SedModel`` (``SedSettings``): the
thesis's FIM on SE(d)^n (docs/design.md#thesis-fim) and its anchored or quotient CRLB
(docs/design.md#anchored-crb), in world or body coordinates (docs/design.md#frames). A model holds
its settings; both return the public results of ``posecrb.models.results``. Anchors and per-pose
requests are pose ids, internal indices exist only below. ``model_for`` makes the model a name of
``posecrb.core.choices.MODELS`` stands for from the keywords of ``posecrb.fim`` / ``posecrb.crlb``.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

from ..core.arguments import choice, flag
from ..core.choices import FIM_VARIANTS, FRAMES, MODELS, ORDERINGS, ROTATION_WEIGHTS
from ..core.errors import ArgumentError
from ..core.graph import PoseGraph
from ..solver.estimate import Estimate
from .paper.model import PaperModel, PaperSettings
from .results import CrlbResult, FimResult
from .sed.model import SedModel, SedSettings


class Model(Protocol):
    """An estimation model with its settings: its FIM and its CRLB at an estimate."""

    @property
    def name(self) -> str:
        """``"paper"`` or ``"sed"`` (the JSON's ``model``)."""
        ...

    def fim(self, graph: PoseGraph, estimate: Estimate, *, anchor: int | None = None) -> FimResult:
        """The Fisher information matrix at ``estimate`` (its log-det anchored at the pose id
        ``anchor``, default the smallest id of each component)."""
        ...

    def crlb(self, graph: PoseGraph, estimate: Estimate, *, anchors: Sequence[int] = (),
             poses: bool | Sequence[int] = False) -> CrlbResult:
        """The Cramér-Rao lower bound at ``estimate`` (anchored at the pose ids ``anchors``), with
        the per-pose blocks of ``poses`` (True: every pose)."""
        ...


def model_for(model: Any, *, rotation_weight: Any = "eq59", fim_variant: Any = None, frame: Any = None,
              quotient: Any = False, ordering: Any = "auto") -> Model:
    """The model ``model`` names with the settings given as keywords, checked: a value outside its
    choices, or a setting of the other model (``frame`` or ``quotient`` with ``"paper"``,
    ``fim_variant`` with ``"sed"``), is an ``ArgumentError`` naming the keyword."""
    model = choice("model", model, MODELS)
    ordering = choice("ordering", ordering, ORDERINGS)
    if model == "paper":
        if frame is not None:
            raise ArgumentError("frame", frame, "applies to the sed model (the paper model's coordinates are "
                                "translation in the world frame, rotation in the body frame)")
        if flag("quotient", quotient):
            raise ArgumentError("quotient", quotient, "applies to the sed model (the paper model is anchored)")
        variant = choice("fim_variant", "consistent" if fim_variant is None else fim_variant, FIM_VARIANTS)
        return PaperModel(PaperSettings(rotation_weight=choice("rotation_weight", rotation_weight, ROTATION_WEIGHTS),
                                        fim_variant=variant, ordering=ordering))
    if fim_variant is not None:
        raise ArgumentError("fim_variant", fim_variant, "applies to the paper model (model='paper')")
    choice("rotation_weight", rotation_weight, ROTATION_WEIGHTS)      # a paper setting; checked, not used
    return SedModel(SedSettings(frame=choice("frame", "world" if frame is None else frame, FRAMES),
                                quotient=flag("quotient", quotient), ordering=ordering))


__all__ = ["CrlbResult", "FimResult", "Model", "PaperModel", "PaperSettings", "SedModel", "SedSettings",
           "model_for"]
