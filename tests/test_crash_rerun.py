"""The Makefile's pytest-xdist flags survive a worker process that dies mid-test.

XLA's CPU compiler (jaxlib 0.10.2) now and then kills the process compiling a program. Each
case here runs pytest with the Makefile's own ``XDIST`` flags on a small suite in a temporary
folder, on real workers, where one test kills its process with ``os.abort()`` as XLA has done
(``Fatal Python error: Aborted``): the test must run once more, an ordinary failure must not,
and the run must end (xdist's ``loadgroup`` scheduler can hang here instead). The suites get
the project's ``tests/_xdist_crash.py`` as their conftest: without it, a worker that dies
before the controller has read the test's rerun budget is not rerun (seen under load: "1
failed, 1 passed", no rerun).
"""

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

MAKEFILE = Path(__file__).resolve().parents[1] / "Makefile"

CRASHES_ONCE = """
import os, pathlib
def test_crashes_once():
    flag = pathlib.Path(__file__).with_name("crashed-once")
    if not flag.exists():
        flag.write_text("")
        os.abort()
"""
CRASHES_ALWAYS = "import os\ndef test_crashes_always():\n    os.abort()\n"
FAILS = "def test_fails():\n    assert 1 == 2\n"
PASSES = "def test_passes():\n    assert True\n"


def _xdist_flags() -> list[str]:
    match = re.search(r"^XDIST := (.+)$", MAKEFILE.read_text(), flags=re.MULTILINE)
    assert match, "the Makefile defines XDIST, the flags of `make test` and `make test-all`"
    return shlex.split(match.group(1))


# in the workers: the rerun budget a test sends the controller never arrives (sent 2 s late from
# a thread that dies with the crashing process), the race tests/_xdist_crash.py closes
BUDGET_LOST = """
import threading
@pytest.hookimpl(trylast=True)
def pytest_configure(config):
    db = getattr(config, "failures_db", None)
    if hasattr(config, "workerinput") and db is not None:
        send = db._set
        def late(i, k, v):
            if k == "r":
                threading.Timer(2.0, send, (i, k, v)).start()
            else:
                send(i, k, v)
        db._set = late
"""


def _run(tmp_path: Path, conftest_extra: str = "", **files: str) -> tuple[int, str]:
    for name, text in files.items():
        (tmp_path / f"test_{name}.py").write_text(text)
    (tmp_path / "pytest.ini").write_text("[pytest]\n")  # not this project's settings
    # but this project's hook that keeps a crashed test's rerun budget (tests/_xdist_crash.py)
    (tmp_path / "conftest.py").write_text(
        (Path(__file__).parent / "_xdist_crash.py").read_text() + conftest_extra)
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    args = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *_xdist_flags()]
    done = subprocess.run(args, cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=120)
    return done.returncode, done.stdout.strip().splitlines()[-1]


def test_the_flags_use_a_scheduler_that_requeues_crashed_tests():
    flags = _xdist_flags()
    assert flags[flags.index("--dist") + 1] in ("load", "worksteal")
    assert flags[flags.index("--reruns") + 1] == "1"


def test_a_test_whose_worker_crashed_runs_again_and_the_run_passes(tmp_path):
    code, summary = _run(tmp_path, crash=CRASHES_ONCE, ok=PASSES, ok2=PASSES)
    assert code == 0, summary
    assert "3 passed" in summary and "1 rerun" in summary


def test_a_test_that_crashes_again_fails_the_run(tmp_path):
    code, summary = _run(tmp_path, crash=CRASHES_ALWAYS, ok=PASSES)
    assert code == 1, summary
    assert "1 failed" in summary and "1 passed" in summary and "1 rerun" in summary


def test_an_ordinary_failure_is_not_rerun(tmp_path):
    code, summary = _run(tmp_path, crash=CRASHES_ONCE, fail=FAILS, ok=PASSES)
    assert code == 1, summary
    assert "1 failed" in summary and "2 passed" in summary and "1 rerun" in summary


def test_a_crash_before_the_controller_has_the_rerun_budget_is_rerun(tmp_path):
    code, summary = _run(tmp_path, BUDGET_LOST, crash=CRASHES_ONCE, ok=PASSES)
    assert code == 0, summary
    assert "2 passed" in summary and "1 rerun" in summary
