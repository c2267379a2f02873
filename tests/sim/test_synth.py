"""Synthetic generators: exact consistency with the ground truth, counts, g2o round trip, noise statistics."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial.transform import Rotation

from posecrb import load
from posecrb.cli import main
from posecrb.io import write_g2o
from posecrb.sim import generators as synth
from posecrb.sim.random_graphs import random_graph

from ..numerics import EPS, MARGIN


def compose_residual(g) -> tuple[float, float]:
    """max |R_i R~_ij - R_j| and max |t_i + R_i t~_ij - t_j| (X_i * Z_ij must equal X_j)."""
    R, t = g.vertex_rot, g.vertex_trans
    ri = R[g.src]
    rot_err = np.abs(ri @ g.rot - R[g.dst]).max()
    trans_err = np.abs(t[g.src] + np.einsum("kab,kb->ka", ri, g.trans) - t[g.dst]).max()
    return float(rot_err), float(trans_err)


def assert_rotations(r: np.ndarray) -> None:
    d = r.shape[-1]
    np.testing.assert_allclose(r @ np.swapaxes(r, -1, -2), np.broadcast_to(np.eye(d), r.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-12)


def n_components(g) -> int:
    a = coo_matrix((np.ones(g.m), (g.src, g.dst)), shape=(g.n, g.n))
    return connected_components(a, directed=False)[0]


GENERATORS = {
    "grid2d": lambda: synth.grid(2, 5),
    "grid3d": lambda: synth.grid(3, 4),
    "grid3d-truncated": lambda: synth.grid(3, 4, poses=37),
    "grid2d-random-rot": lambda: synth.grid(2, 4, orientation="random", rng=1),
    "sphere": lambda: synth.sphere(6, 7),
    "torus": lambda: synth.torus(5, 6),
    "torus-partial": lambda: synth.torus(5, 6, poses=23),
    "octagon": lambda: synth.octagon(21),
    "random2d": lambda: random_graph(np.random.default_rng(0), 15, 30, 2),
    "random3d": lambda: random_graph(np.random.default_rng(1), 15, 30, 3, info="block"),
}


@pytest.mark.parametrize("name", list(GENERATORS))
def test_noise_free_measurements_compose_exactly(name):
    g = GENERATORS[name]()
    assert_rotations(g.vertex_rot)
    assert_rotations(g.rot)
    rot_err, trans_err = compose_residual(g)
    assert rot_err < 1e-12 and trans_err < 1e-11
    assert n_components(g) == 1
    assert np.all(g.src != g.dst)
    assert g.format == "synthetic"


@pytest.mark.parametrize("name", list(GENERATORS))
def test_round_trip_through_g2o(name, tmp_path):
    g = GENERATORS[name]()
    f = tmp_path / f"{name}.g2o"
    write_g2o(g, f)
    h = load(f)
    assert (h.dim, h.n, h.m) == (g.dim, g.n, g.m)
    np.testing.assert_array_equal(h.ids, g.ids)
    np.testing.assert_array_equal(h.src, g.src)
    np.testing.assert_array_equal(h.dst, g.dst)
    # numbers are written with %.17g, which round-trips exactly; rotations go through an angle
    # (2D) or a unit quaternion (3D) and back: a few roundings of entries of size <= 1
    rot_atol = MARGIN * g.dim * EPS
    np.testing.assert_allclose(h.rot, g.rot, rtol=0, atol=rot_atol)
    np.testing.assert_array_equal(h.trans, g.trans)
    np.testing.assert_array_equal(h.info, g.info)
    np.testing.assert_allclose(h.vertex_rot, g.vertex_rot, rtol=0, atol=rot_atol)
    np.testing.assert_array_equal(h.vertex_trans, g.vertex_trans)
    np.testing.assert_array_equal(h.tau, g.tau)
    np.testing.assert_array_equal(h.kappa, g.kappa)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("side", [2, 3, 5])
def test_grid_counts_closed_form(dim, side):
    g = synth.grid(dim, side)
    assert g.n == side ** dim
    assert g.m == dim * side ** (dim - 1) * (side - 1)      # every lattice neighbour pair once
    pairs = {tuple(sorted(p)) for p in zip(g.src.tolist(), g.dst.tolist())}
    assert len(pairs) == g.m
    steps = np.abs(np.diff(g.vertex_trans, axis=0)).sum(axis=1)
    np.testing.assert_allclose(steps, 1.0)                   # the walk moves to a neighbour each step


@pytest.mark.parametrize("dim, side", [(2, 4), (2, 5), (3, 2), (3, 3), (3, 4)])
def test_boustrophedon_visits_every_cell_once_by_unit_steps(dim, side):
    c = synth.boustrophedon(side, dim, side ** dim)
    assert len({tuple(x) for x in c.tolist()}) == side ** dim
    assert (np.abs(np.diff(c, axis=0)).sum(axis=1) == 1).all()


def test_sphere_and_torus_counts():
    s = synth.sphere(50, 50)
    assert (s.n, s.m) == (2500, 4949)                        # as sphere2500.g2o
    np.testing.assert_allclose(np.linalg.norm(s.vertex_trans, axis=1), 50.0)
    t = synth.torus(7, 5)
    assert (t.n, t.m) == (35, 34 + 6 * 5 + 5)                # chain + ring links + wrap-around
    tp = synth.torus(7, 5, poses=30)
    assert tp.m == 29 + 25


def test_octagon_is_the_papers_figure_2():
    g = synth.octagon()
    assert (g.n, g.m) == (8, 7)
    assert list(zip(g.src.tolist(), g.dst.tolist())) == [(k, k + 1) for k in range(7)]
    side = 2 * math.sin(math.pi / 8)
    np.testing.assert_allclose(np.linalg.norm(g.trans, axis=1), side)
    np.testing.assert_allclose(g.tau, 1e4)                   # delta^2 = 1e-4
    np.testing.assert_allclose(g.kappa, 5e3)
    cand = synth.octagon_candidate_edges()
    assert len(cand) == 21 and len(set(cand)) == 21 and all(0 not in e for e in cand)
    g3 = synth.octagon(3)
    assert g3.m == 10 and list(zip(g3.src[7:].tolist(), g3.dst[7:].tolist())) == cand[:3]
    gr = synth.octagon(5, rng=4)
    extra = list(zip(gr.src[7:].tolist(), gr.dst[7:].tolist()))
    assert len(set(extra)) == 5 and set(extra) <= set(cand)
    gx = synth.octagon([(2, 6), (3, 7)])
    assert gx.m == 9
    with pytest.raises(ValueError):
        synth.octagon([(0, 0)])


def test_random_graph_properties():
    rng = np.random.default_rng(7)
    g = random_graph(rng, 30, 60, 3)
    assert (g.n, g.m) == (30, 60) and n_components(g) == 1
    assert np.any(np.diff(g.ids) > 1) and g.ids[0] > 0       # non-contiguous ids
    pairs = [tuple(sorted(p)) for p in zip(g.src.tolist(), g.dst.tolist())]
    assert len(set(pairs)) < g.m                             # at least one parallel edge
    eig = np.linalg.eigvalsh(g.info)
    assert eig.min() > 0                                     # positive definite
    assert np.abs(g.info[:, :3, 3:]).max() > 0               # "full": cross terms
    bt = np.linalg.eigvalsh(g.info[:, :3, :3])
    assert np.all(bt[:, -1] / bt[:, 0] > 1.0001)             # anisotropic
    b = random_graph(np.random.default_rng(7), 10, 12, 2, info="block")
    assert np.all(b.info[:, :2, 2:] == 0)
    i = random_graph(np.random.default_rng(7), 10, 12, 2, info="isotropic", id_gaps=False)
    np.testing.assert_array_equal(i.ids, np.arange(10))
    np.testing.assert_allclose(i.info[:, 0, 0], i.info[:, 1, 1])
    tree = random_graph(np.random.default_rng(3), 12, 11, 2)
    assert n_components(tree) == 1 and tree.m == 11


def test_same_seed_same_graph_and_noise_changes_measurements():
    a = synth.grid(3, 3, noise=True, rng=5)
    b = synth.grid(3, 3, noise=True, rng=np.random.default_rng(5))
    c = synth.grid(3, 3)
    np.testing.assert_array_equal(a.rot, b.rot)
    np.testing.assert_array_equal(a.trans, b.trans)
    assert np.abs(a.trans - c.trans).max() > 1e-4
    np.testing.assert_array_equal(a.vertex_trans, c.vertex_trans)   # truth unchanged
    with pytest.raises(ValueError, match="seed"):
        synth.grid(2, 3, noise=True)


@pytest.mark.parametrize("dim", [2, 3])
def test_isotropic_noise_has_the_model_variances(dim):
    """Translation residual variance 1/tau per axis; Langevin angle: E[1 - cos t] in closed form."""
    tau, kappa = 400.0, 50.0
    g = synth.grid(dim, 100 if dim == 2 else 20, tau=tau, kappa=kappa, noise=True, rng=11)
    exact = synth.grid(dim, 100 if dim == 2 else 20, tau=tau, kappa=kappa)
    y = g.trans - exact.trans                               # eq. (80): t~ = R_i^T (t_j - t_i) + y
    m = g.m
    var = (y ** 2).mean()
    assert abs(var * tau - 1) < 6 * math.sqrt(2 / (m * dim))
    z = np.swapaxes(exact.rot, 1, 2) @ g.rot                # Z_ij = R_ij^T R~_ij
    cos_t = (np.trace(z, axis1=1, axis2=2) - (dim - 2)) / 2 if dim == 3 else z[:, 0, 0]
    from scipy.special import ive
    x = 2 * kappa
    # E[cos t]: 2D I1/I0; 3D density prop. exp(2k cos t)(1 - cos t): (I1 - (I0 + I2)/2) / (I0 - I1).
    i0, i1, i2 = ive(0, x), ive(1, x), ive(2, x)
    expected = i1 / i0 if dim == 2 else (i1 - (i0 + i2) / 2) / (i0 - i1)
    mean = cos_t.mean()
    se = cos_t.std() / math.sqrt(m)
    assert abs(mean - expected) < 6 * se


def test_gaussian_noise_on_random_graph_is_whitened_by_its_information():
    rng = np.random.default_rng(3)
    n, m = 400, 3000
    g = random_graph(rng, n, m, 3, noise="gaussian", tau_range=(1e2, 1e3), kappa_range=(1e3, 1e4))
    exact = random_graph(np.random.default_rng(3), n, m, 3, tau_range=(1e2, 1e3), kappa_range=(1e3, 1e4))
    np.testing.assert_array_equal(exact.info, g.info)
    xt = g.trans - exact.trans
    xr = Rotation.from_matrix(np.swapaxes(exact.rot, 1, 2) @ g.rot).as_rotvec()
    xi = np.hstack([xt, xr])
    chi2 = np.einsum("ka,kab,kb->k", xi, g.info, xi)
    assert abs(chi2.mean() - 6) < 6 * math.sqrt(12 / m)      # chi-square with 6 dof


def test_builtin_demo_is_fixed():
    a, b = synth.builtin_demo(), synth.builtin_demo()
    assert (a.n, a.m, a.dim) == (100, 180, 2)
    np.testing.assert_array_equal(a.trans, b.trans)
    assert np.abs(a.trans - synth.grid(2, 10).trans).max() > 0


def test_generate_sizes():
    assert synth.generate("grid2d", 50).n == 50
    assert synth.generate("grid3d", 30).n == 30
    assert synth.generate("sphere", 100).n == 100
    t = synth.generate("torus", 5000)
    assert (t.n, t.m) == (5000, 2 * 5000 - 1)
    with pytest.raises(ValueError):
        synth.generate("octagon", 9)


def test_cli_synth(tmp_path, capsys):
    out = tmp_path / "g.g2o"
    assert main(["datasets", "synth", "grid3d", "--poses", "27", "--noise", "0.1", "--seed", "3",
                 "--out", str(out), "--format", "json"]) == 0
    g = load(out)
    assert (g.n, g.dim, g.m) == (27, 3, 54)
    np.testing.assert_allclose(g.tau, 100.0)
    np.testing.assert_allclose(g.kappa, 50.0)
    assert compose_residual(g)[1] > 1e-3                     # noisy
    assert main(["datasets", "synth", "sphere", "--poses", "16", "--tau", "9", "--noise-free",
                 "--out", str(out)]) == 0
    g = load(out)
    assert g.n == 16 and max(compose_residual(g)) < 1e-12 and np.allclose(g.tau, 9)
    assert main(["datasets", "synth", "octagon", "--poses", "9", "--out", str(out)]) == 2
    assert main(["datasets", "synth", "demo", "--out", str(out)]) == 0
    assert load(out).m == 180
