"""The README's tour runs as written (issue #54).

The tour is the fenced ``bash``/``sh`` blocks between ``<!-- tour`` and ``<!-- end of tour -->``
in README.md. They run in order, verbatim, under ``bash -e`` in a temporary folder holding a
copy of ``data/samples`` and a ``.venv`` link to the repository's environment, so ``source
.venv/bin/activate`` works as a newcomer types it. In CI the commands that take minutes
(:data:`SLOW_COMMANDS`) are left out and listed; the ``slow`` test runs every one. A second test
checks that every ``--option`` the README shows for a command is in that command's ``--help``.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
TOUR_START, TOUR_END = "<!-- tour", "<!-- end of tour -->"

#: Tour commands that take minutes on a 2-core machine (calibration, discovery, severity, the
#: fleet's fits and what reads their results): left out of the CI form, run by the slow test.
SLOW_COMMANDS = ("dtwin calibrate", "dtwin discover", "dtwin severity", "dtwin fleet")

#: Commands with sub-commands: their command path is two words (``dtwin fleet identify``).
GROUPS = ("fleet", "record", "spec")


def _blocks(text: str) -> list[str]:
    """The fenced ``bash``/``sh`` blocks of `text`, in order."""
    return [m.group(2) for m in re.finditer(r"^```(bash|sh)\n(.*?)^```", text, re.M | re.S)]


def tour_commands(text: str | None = None) -> list[str]:
    """The tour's command lines, in order (comments and blank lines dropped)."""
    text = README.read_text() if text is None else text
    start, end = text.find(TOUR_START), text.find(TOUR_END)
    assert 0 <= start < end, f"README.md has no tour ({TOUR_START} … {TOUR_END})"
    return [ln.strip() for b in _blocks(text[start:end]) for ln in b.splitlines()
            if ln.strip() and not ln.strip().startswith("#")]


def readme_dtwin_commands() -> list[list[str]]:
    """Every ``dtwin …`` line of the README's code blocks, as tokens (comments cut)."""
    out = []
    for b in _blocks(README.read_text()):
        for ln in b.splitlines():
            ln = ln.split(" #")[0].strip()
            if ln.startswith("dtwin "):
                out.append(shlex.split(ln))
    return out


def _run_tour(tmp_path: Path, skip: tuple[str, ...]) -> tuple[subprocess.CompletedProcess,
                                                               list[str]]:
    """Run the tour in a copy of the needed files; returns the process and the skipped lines."""
    if not (ROOT / ".venv" / "bin" / "activate").is_file():
        pytest.skip("no .venv in the repository (the README's set-up, `make`, makes it)")
    commands = tour_commands()
    run = [c for c in commands if not c.startswith(skip)]
    skipped = [c for c in commands if c.startswith(skip)]
    shutil.copytree(ROOT / "data" / "samples", tmp_path / "data" / "samples")
    (tmp_path / ".venv").symlink_to(ROOT / ".venv", target_is_directory=True)
    script = ("trap 'echo \"README tour: this command failed: $BASH_COMMAND\" >&2' ERR\n"
              + "\n".join(run) + "\n")
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONPATH")}
    env["PATH"] = "/usr/local/bin:/usr/bin:/bin"  # the shell of a newcomer: no venv yet
    env.setdefault("MPLBACKEND", "Agg")
    proc = subprocess.run(["bash", "-e", "-c", script], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=3600)
    return proc, skipped


def test_tour_has_the_workflow():
    """The tour activates the venv first and runs the workflow on shipped files only."""
    commands = tour_commands()
    assert commands[0] == "source .venv/bin/activate"
    for step in ("dtwin calibrate", "dtwin discover", "dtwin severity", "dtwin fleet identify"):
        assert any(c.startswith(step) for c in commands), step
    for c in commands:
        for tok in shlex.split(c):
            if tok.startswith("data/"):
                assert (ROOT / tok).is_file(), f"the README's tour uses {tok}, which is not shipped"


def test_readme_options_exist_in_help():
    """Each ``--option`` the README shows for a command is listed by ``dtwin CMD --help``."""
    from typer.testing import CliRunner

    from dtwin.cli import _load_commands, app

    _load_commands()
    runner = CliRunner()
    helps: dict[tuple[str, ...], str] = {}
    commands = readme_dtwin_commands()
    assert commands, "the README shows no dtwin command"
    for tokens in commands:
        words = [t for t in tokens[1:] if not t.startswith("-")]
        path = tuple(words[:2] if words and words[0] in GROUPS else words[:1])
        if path not in helps:
            res = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "250"},
                                terminal_width=250)
            assert res.exit_code == 0, f"dtwin {' '.join(path)} --help: {res.output}"
            helps[path] = res.output
        listed = set(re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", helps[path]))
        shown = {t.split("=")[0] for t in tokens if t.startswith("--")}
        missing = shown - listed
        assert not missing, (f"README: dtwin {' '.join(path)} shows {sorted(missing)}, which "
                             f"its --help does not list")


def test_readme_tour_quick(tmp_path):
    """CI form: the tour without the commands that take minutes (:data:`SLOW_COMMANDS`)."""
    proc, skipped = _run_tour(tmp_path, SLOW_COMMANDS)
    assert proc.returncode == 0, proc.stderr[-3000:]
    print("left out of the CI form (run by the slow test):\n  " + "\n  ".join(skipped))
    assert skipped and all(c.startswith(SLOW_COMMANDS) for c in skipped)
    # what the quick commands promise: the spectrum's report and its HDF5 export
    assert (tmp_path / "tour" / "spectrum" / "report.html").stat().st_size > 10_000
    import h5py

    with h5py.File(tmp_path / "tour" / "spectrum.h5") as f:
        assert f["spectrum/frequency"].attrs["unit"] == "Hz"
        assert f["spectrum/amplitude"].shape == f["spectrum/frequency"].shape
    # the bundled records were read, never written
    for p in (ROOT / "data" / "samples").glob("*.dtwin.h5"):
        assert (tmp_path / "data" / "samples" / p.name).read_bytes() == p.read_bytes()


@pytest.mark.slow
def test_readme_tour_full(tmp_path):
    """Every command of the tour, as written (calibration, discovery, severity, the fleet)."""
    proc, skipped = _run_tour(tmp_path, ())
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert not skipped
    tour = tmp_path / "tour"
    assert (tour / "cal" / "calibrated.toml").is_file()
    disc = json.loads((tour / "discover" / "discover.json").read_text())
    # the README says discover names the sun fault
    assert any("sun" in s["effect"] or "sun" in s["named"] for s in disc["steps"]), disc["steps"]
    assert "Candidates judged in each step" in (tour / "discover" / "report.html").read_text()
    sev = json.loads((tour / "severity" / "severity.json").read_text())
    lo, hi = sev["interval_95"]  # the severity with its interval, as the README says
    assert 0.0 <= lo <= sev["severity"] <= hi <= 1.0
    assert any(p.suffix == ".csv" for p in (tour / "fleet").iterdir())


def test_readme_links_point_at_shipped_files():
    """Every relative link of the README names a file of the repository."""
    links = re.findall(r"\]\(([^)#:]+)\)", README.read_text())
    assert links, "the README links into docs/"
    missing = [p for p in links if not (ROOT / p).exists()]
    assert not missing, f"README links to files that do not exist: {missing}"
