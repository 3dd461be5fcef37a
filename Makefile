# dtwin — two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
export JAX_ENABLE_X64 := 1
export MPLBACKEND := Agg
# JAX's persistent compilation cache: the user's cache folder (~/.cache/dtwin/jax, see
# dtwin/_config.py) for the demo and every command, so a second run does not compile again;
# the tests keep theirs in the venv (TEST_JAX_CACHE), away from the user's and removed by
# `make clean`. DTWIN_JAX_CACHE=off (or a folder) given to make overrides both.
TEST_JAX_CACHE := $(abspath $(VENV))/jax-cache
test test-all: export DTWIN_JAX_CACHE ?= $(TEST_JAX_CACHE)

# Two pytest-xdist workers. XLA's CPU compiler (jaxlib 0.10.2) now and then kills the process
# compiling a program (`Fatal Python error: Aborted` or a segfault); xdist then starts a new
# worker and pytest-rerunfailures runs the test that was running once more (`--reruns 1`).
# `--only-rerun` names a message no ordinary failure has, so an ordinary failure is never rerun
# (crashed tests are rerun whatever the filter). `worksteal`, not `loadgroup`: xdist's group and
# file schedulers cannot put a crashed test back in the queue, and can hang waiting for the
# replacement worker (tests/test_crash_rerun.py runs all of this on a suite that crashes).
# tests/_xdist_crash.py (imported by tests/conftest.py) gives a crashed test its rerun budget on
# the controller, which otherwise hears it from a worker that may die before it is read.
# Up to 5 crashed tests a run are rerun: the full suite has lost one or two workers a run that
# way (two in each of three runs on 2026-11-28, inside XLA's backend_compile_and_load; each
# test passed on its rerun).
XDIST := -n 2 --dist worksteal --reruns 1 --only-rerun "pytest-xdist worker crashed" --max-suite-reruns 5

.PHONY: venv demo test test-all lint bench bench-family notebooks docs clean

$(STAMP): pyproject.toml
	test -d $(VENV) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e ".[test]"
	touch $(STAMP)

venv: $(STAMP)

lint: $(STAMP)
	$(VENV)/bin/ruff check dtwin identify tests benchmarks data

test: lint
	$(VENV)/bin/pytest -q -m "not slow" --durations=40 $(XDIST)

test-all: lint
	$(VENV)/bin/pytest -q $(XDIST)

demo: $(STAMP)
	$(PY) -m dtwin.identify.demo --out demo-output

bench: $(STAMP)
	$(PY) benchmarks/run_all.py

# The family benchmark: calibrate, discover and severity on every gearbox of
# ../shared/independent/ (benchmarks/family.py; table in benchmarks/out/family/family.md).
bench-family: $(STAMP)
	$(PY) benchmarks/family.py

notebooks: $(STAMP)
	$(PY) notebooks/render.py notebooks demo-output/notebooks

# The user's documentation and its API reference (from the docstrings) into site/.
docs: $(STAMP)
	$(VENV)/bin/mkdocs build --strict

clean:
	rm -rf $(VENV) demo-output site .pytest_cache
