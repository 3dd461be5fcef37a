"""A crashed test's rerun budget, set on the controller (pytest-xdist + pytest-rerunfailures).

pytest-rerunfailures learns how often a test may run again from the worker that runs it: when
the test starts, the worker sends the budget to the controller over a socket, without waiting
for an answer. A worker that dies at once (XLA's compiler aborting the process) can die before
the controller has read that message; the controller then finds a budget of 0 and reports the
crash as a failure instead of running the test again — seen under load in
``tests/test_crash_rerun.py``. This hook, run before rerunfailures' own, gives the crashed
test the run's ``--reruns`` budget on the controller when the message has not arrived. It is
imported by ``tests/conftest.py`` and copied into the small suites of
``tests/test_crash_rerun.py`` (which check it together with the Makefile's flags).
"""

import pytest


@pytest.hookimpl(tryfirst=True, optionalhook=True)
def pytest_handlecrashitem(crashitem, report, sched):
    db = getattr(sched.config, "failures_db", None)
    reruns = sched.config.getoption("reruns", None)
    if db is not None and reruns and db.get_test_reruns(crashitem) < reruns:
        db.set_test_reruns(crashitem, reruns)
