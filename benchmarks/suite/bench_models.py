"""Fisher information and Cramér-Rao bounds at the file's vertices: ``posecrb.fim`` and ``posecrb.crlb``,
and the fill-reducing orderings of their factorizations."""
from __future__ import annotations

from . import inputs
from .common import Benchmark

# The orderings compared (``ordering=`` of fim, crlb and bounds); auto is posecrb's rule.
ORDERINGS = ("auto", "amd", "metis", "nesdis")


class Fim(Benchmark):
    """The paper FIM (eq. 42 / 64), its log-det and the log-det's accuracy bound."""

    params = [inputs.WITH_VERTICES + inputs.GRIDS]

    def setup(self, name: str) -> None:
        import posecrb

        self.prepare(name, lambda graph: posecrb.fim(graph, estimate="vertices"))

    def time_fim(self, name: str) -> None:
        self.call(self.input)

    def peakmem_fim(self, name: str) -> None:
        self.call(self.input)


class Crlb(Benchmark):
    """The paper model's CRLB trace (eq. 67, with eq. 68's curvature term in 3D)."""

    params = Fim.params

    def setup(self, name: str) -> None:
        import posecrb

        self.prepare(name, lambda graph: posecrb.crlb(graph, estimate="vertices"))

    def time_crlb(self, name: str) -> None:
        self.call(self.input)

    def peakmem_crlb(self, name: str) -> None:
        self.call(self.input)


class CrlbPerPose(Benchmark):
    """Every pose's covariance block of the sed model's anchored bound in GTSAM's coordinates
    (``crlb(model="sed", frame="body", poses="all")``): what GTSAM's ``Marginals`` computes
    (benchmarks/peers/gtsam_marginals.py compares the two as whole processes)."""

    params = [(inputs.GRID_3D_SMALL,) if inputs.QUICK else ("intel", "city10000", "sphere2500", "torus3D")]

    def setup(self, name: str) -> None:
        import posecrb

        self.prepare(name, lambda graph: posecrb.crlb(graph, model="sed", frame="body", estimate="vertices",
                                                      poses="all"))

    def time_crlb_per_pose(self, name: str) -> None:
        self.call(self.input)


class Orderings(Benchmark):
    """``fim`` with each fill-reducing ordering: the data behind ``ordering="auto"`` (the 3D grid of
    5,832 poses, not 21,952: there AMD's factor alone takes 895 Gflop, and its flop counts are in
    docs/decisions/orderings.md)."""

    params = [(inputs.GRID_3D_SMALL,) if inputs.QUICK else ("city10000", "sphere2500", "grid2d-100000", "grid3d-5000"),
              ORDERINGS]
    param_names = ["input", "ordering"]

    def setup(self, name: str, ordering: str) -> None:
        import posecrb

        self.prepare(name, lambda graph: posecrb.fim(graph, estimate="vertices", ordering=ordering))

    def time_fim(self, name: str, ordering: str) -> None:
        self.call(self.input)
