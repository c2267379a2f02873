"""A PoseGraph is frozen, arrays included: a caller cannot change its measurements behind the
cached values derived from them, and the caller's own arrays are neither frozen nor shared."""
from __future__ import annotations

import dataclasses
import inspect

import numpy as np
import pytest

import posecrb
from posecrb.core.graph import PoseGraph
from posecrb.sim.generators import grid

ARRAYS = ("ids", "src", "dst", "rot", "trans", "info", "vertex_rot", "vertex_trans", "edge_lines")
DERIVED = ("tau", "kappa", "rotation_weights", "degree", "component_labels")

# Every public function that takes a graph, with the keywords it needs (estimates at the vertices:
# the file's own poses, so every function reads the arrays a caller might try to change).
CALLS = {
    "solve": {},
    "bounds": {"estimate": "vertices"},
    "fim": {"estimate": "vertices"},
    "crlb": {"estimate": "vertices"},
    "select": {"budget": 3},
    "timeline": {"estimate": "vertices"},
    "verify": {"estimate": "the graph's vertices"},     # as an Estimate, made from each graph
}


def _keywords(name: str, g: PoseGraph) -> dict:
    if name == "verify":
        return {"estimate": posecrb.Estimate(np.array(g.vertex_rot), np.array(g.vertex_trans))}
    return CALLS[name]


def _attempt_every_change(g: PoseGraph) -> None:
    """What a caller might do to a graph's arrays; each must fail."""
    for name in ARRAYS + DERIVED:
        arr = getattr(g, name)
        if arr is None:
            continue
        with pytest.raises(ValueError, match="read-only"):
            arr[...] = 0
        with pytest.raises(ValueError, match="read-only"):
            arr *= 4
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(g, name, arr * 4)


def _without_times(value):
    if isinstance(value, dict):
        return {k: _without_times(v) for k, v in value.items()
                if k not in ("times", "runs") and not k.endswith(("_time", "_seconds"))}
    if isinstance(value, list):
        return [_without_times(v) for v in value]
    return value


def _copy(g: PoseGraph) -> PoseGraph:
    return PoseGraph(**{f.name: (np.array(v) if isinstance(v, np.ndarray) else v)
                        for f in dataclasses.fields(g) for v in [getattr(g, f.name)]})


def test_the_calls_cover_every_public_function_that_takes_a_graph():
    public = {name for name in posecrb.__all__ if inspect.isfunction(getattr(posecrb, name))}
    assert public - {"load", "parse"} == set(CALLS)


@pytest.mark.parametrize("dim", [2, 3])
def test_every_public_function_on_a_graph_whose_arrays_a_caller_tried_to_change(dim):
    g = grid(dim, 3, noise=True, rng=5)
    pristine = _copy(g)
    _ = g.tau, g.rotation_weights, g.n_components, g.degree        # fill the caches first
    _attempt_every_change(g)
    for name in CALLS:
        fn, kwargs = getattr(posecrb, name), _keywords(name, g)
        assert _without_times(fn(g, **kwargs).to_dict()) == _without_times(fn(pristine, **kwargs).to_dict()), name
    for name in ARRAYS:
        if getattr(g, name) is not None:
            np.testing.assert_array_equal(getattr(g, name), getattr(pristine, name))
            assert not getattr(g, name).flags.writeable


def test_bounds_after_an_attempted_change_of_the_information(shared_datasets):
    # the reported scenario: `G.info[:] *= 4` changed the information under cached tau and kappa,
    # and bounds gave lb from the new information above fim_logdet from the cached one
    g = posecrb.load(shared_datasets / "intel.g2o")
    before = posecrb.bounds(g, estimate="vertices")
    with pytest.raises(ValueError, match="read-only"):
        g.info[:] *= 4
    with pytest.raises(ValueError, match="read-only"):
        g.tau[:] = 1.0                  # the reader's seeded cache too
    after = posecrb.bounds(g, estimate="vertices")
    assert after.lb == before.lb and after.fim_logdet == before.fim_logdet
    assert after.lb <= after.fim_logdet <= after.ub and after.status.ok


def test_the_callers_arrays_stay_writeable_and_their_changes_do_not_reach_the_graph():
    g = grid(2, 3, noise=True, rng=1)
    info = np.array(g.info)
    memory = np.zeros((2 * g.m, 3, 3))
    memory[::2] = g.info
    view = memory[::2]                                    # a view of the caller's memory
    a = dataclasses.replace(g, info=info)
    b = dataclasses.replace(g, info=view)
    assert info.flags.writeable and view.flags.writeable and memory.flags.writeable
    tau = a.tau.copy()
    info *= 4
    memory *= 4
    np.testing.assert_array_equal(a.info, g.info)
    np.testing.assert_array_equal(b.info, g.info)
    np.testing.assert_array_equal(a.tau, tau)


def test_replace_shares_the_frozen_arrays_it_keeps():
    g = grid(2, 3, noise=True, rng=1)
    h = dataclasses.replace(g, vertex_rot=np.array(g.vertex_rot))
    assert h.rot is g.rot and h.info is g.info and h.src is g.src
    assert h.vertex_rot is not g.vertex_rot and not h.vertex_rot.flags.writeable
    # a read-only view of writeable memory is not frozen: copied
    memory = np.array(g.info)
    view = memory[:]
    view.setflags(write=False)
    k = dataclasses.replace(g, info=view)
    assert k.info is not view
    memory *= 4
    np.testing.assert_array_equal(k.info, g.info)
