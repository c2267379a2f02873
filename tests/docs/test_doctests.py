"""The Examples of every public name's docstring (``posecrb.__all__``) run and give what they show.

They use the real ``intel`` dataset (``$POSECRB_DATA``), as a reader of the documentation would."""
from __future__ import annotations

import doctest

import pytest

import posecrb

NAMES = [n for n in posecrb.__all__ if n != "__version__"]
FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


def _run(obj, name: str) -> None:
    finder = doctest.DocTestFinder(recurse=True)
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    tests = [t for t in finder.find(obj, name, globs={}) if t.examples]
    assert tests, f"{name}: no examples"
    for t in tests:
        runner.run(t)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{name}: {result.failed} example(s) failed (see the output above)"


@pytest.mark.parametrize("name", NAMES)
def test_public_docstring_examples(name, shared_datasets, monkeypatch):
    monkeypatch.setenv("POSECRB_DATA", str(shared_datasets))
    _run(getattr(posecrb, name), f"posecrb.{name}")


def test_package_docstring_example(shared_datasets, monkeypatch):
    monkeypatch.setenv("POSECRB_DATA", str(shared_datasets))
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    for t in doctest.DocTestFinder(recurse=False).find(posecrb, "posecrb", globs={}):
        runner.run(t)
    assert runner.summarize(verbose=False).failed == 0
