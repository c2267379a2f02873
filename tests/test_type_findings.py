"""Edge cases found by static type checking (mypy): each once crashed with a raw TypeError or
AttributeError (reported as an internal error) instead of a PosecrbError with a reason."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from posecrb.core.errors import UsageError
from posecrb.io import write_g2o

from .helpers import random_pose_graph


def test_write_g2o_rotations_without_translations_is_a_usage_error(tmp_path):
    graph, rot, _ = random_pose_graph(5, 2, np.random.default_rng(0))
    bare = replace(graph, vertex_rot=None, vertex_trans=None)
    with pytest.raises(UsageError, match="together"):
        write_g2o(bare, tmp_path / "out.g2o", rot=rot)
    assert not (tmp_path / "out.g2o").exists()
    # both given, or neither: written (the latter without vertices)
    write_g2o(bare, tmp_path / "both.g2o", rot=rot, trans=np.zeros((5, 2)))
    assert (tmp_path / "both.g2o").read_text().count("VERTEX_SE2") == 5
    write_g2o(bare, tmp_path / "none.g2o")
    assert "VERTEX_SE2" not in (tmp_path / "none.g2o").read_text()
