"""``posecrb.load`` and ``posecrb.parse``: a pose graph from a file, a dataset name or a file's content."""
from __future__ import annotations

import os

from ..core.arguments import choice
from ..core.choices import QUATERNION_MODES, Quaternions
from ..core.graph import PoseGraph
from . import arguments as arg
from .arguments import public


@public()
def load(source: str | os.PathLike[str], data_dir: str | os.PathLike[str] | None = None, *,
         quaternions: Quaternions = "normalize") -> PoseGraph:
    """Read a pose graph from a g2o or TORO file, by path or by dataset name.

    The format is found from the content, never from the file name. A bare name (``"intel"``,
    ``"garage"``) is resolved exactly as the command line resolves its FILE arguments.

    Parameters
    ----------
    source : str or os.PathLike
        A path, or a dataset name looked up in ``data_dir``, ``$POSECRB_DATA``, ``./datasets``
        and ``~/.cache/posecrb`` (then the manifest's names, e.g. the paper's ``garage``).
    data_dir : str or os.PathLike, optional
        Directory searched first for bare names (the command line's ``--data-dir``).
    quaternions : {"normalize", "raw"}
        How 3D edge quaternions become rotations: normalised (default), or as written, as
        SE-Sync reads them (only to reproduce SE-Sync's objective values).

    Returns
    -------
    PoseGraph
        The checked graph; pose ids as in the file (``graph.ids``).

    Raises
    ------
    DatasetNotFound
        A bare name that is nowhere on the search path.
    ParseError
        The file cannot be read or is malformed (``path:line: reason``).
    ArgumentError
        ``source`` is not a path or a name (bytes: use ``parse``).

    Examples
    --------
    >>> import posecrb
    >>> graph = posecrb.load("intel")
    >>> graph.dim, graph.n, graph.m
    (2, 1728, 2512)
    """
    choice("quaternions", quaternions, QUATERNION_MODES)
    return arg.load_graph(source, data_dir, quaternions=quaternions)[0]


@public()
def parse(text: str | bytes) -> PoseGraph:
    """Read a pose graph from the content of a g2o or TORO file.

    Parameters
    ----------
    text : str or bytes
        The file's content (bytes are decoded as UTF-8). The format is detected from the records.

    Returns
    -------
    PoseGraph
        The checked graph (its ``path`` is ``"<string>"``).

    Raises
    ------
    ParseError
        Malformed content (``<string>:line: reason``).
    ArgumentError
        ``text`` is neither ``str`` nor ``bytes``.

    Examples
    --------
    >>> import posecrb
    >>> g = posecrb.parse('''
    ... EDGE_SE2 0 1 1 0 0 100 0 0 100 0 1000
    ... EDGE_SE2 1 2 1 0 0 100 0 0 100 0 1000
    ... EDGE_SE2 2 0 -2 0 0 100 0 0 100 0 1000
    ... ''')
    >>> g.dim, g.n, g.m, g.ids.tolist()
    (2, 3, 3, [0, 1, 2])
    """
    return arg.parse_content(text)
