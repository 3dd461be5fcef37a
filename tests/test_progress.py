"""Progress of the long commands on stderr, with an estimate (dtwin/cli/progress.py, issue 51
item 5): one line per stage on stderr, nothing on stdout, nothing under ``--quiet`` or
``--json``; the estimate is the last run's time from the same stage to its end."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dtwin.cli import main
from dtwin.cli import progress as progress_module

FS = 5000.0


@pytest.fixture(scope="module")
def rec(tmp_path_factory):
    """A 1 s CSV record: a 499 Hz tone (the paper-sim mesh at ~30 Hz input) in noise."""
    d = tmp_path_factory.mktemp("progress")
    t = np.arange(int(FS)) / FS
    x = np.sin(2 * np.pi * 499.0 * t) + 0.1 * np.random.default_rng(0).standard_normal(t.size)
    path = d / "rec.csv"
    np.savetxt(path, np.column_stack([t, x]), delimiter=",", header="time [s],acc [m/s^2]",
               comments="")
    return str(path)


class Stop(Exception):
    """Raised by the stand-ins once they have reported their stages."""


def _stand_in(keyword: str):
    def run(*args, **kwargs):
        say = kwargs.get(keyword)
        if say is not None:
            say("stage one of the stand-in")
            say("stage two of the stand-in")
        raise Stop

    return run


@pytest.fixture()
def stand_ins(monkeypatch, tmp_path):
    """The library's long steps replaced by stand-ins that report two stages and stop (no
    compilation); the timings of earlier runs kept in an empty folder of this test."""
    from importlib import import_module

    monkeypatch.setenv("DTWIN_JAX_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("DTWIN_DEBUG", "1")  # the stand-in's exception reaches the test
    (tmp_path / "cache").mkdir()
    for module, name, keyword in (("dtwin.identify.calibrate", "calibrate", "progress"),
                                  ("dtwin.identify.discover", "discover", "log"),
                                  ("dtwin.identify.severity", "estimate_severity", "progress")):
        monkeypatch.setattr(import_module(module), name, _stand_in(keyword))


COMMANDS = {
    "calibrate": ["calibrate", "{rec}", "--preset", "paper-sim", "--out", "{out}"],
    "discover": ["discover", "{rec}", "--preset", "paper-sim"],
    "severity": ["severity", "{rec}", "--preset", "paper-sim", "--f-sun", "30"],
}


def _run(argv, capsys):
    capsys.readouterr()
    with pytest.raises(Stop):
        main(argv)
    return capsys.readouterr()


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_progress_on_stderr_and_silent_with_quiet_or_json(command, rec, tmp_path, stand_ins,
                                                          capsys):
    argv = [a.format(rec=rec, out=str(tmp_path / "out")) for a in COMMANDS[command]]
    shown = _run(argv, capsys)
    lines = [ln for ln in shown.err.splitlines() if ln.startswith(f"{command} [")]
    assert lines and lines[0].endswith("]: starting"), shown.err
    if command != "severity":  # its library call reports no stages: the start line only
        assert [ln.split("]: ", 1)[1] for ln in lines[1:]] == ["stage one of the stand-in",
                                                               "stage two of the stand-in"]
    assert "stand-in" not in shown.out and f"{command} [" not in shown.out
    for flags in (["--quiet"], ["--json"]):
        silent = _run(flags + argv if flags == ["--quiet"] else argv + flags, capsys)
        assert f"{command} [" not in silent.err and "stand-in" not in silent.err, flags
        assert "stand-in" not in silent.out


def test_estimate_is_the_last_runs_time_from_the_same_stage():
    last = {"total": 100.0, "stages": [10.0, 40.0]}
    assert progress_module.estimate_left(None, 0, 0.0) is None  # first run: no estimate
    assert progress_module.estimate_left(last, 0, 5.0) == 95.0
    assert progress_module.estimate_left(last, 1, 12.0) == 90.0
    assert progress_module.estimate_left(last, 2, 35.0) == 60.0
    assert progress_module.estimate_left(last, 3, 70.0) == 30.0  # more stages than last time
    assert progress_module.estimate_left(last, 3, 120.0) is None  # past its end


def test_a_finished_run_gives_the_next_one_its_estimate(monkeypatch, tmp_path, capsys):
    """A run of 50 s with stages at 10 s and 30 s is kept; the next run of the same command and
    size shows 40 s left at its first stage and 20 s at its second (clock stubbed)."""
    monkeypatch.setenv("DTWIN_JAX_CACHE", str(tmp_path))
    clock = iter([0.0, 0.0, 10.0, 10.0, 30.0, 30.0, 50.0,  # first run
                  0.0, 0.0, 10.0, 10.0, 30.0, 30.0, 50.0])
    monkeypatch.setattr(progress_module.time, "perf_counter", lambda: next(clock))
    for _ in range(2):
        with progress_module.progress("calibrate", size="5000@5000") as stage:
            stage("first")
            stage("second")
    err = capsys.readouterr().err.splitlines()
    assert err[:4] == ["calibrate [   0 s]: starting", "calibrate [  10 s]: first",
                       "calibrate [  30 s]: second", "calibrate: done in 50 s"]
    assert err[4:] == ["calibrate [   0 s, about 50 s left]: starting",
                       "calibrate [  10 s, about 40 s left]: first",
                       "calibrate [  30 s, about 20 s left]: second",
                       "calibrate: done in 50 s"]
    kept = json.loads((tmp_path / "dtwin-timings.json").read_text())
    assert kept == {"calibrate|5000@5000": {"total": 50.0, "stages": [10.0, 30.0]}}
