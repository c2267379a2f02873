"""CHOLMOD wrapper: log-det vs numpy slogdet, shared ordering, non-PD reported."""
import numpy as np
import pytest
import scipy.sparse as sp

from posecrb.core.errors import NotPositiveDefinite
from posecrb.linalg.cholesky import SymbolicCholesky, lambda_min, logdet, solve_tail

from ..numerics import EPS, MARGIN, inverse_entry_atol, logdet_atol


def _spd(rng, n, density=0.05):
    a = sp.random(n, n, density=density, random_state=np.random.RandomState(int(rng.integers(1 << 30))))
    return (a @ a.T + sp.identity(n) * 0.5).tocsc()


@pytest.mark.parametrize("n", [5, 60, 400])
def test_logdet_matches_slogdet(n):
    rng = np.random.default_rng(n)
    a = _spd(rng, n)
    sign, ref = np.linalg.slogdet(a.toarray())
    assert sign == 1
    assert logdet(a) == pytest.approx(ref, abs=logdet_atol(a.toarray()))
    shifted = a.toarray() + 2.5 * np.eye(n)
    assert logdet(a, beta=2.5) == pytest.approx(np.linalg.slogdet(shifted)[1], abs=logdet_atol(shifted))


def test_shared_symbolic_analysis_reused():
    rng = np.random.default_rng(3)
    a = _spd(rng, 200)
    b = a.copy()
    b.data = b.data * 3.0 + 0.0  # same pattern, different values
    sym = SymbolicCholesky(a)
    assert sym.factor(b).logdet() == pytest.approx(np.linalg.slogdet(b.toarray())[1], abs=logdet_atol(b.toarray()))
    with pytest.raises(ValueError):
        sym.factor(sp.identity(3, format="csc"))


@pytest.mark.parametrize("mode", ["simplicial", "supernodal"])
def test_not_positive_definite_is_reported(mode):
    a = sp.csc_matrix(np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    with pytest.raises(NotPositiveDefinite) as exc:
        SymbolicCholesky(a, mode=mode).factor(a, name="test matrix")
    assert "test matrix" in str(exc.value)


def test_singular_laplacian_reported():
    lap = sp.csc_matrix(np.array([[1.0, -1.0], [-1.0, 1.0]]))
    with pytest.raises(NotPositiveDefinite):
        logdet(lap, name="L")


def test_lambda_min_matches_dense():
    rng = np.random.default_rng(5)
    for n in (50, 500):
        a = _spd(rng, n, density=0.01)
        ev = np.linalg.eigvalsh(a.toarray())
        # symmetric eigenvalues are perturbed by at most the backward error ~ n eps ||A||_2
        assert lambda_min(a) == pytest.approx(ev[0], abs=MARGIN * n * EPS * ev[-1])



@pytest.mark.parametrize("ordered", [False, True])
@pytest.mark.parametrize("k", [1, 3])
def test_solve_tail_is_the_last_rows_of_the_full_solve(ordered, k):
    """Rows first: of A^-1 [0; W]: bit for bit the full solve's, and the dense Schur complement's
    inverse applied to W within the inverse's rounding (an independent reference), for CHOLMOD's
    own ordering and for a user permutation (PermutedFactor)."""
    rng = np.random.default_rng(7 + k)
    n, first = 150, 40
    a = _spd(rng, n, density=0.04)
    perm = rng.permutation(n) if ordered else None
    f = SymbolicCholesky(a, permutation=perm).factor(a)
    W = rng.standard_normal((n - first, k))
    b = np.zeros((n, k))
    b[first:] = W
    got = solve_tail(f, first, W)
    assert got.shape == W.shape and got.flags.c_contiguous
    assert np.array_equal(got, f(b)[first:])
    dense = a.toarray()
    top, side = dense[:first, :first], dense[:first, first:]
    schur = dense[first:, first:] - side.T @ np.linalg.solve(top, side)
    ref = np.linalg.solve(schur, W)
    # (A^-1)[first:, first:] = schur^-1: each entry within the inverse's rounding, times the 1-norm of a column of W
    atol = inverse_entry_atol(dense) * np.abs(W).sum(axis=0).max()
    assert np.max(np.abs(got - ref)) <= atol

def test_lambda_min_unconverged_is_an_error_not_an_estimate(monkeypatch):
    import posecrb.linalg.cholesky as chol
    from posecrb.core.errors import NumericalError
    from posecrb.linalg.lanczos import RitzPair

    a = _spd(np.random.default_rng(6), 300, density=0.01)
    monkeypatch.setattr(chol, "largest_eigenpair",
                        lambda *args, **kw: RitzPair(1.0, np.ones(300), 0.5, False, 6000, 300))
    with pytest.raises(NumericalError, match="did not converge"):
        lambda_min(a, name="A")


_CYCLE_SCRIPT = r"""
import ctypes, gc, os, sys
import scipy.sparse as sp
if sys.argv[1] == "posecrb":
    import posecrb.linalg.cholesky  # noqa: F401  (the fix is applied on import)
from sksparse.cholmod import analyze
# Where scikit-sparse 0.4.16 + SuiteSparse 5 write when a Factor's _common was cleared to None:
# None + 24 (object header and vtable pointer of Common) + 1972 (cholmod_common.status).
probe = ctypes.c_int.from_address(id(None) + 24 + 1972)
before = probe.value
gc.disable()
for _ in range(3):
    f = analyze(sp.identity(5, format="csc") * 2.0)   # allocated before the cycle: cleared first
    box = type("Box", (), {})()
    box.f, box.me = f, box
    del f, box
gc.collect()
print(before, probe.value, flush=True)
os._exit(0)                                        # never finalize an interpreter that may be corrupted
"""


def test_factor_in_a_reference_cycle_is_freed_with_its_common():
    """scikit-sparse's Factor, collected inside a reference cycle, must not reach CHOLMOD with
    ``_common`` already cleared to None (CHOLMOD then writes -4 past None: memory corruption)."""
    import ctypes
    import os
    import subprocess
    import sys
    from pathlib import Path

    from sksparse.cholmod import Factor

    get_slot = ctypes.pythonapi.PyType_GetSlot
    get_slot.restype, get_slot.argtypes = ctypes.c_void_p, [ctypes.py_object, ctypes.c_int]
    assert get_slot(Factor, 51) is None                # Py_tp_clear emptied by posecrb.linalg.cholesky

    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}

    def run(mode):
        out = subprocess.run([sys.executable, "-c", _CYCLE_SCRIPT, mode], capture_output=True, text=True,
                             env=env, timeout=120, check=True).stdout.split()
        return int(out[0]), int(out[1])

    bare = run("bare")
    if bare[0] == bare[1]:
        pytest.skip("this scikit-sparse/CHOLMOD build does not write at the probed address")
    assert bare[1] == -4                               # the defect, reproduced without posecrb
    fixed = run("posecrb")
    assert fixed[0] == fixed[1]
