"""The library's shape: no public function writes a file, the signatures take Python values (no
command-line spellings), every choice is a Literal of posecrb.core.choices, and the removed keywords
say what to call instead."""
from __future__ import annotations

import ast
import inspect
import textwrap
import typing

import pytest

import posecrb
from posecrb.core import choices

FUNCTIONS = [n for n in posecrb.__all__ if inspect.isfunction(getattr(posecrb, n))]
# Calls that write a file (the output layer's writers, numpy's and matplotlib's) and the modes of open().
WRITERS = {"atomic_write", "write_text", "write_g2o", "write_toro", "save", "savez", "savez_compressed",
           "savefig", "save_figure", "to_csv", "to_json", "write_run_record", "make_output_dir", "dump",
           "write_bytes", "mkdir", "replace", "rename", "unlink"}
WRITE_MODES = ("w", "a", "x", "+")


def _calls(fn) -> list[tuple[str, ast.Call]]:
    """(called name, node) of every call in the body of ``fn`` (nested functions included)."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(inspect.unwrap(fn))))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
            out.append((name, node))
    return out


def _opens_for_writing(name: str, node: ast.Call) -> bool:
    if name != "open":
        return False
    modes = list(node.args[1:2]) + [k.value for k in node.keywords if k.arg == "mode"]
    return any(not isinstance(m, ast.Constant) or any(c in str(m.value) for c in WRITE_MODES) for m in modes)


@pytest.mark.parametrize("name", FUNCTIONS)
def test_no_public_function_opens_a_file_for_writing(name):
    fn = getattr(posecrb, name)
    calls = _calls(fn)
    assert calls, name
    bad = [n for n, node in calls if n in WRITERS or _opens_for_writing(n, node)]
    # dataclasses.replace copies a result (not os.replace): allowed by name only as replace(res, ...)
    bad = [n for n in bad if n != "replace"] + [
        "os.replace" for n, node in calls if n == "replace" and isinstance(node.func, ast.Attribute)]
    assert bad == [], f"{name} calls {bad}"
    sig = inspect.signature(fn)
    assert not {"out", "save", "plot"} & set(sig.parameters), name


def test_the_check_sees_a_writer():
    """Not vacuous: a function that opens a file for writing, or calls a writer, is caught."""

    def writes(path):
        with open(path, "w") as fh:
            fh.write("x")

    def saves(res, path):
        res.save(path)

    assert any(_opens_for_writing(n, node) for n, node in _calls(writes))
    assert any(n in WRITERS for n, _ in _calls(saves))


# Parameters that take counts, ids, budgets and pose selections: numbers or sequences, never text
# (only the Literal spellings "auto" and "all" of repeat and poses).
NUMERIC = {"anchor", "budget", "poses", "every", "start", "stop", "repeat", "seed", "max_iter", "r0", "rmax", "tol",
           "certificate_tol"}


@pytest.mark.parametrize("name", FUNCTIONS)
def test_signatures_take_no_command_line_spellings(name):
    sig = inspect.signature(getattr(posecrb, name))
    for p in sig.parameters.values():
        if p.name in NUMERIC:
            text = str(p.annotation)
            words = text.replace("Literal['auto']", "").replace("Literal['all']", "").replace("PoseSelection", "")
            assert "str" not in words, f"{name}({p.name}: {text})"
    assert typing.get_args(typing.get_args(choices.Gains)) == () and "lazy" not in sig.parameters


@pytest.mark.parametrize("call, keywords, says", [
    ("crlb", {"poses": "0,5,10-12"}, "poses='0,5,10-12' is text: pass True (or 'all') or a sequence of pose ids"),
    ("select", {"budget": "20%"}, "budget='20%' is text"),
    ("select", {"budget": 2, "lazy": True}, "lazy=True: is no longer a keyword of select(): use gains="),
    ("select", {"budget": 2, "jl": True}, "jl=True: is no longer a keyword"),
    ("select", {"budget": 2, "exact": True}, "exact=True: is no longer a keyword"),
    ("select", {"budget": 2, "out": "x.g2o"}, "out='x.g2o': is no longer a keyword of select(): write the pruned "
                                              "graph with posecrb.io.write_g2o(res.pruned_graph(graph), path)"),
    ("solve", {"out": "x.g2o"}, "is no longer a keyword of solve(): write the estimate with posecrb.io.write_g2o"),
    ("fim", {"save": "x.npz"}, "save='x.npz': is no longer a keyword of fim(): write the result with res.save(path)"),
    ("timeline", {"plot": "x.png"}, "is no longer a keyword of timeline(): draw the figure with "
                                    "posecrb.report.plot_timeline(res, path)"),
    ("bounds", {"repeats": 3}, "repeats=3 is not a keyword of bounds() (see help(posecrb.bounds))"),
])
def test_command_line_spellings_and_removed_keywords_say_what_to_pass(call, keywords, says):
    graph = posecrb.parse("EDGE_SE2 0 1 1 0 0 100 0 0 100 0 1000\nEDGE_SE2 1 2 1 0 0 100 0 0 100 0 1000\n"
                          "EDGE_SE2 2 0 -2 0 0 100 0 0 100 0 1000\n")
    with pytest.raises(posecrb.ArgumentError) as info:
        getattr(posecrb, call)(graph, **keywords)
    assert says in str(info.value)


def test_every_choice_is_a_literal_with_its_tuple():
    for name, value in vars(choices).items():
        if name.isupper() and isinstance(value, tuple):
            assert value and all(isinstance(v, str) for v in value), name
    literals = {n: v for n, v in vars(choices).items() if typing.get_origin(v) is typing.Literal}
    tuples = {v for n, v in vars(choices).items() if n.isupper() and isinstance(v, tuple)}
    assert {typing.get_args(v) for v in literals.values()} <= tuples
    source = inspect.getsource(choices)
    assert [line for line in source.splitlines() if line.startswith(("import ", "from "))] == \
        ["from __future__ import annotations", "from typing import Literal, get_args"]
