"""The wide figures' legends (``plot_tables``, ``plot_sparsify``) are readable where the documentation
shows them scaled to its column: at least ``LEGEND_FONTSIZE``, below every panel's tick labels (they
hide no point), and inside the figure."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from matplotlib.legend import Legend

from posecrb.experiments.sparsify import SparsifyResult
from posecrb.report import plots


def _laid_out(monkeypatch: pytest.MonkeyPatch, draw) -> dict[str, Any]:
    """The figure ``draw`` makes, laid out and drawn as ``save_figure`` would write it: its legends'
    font sizes and boxes, and the lowest edge of any panel's tick labels (display pixels)."""
    seen: dict[str, Any] = {}

    def inspect(fig, path):
        fig.tight_layout()
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        legends = [a for ax in fig.axes for a in ax.get_children() if isinstance(a, Legend)] + list(fig.legends)
        seen["sizes"] = [t.get_fontsize() for leg in legends for t in [*leg.get_texts(), leg.get_title()]
                         if t.get_text()]
        seen["boxes"] = [leg.get_window_extent(renderer) for leg in legends]
        ticks = [ax.xaxis.get_tightbbox(renderer) for ax in fig.axes if ax.axison]
        seen["panels_bottom"] = min(box.y0 for box in ticks if box is not None)
        seen["figure"] = fig.bbox
        import matplotlib.pyplot as plt
        plt.close(fig)
        return Path(path)

    monkeypatch.setattr(plots, "save_figure", inspect)
    draw()
    return seen


def _check(seen: dict[str, Any], legends: int) -> None:
    assert len(seen["boxes"]) == legends
    assert seen["sizes"] and min(seen["sizes"]) >= plots.LEGEND_FONTSIZE >= 10
    for box in seen["boxes"]:
        assert box.y1 <= seen["panels_bottom"], "a legend overlaps a panel or its tick labels"
        assert box.x0 >= seen["figure"].x0 and box.x1 <= seen["figure"].x1 and box.y0 >= seen["figure"].y0


@pytest.mark.parametrize("datasets", [1, 12])
def test_tables_legends_below_the_panels(monkeypatch, tmp_path, datasets):
    names = ["CSAIL", "intel", "manhattan", "kitti_00", "city10000", "ais2klinik", "tinyGrid3D", "smallGrid3D",
             "parking-garage", "sphere2500", "torus3D", "cubicle"][:datasets]
    rows = [{"dataset": name, "dim": 2 if k < 6 else 3, "status": "ok", "lb": 100.0, "fim_logdet": 101.0 + k,
             "ub": 110.0 + k, "fim_time": 1e-2, "ub_time": 1e-3, "lb_time": 1e-3, "fim_build_time": 1e-3,
             "laplacians_build_time": 1e-4} for k, name in enumerate(names)]
    seen = _laid_out(monkeypatch, lambda: plots.plot_tables(rows, tmp_path / "t.png", note="a note"))
    _check(seen, legends=2)


def test_sparsify_legend_below_the_panels(monkeypatch, tmp_path):
    methods = ["greedy", "relax", "fiedler-relax", "random", "naive"]
    rows = [{"method": m, "percent": p, "tree": 10.0 + p / 10 + k, "fiedler": 0.01 * (k + 1), "ate_trans": 0.1 / p}
            for k, m in enumerate(methods) for p in (10, 50, 100)]
    result = SparsifyResult(dataset="intel", path=None, sha256=None, dim=2, poses=1728, edges=2512, fixed=1727,
                            fixed_rule="odometry", candidates=785, anchor_id=0, objective="tree",
                            reference={"tree": 30.0, "fixed_only": {"tree": 10.0}}, rows=rows,
                            budgets=["10%", "50%", "100%"], methods=methods, seed=0)
    seen = _laid_out(monkeypatch, lambda: plots.plot_sparsify(result, tmp_path / "s.png"))
    _check(seen, legends=1)
