"""The library's writers never replace what they were given: ``Result.save``, ``posecrb.io.write_g2o``
(and ``write_toro``, ``posecrb.io.save``) and ``posecrb.report.plot_timeline`` each refuse the file of
every graph or result they are given, a loaded graph's ``path`` included."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

import posecrb
from posecrb.io import save, write_g2o, write_toro
from posecrb.report import plot_timeline

DATA = Path(__file__).resolve().parents[1] / "data" / "cli_json"


def _copy(tmp_path: Path, name: str) -> Path:
    """g2d.g2o under another name (the format comes from the content, not the suffix)."""
    target = tmp_path / name
    shutil.copy(DATA / "g2d.g2o", target)
    return target


@pytest.mark.parametrize("name", ["g.g2o", "g.npz", "g.png", "g.graph"])
def test_every_writer_refuses_the_file_of_the_graph_or_result_it_was_given(tmp_path, name):
    """`G = posecrb.load("myintel.g2o"); posecrb.select(G, budget=5, out="myintel.g2o")` replaced the
    input with the pruned graph: a graph object contributed no input to the check."""
    path = _copy(tmp_path, name)
    before = path.read_bytes()
    graph = posecrb.load(path)
    sel = posecrb.select(graph, budget=2)
    line = posecrb.timeline(graph, estimate="vertices")
    npz, png = name.endswith(".npz"), name.endswith(".png")
    writers = [   # (writer, whether its target is the input file: save appends .npz to another name)
        (lambda: write_g2o(graph, path), True),
        (lambda: write_g2o(graph, str(path), graph.vertex_rot, graph.vertex_trans), True),
        (lambda: write_toro(graph, path), True),
        (lambda: save(graph, path, format="g2o"), True),
        (lambda: write_g2o(sel.pruned_graph(graph), path), True),
        (lambda: sel.save(path), npz),
        (lambda: posecrb.bounds(graph, estimate="vertices").save(path), npz),
        (lambda: posecrb.fim(graph, estimate="vertices").save(path), npz),
        (lambda: posecrb.crlb(graph, estimate="vertices").save(path), npz),
        (lambda: line.save(path), npz),
        (lambda: plot_timeline(line, path), png),
    ]
    for k, (write, onto_input) in enumerate(writers):
        try:
            write()
            refusal = ""
        except posecrb.PosecrbError as exc:
            refusal = str(exc)
        assert path.read_bytes() == before, (name, k)
        if onto_input:
            assert "is the input file" in refusal, (name, k, refusal)


def test_an_estimate_file_is_an_input_of_its_results(tmp_path):
    path = _copy(tmp_path, "g.g2o")
    estimate = _copy(tmp_path, "est.npz")
    res = posecrb.fim(path, estimate=str(estimate))
    assert set(res.input_paths()) == {str(path), str(estimate)}
    with pytest.raises(posecrb.ArgumentError, match="is the input file"):
        res.save(estimate)
    line = posecrb.timeline(path, estimate=str(estimate))
    png = _copy(tmp_path, "est.png")
    assert str(estimate) in line.input_paths()
    assert posecrb.timeline(path, estimate=str(png)).input_paths() == (str(path), str(png))
    with pytest.raises(posecrb.ArgumentError, match="is the input file"):
        plot_timeline(posecrb.timeline(path, estimate=str(png)), png)


def test_writing_elsewhere_works_and_a_pruned_graph_keeps_its_origin(tmp_path):
    path = _copy(tmp_path, "g.g2o")
    graph = posecrb.load(path)
    sel = posecrb.select(graph, budget=2)
    pruned = sel.pruned_graph(graph)
    assert pruned.path == graph.path and pruned.m == sel.fixed.edges + sel.budget
    write_g2o(pruned, tmp_path / "pruned.g2o")
    assert posecrb.load(tmp_path / "pruned.g2o").m == pruned.m
    assert Path(sel.save(tmp_path / "sel")).name == "sel.npz"
    assert plot_timeline(posecrb.timeline(graph, estimate="vertices"), tmp_path / "t.png").exists()
    with pytest.raises(posecrb.UsageError, match="rebuilt from a dict"):
        posecrb.SelectResult.from_dict(sel.to_dict()).pruned_graph(graph)
