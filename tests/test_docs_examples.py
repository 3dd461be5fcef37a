"""Every Python example of the guides runs as written (issue #54 item 2).

The examples are the fenced ``python`` blocks of ``docs/*.md``. Each runs verbatim in a fresh
interpreter (``python -c``) from the repository root, so that it reads the bundled records of
``data/samples`` and the presets as a reader who copies it does; ``TMPDIR`` points at the test's
own folder, where the examples write their files (``tempfile.mkdtemp()``), and a block that
leaves a new file in the repository fails. A block whose fence follows the line
``<!-- example: slow -->`` takes minutes (a fit, discovery, a fleet run, the drive comparison:
XLA compiles a forward-mode fit for over a minute on a 2-core machine) and is marked ``slow``.
Tests are named by page and block number, from 1 (``records.md-1``).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
SLOW = "<!-- example: slow -->"
_BLOCK = re.compile(r"^(?:(" + re.escape(SLOW) + r")\n)?```python\n(.*?)^```", re.M | re.S)

#: Seconds a block may run: the quick ones take under a minute, the slow ones a few.
TIMEOUT_S = {False: 600, True: 1800}


def doc_examples(docs: Path = DOCS) -> list[tuple[str, int, str, bool]]:
    """``(page, block number from 1, code, slow)`` of every ``python`` block of `docs`."""
    return [(page.name, i, m.group(2), m.group(1) is not None)
            for page in sorted(docs.glob("*.md"))
            for i, m in enumerate(_BLOCK.finditer(page.read_text()), start=1)]


EXAMPLES = doc_examples()


def _untracked() -> set[str]:
    """Files of the repository that git does not track and does not ignore (empty outside a
    git checkout)."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        return set()
    proc = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all"], cwd=ROOT,
                          capture_output=True, text=True)
    return {ln[3:] for ln in proc.stdout.splitlines() if ln.startswith("??")}


def test_docs_hold_python_examples():
    """The collector finds the guides' examples, and every slow marker stands directly before a
    ``python`` fence (a misplaced one would leave its block in the quick run)."""
    assert EXAMPLES, "docs/*.md hold no ```python block: the collector found nothing to run"
    for page in sorted(DOCS.glob("*.md")):
        text = page.read_text()
        marked = sum(m.group(1) is not None for m in _BLOCK.finditer(text))
        assert text.count(SLOW) == marked, (f"docs/{page.name}: `{SLOW}` must be the line "
                                            "directly before a ```python fence")


@pytest.mark.parametrize(
    ("code", "slow"),
    [pytest.param(code, slow, id=f"{page}-{i}", marks=[pytest.mark.slow] if slow else [])
     for page, i, code, slow in EXAMPLES])
def test_doc_example_runs(code, slow, tmp_path):
    """The block runs without error from the repository root and writes nothing there."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(JAX_ENABLE_X64="1", MPLBACKEND="Agg", TMPDIR=str(tmp_path))
    before = _untracked()
    try:
        proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env,
                              capture_output=True, text=True, timeout=TIMEOUT_S[slow])
    except subprocess.TimeoutExpired:
        pytest.fail(f"the example ran past {TIMEOUT_S[slow]} s:\n{code}")
    assert proc.returncode == 0, f"the example failed:\n{code}\n{proc.stderr[-4000:]}"
    new = sorted(_untracked() - before)
    assert not new, f"the example wrote into the repository: {new}\n{code}"
