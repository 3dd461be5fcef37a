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
import sys
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


def readme_dtwin_commands(path: Path = README) -> list[list[str]]:
    """Every ``dtwin …`` command of a Markdown page (the README by default), as tokens: the
    lines of its ``bash``/``sh`` blocks (comments cut) and its inline code spans (```dtwin
    spectrum … --export FILE```); placeholders (``dtwin COMMAND --help``, ``dtwin ...``) are
    left out."""
    text = path.read_text()
    lines = [ln.split(" #")[0].strip() for b in _blocks(text) for ln in b.splitlines()]
    lines += re.findall(r"(?<!`)`(dtwin [^`\n]+)`", text)
    out = []
    for ln in lines:
        if not ln.startswith("dtwin ") or "..." in ln or "…" in ln:
            continue
        tokens = shlex.split(ln)
        words = [t for t in tokens[1:] if not t.startswith("-")]
        if words and words[0].isupper():  # dtwin COMMAND --help
            continue
        out.append(tokens)
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


def _warnings(stderr: str) -> list[str]:
    """The lines of `stderr` that warn: dtwin's ``warning:`` lines and any other package's
    (Python's ``…Warning:``, JAX's ``os.fork()``, Ray's token note); a bundled record run as the
    README says has nothing to warn about."""
    return [ln for ln in stderr.splitlines()
            if re.search(r"warning:|Warning\b|os\.fork|token", ln, re.IGNORECASE)]


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


#: The pages whose ``dtwin`` commands are checked against ``--help``: the README and the
#: user's guides.
PAGES = (README, *sorted((ROOT / "docs").glob("*.md")))


def test_readme_options_exist_in_help():
    """Each command the README and the guides of ``docs/`` show (code blocks and inline code)
    exists, and each ``--option`` it shows is listed by that command's ``--help``."""
    from typer.testing import CliRunner

    from dtwin.cli import _load_commands, app

    _load_commands()
    runner = CliRunner()
    helps: dict[tuple[str, ...], str] = {}
    assert readme_dtwin_commands(), "the README shows no dtwin command"
    for page in PAGES:
        name = page.relative_to(ROOT)
        for tokens in readme_dtwin_commands(page):
            words = [t for t in tokens[1:] if not t.startswith("-")]
            path = tuple(words[:2] if words and words[0] in GROUPS else words[:1])
            if path not in helps:
                res = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "250"},
                                    terminal_width=250)
                assert res.exit_code == 0, (f"{name}: `{shlex.join(tokens)}`: dtwin "
                                            f"{' '.join(path)} --help: {res.output}")
                helps[path] = res.output
            listed = set(re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", helps[path]))
            shown = {t.split("=")[0] for t in tokens if t.startswith("--")}
            missing = shown - listed
            assert not missing, (f"{name}: dtwin {' '.join(path)} shows {sorted(missing)}, "
                                 f"which its --help does not list")


def test_group_help_names_only_its_sub_commands():
    """A command group's one-line help ends by listing the sub-commands it has, and no other
    (``dtwin record --help`` once offered a ``check`` that did not exist)."""
    import typer.main

    from dtwin.cli import _load_commands, app

    _load_commands()
    group = typer.main.get_group(app)
    for name in GROUPS:
        sub = group.commands[name]
        listed = sub.help.splitlines()[0].rsplit("): ", 1)[-1].rstrip(".")
        words = {w.strip() for w in listed.split(",")}
        assert words == set(sub.commands), (f"dtwin {name}: its help lists {sorted(words)}, "
                                            f"it has {sorted(sub.commands)}")


def test_readme_python_runs(tmp_path):
    """The README's Python blocks run as written, in a fresh interpreter."""
    blocks = re.findall(r"^```python\n(.*?)^```", README.read_text(), re.M | re.S)
    assert blocks, "the README shows no Python"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.setdefault("MPLBACKEND", "Agg")
    for code in blocks:
        proc = subprocess.run([sys.executable, "-c", code],
                              cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=1200)
        assert proc.returncode == 0, f"README's Python:\n{code}\n{proc.stderr[-3000:]}"


def test_readme_tour_quick(tmp_path):
    """CI form: the tour without the commands that take minutes (:data:`SLOW_COMMANDS`)."""
    proc, skipped = _run_tour(tmp_path, SLOW_COMMANDS)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert not _warnings(proc.stderr), proc.stderr[-3000:]
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
    assert not _warnings(proc.stderr), proc.stderr[-3000:]
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
