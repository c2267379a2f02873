"""The timing protocol (posecrb.core.timing), on a fake clock: each call of the timed function
advances it by a known duration, so the number of runs is exact, never a property of this machine."""
from __future__ import annotations

import json

import pytest

from posecrb.cli import main
from posecrb.core import timing
from posecrb.core.errors import UsageError
from posecrb.core.timing import AUTO_BUDGET, AUTO_MAX_RUNS, AUTO_SINGLE_PASS, auto_runs, measure


class FakeClock:
    def __init__(self, durations):
        self.now = 0.0
        self.durations = list(durations)
        self.calls = 0

    def perf_counter(self):
        return self.now

    def work(self):
        d = self.durations[min(self.calls, len(self.durations) - 1)]
        self.calls += 1
        self.now += d
        return self.calls


@pytest.fixture
def clock(monkeypatch):
    def make(*durations):
        c = FakeClock(durations)
        monkeypatch.setattr(timing.time, "perf_counter", c.perf_counter)
        return c
    return make


@pytest.mark.parametrize("seconds", [AUTO_SINGLE_PASS, 1.5, 30.0])
def test_auto_long_pass_runs_once(clock, seconds):
    c = clock(seconds)
    t = measure(c.work, "auto")
    assert (t.runs, t.warmup, c.calls, t.seconds, t.value) == (1, False, 1, seconds, 1)


@pytest.mark.parametrize("seconds", [1e-6, 0.01, 0.3, 0.45, 0.5, 0.7, 0.99])
def test_auto_short_pass_warms_up_and_fits_budget(clock, seconds):
    c = clock(seconds)
    t = measure(c.work, "auto")
    assert t.warmup and t.runs == auto_runs(seconds) and c.calls == t.runs + 1
    assert 1 <= t.runs <= AUTO_MAX_RUNS
    # the timed runs and the warm-up fit in the budget, unless one run is all there is
    assert t.runs == 1 or (t.runs + 1) * seconds <= AUTO_BUDGET + 1e-12
    # and one more would not have fitted, unless the cap stopped it
    assert t.runs == AUTO_MAX_RUNS or (t.runs + 2) * seconds > AUTO_BUDGET
    assert t.seconds == pytest.approx(seconds)


def test_auto_warmup_is_excluded(clock):
    c = clock(0.9, 0.1)          # a slow first call (cache, compilation), then steady
    t = measure(c.work, "auto")
    assert t.warmup and t.seconds == pytest.approx(0.1) and t.runs == AUTO_MAX_RUNS


def test_auto_median(clock):
    c = clock(0.2, 0.3, 0.1, 0.5, 0.2, 0.2)
    t = measure(c.work, "auto")
    assert t.runs == 5 and t.seconds == pytest.approx(0.2) and t.value == 6


@pytest.mark.parametrize("k", [1, 2, 3, 7])
def test_explicit_repeat_keeps_its_meaning(clock, k):
    c = clock(5.0)              # even a long pass is repeated when asked
    t = measure(c.work, k)
    assert t.runs == k and t.warmup == (k > 1) and c.calls == k + (k > 1)
    assert measure(clock(5.0).work, k, warmup=False).runs == k


@pytest.mark.parametrize("bad", [0, -1, 2.5, "3", "fast", None, True])
def test_bad_repeat(bad):
    with pytest.raises(UsageError):
        measure(lambda: None, bad)


def test_library_default_runs_once(clock):
    c = clock(0.001)
    assert measure(c.work).runs == 1 and c.calls == 1 and timing.timed(c.work)[0] == 2


def test_cli_repeat_option(shared_datasets, capsys):
    # auto by default; the JSON says how many runs every time is the median of
    assert main(["bounds", "CSAIL", "--data-dir", str(shared_datasets), "--format", "json"]) == 0
    row = json.loads(capsys.readouterr().out)
    row = row[0] if isinstance(row, list) else row
    assert set(row["runs"]) == set(row["times"])
    assert all(1 <= n <= AUTO_MAX_RUNS for k, n in row["runs"].items() if row["times"][k] is not None)
    # the estimate and the log-det's accuracy bound are computed once, never timed by repeats
    assert row["runs"]["solve"] == row["runs"]["logdet_accuracy"] == 1
    assert main(["bounds", "CSAIL", "--data-dir", str(shared_datasets), "--format", "json", "--repeat", "2"]) == 0
    row = json.loads(capsys.readouterr().out)
    row = row[0] if isinstance(row, list) else row
    assert all(n == 2 for k, n in row["runs"].items() if k not in ("solve", "logdet_accuracy"))
    assert row["runs"]["logdet_accuracy"] == 1
    assert main(["bounds", "CSAIL", "--repeat", "often"]) == 2
