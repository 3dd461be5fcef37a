"""The bad-input battery's CI subset (benchmarks/bad_input_battery.py, issue 53): a handful of
cases, each a `python -m dtwin` process with a 30 s timeout, inputs checksummed before and
after. The full battery is the script (`python benchmarks/bad_input_battery.py`)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "bad_input_battery.py"


@pytest.fixture(scope="module")
def battery():
    spec = importlib.util.spec_from_file_location("bad_input_battery", _PATH)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["bad_input_battery"] = mod  # dataclasses look their module up there
    spec.loader.exec_module(mod)
    return mod


def test_battery_ci_cases(battery, tmp_path):
    cases = [c for c in battery.cases() if c.name in battery.CI_CASES]
    assert sorted(c.name for c in cases) == sorted(battery.CI_CASES)
    results = battery.run(cases, tmp_path, timeout=30.0, log=lambda line: None)
    assert all(r.ok for r in results), battery.summary(results)
    # what the cases stand for: bad input refused (2), the interrupt 130, within the timeout
    codes = {r.name: r.code for r in results}
    assert codes.pop("freqs.interrupt-import") == 130
    assert set(codes.values()) == {2}
    assert all(r.seconds < 30.0 for r in results)


def test_battery_reports_a_changed_input_and_a_hang(battery, tmp_path):
    """The battery's own checks: a case whose input changes, and one that outlives the
    timeout, are failures with their reason (`dtwin record convert --force` onto a file the
    case lists as an input; `dtwin simulate` of a 60 s record with a 3 s timeout)."""
    battery.make_inputs(tmp_path)
    (tmp_path / "victim.dtwin.h5").write_bytes(b"old")
    changed = battery.Case("x.changed", ("record", "convert", "{w}/good.csv",
                                         "{w}/victim.dtwin.h5", "--force"),
                           ("victim.dtwin.h5",), (0,))
    r = battery.run_case(changed, tmp_path, timeout=60.0)
    assert not r.ok and r.reason == "input changed: victim.dtwin.h5", r
    hang = battery.Case("x.hang", ("simulate", "--preset", "paper-bench", "--duration", "60"),
                        (), (0,))
    r = battery.run_case(hang, tmp_path, timeout=3.0)
    assert not r.ok and r.reason.startswith("hang: still running after 3 s"), r


def test_battery_table_covers_each_kind_of_bad_input(battery):
    """The issue's table: every case falls in one of the eight kinds (missing, empty,
    truncated, wrong format, wrong rate, huge, contradicting, interrupt); every command that
    reads a record has a case of each, every command an interrupt; a failed cell is bold."""
    cases = battery.cases()
    kinds = {c.name: battery.kind_of(c.name) for c in cases}
    assert set(kinds.values()) == set(battery.KINDS), {k for k in kinds.values()}
    cells = {}
    for name, kind in kinds.items():
        cells.setdefault(name.split(".", 1)[0], set()).add(kind)
    for cmd in ("record-info", "spectrum", "view", "severity", "identify", "calibrate",
                "discover"):
        assert cells[cmd] == set(battery.KINDS), (cmd, set(battery.KINDS) - cells[cmd])
    for cmd in ("record-convert", "spec-check", "freqs", "modes", "stiffness", "simulate",
                "compare-drives", "fleet-identify"):
        assert "interrupt" in cells[cmd], cmd
    results = [battery.Result(c.name, True, "ok", 2, 1.0, "") for c in cases]
    results[0] = battery.Result(results[0].name, False, "traceback on stderr", 1, 1.0, "")
    table = battery.matrix(results).splitlines()
    assert table[0].startswith("| command | missing | empty | truncated | wrong format |")
    first = cases[0].name.split(".", 1)[0]
    assert any(line.startswith(f"| {first} |") and "**" in line for line in table)


def test_battery_interrupt_case_that_ends_first_is_a_failure(battery, tmp_path):
    """An interrupt case whose command ends before its SIGINT is due did not test the
    interrupt: a failure with that reason, not an ok."""
    battery.make_inputs(tmp_path)
    case = battery.Case("x.interrupt", ("--version",), (), (130,), 60.0)
    r = battery.run_case(case, tmp_path, timeout=90.0)
    assert not r.ok and r.reason.startswith("ended (exit 0) before the interrupt at 60 s"), r
