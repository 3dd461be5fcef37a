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

# Two pytest-xdist workers, no reruns: a failure is a failure. The XLA compiler crashes that
# once killed a worker now and then were the process running out of memory mappings
# (vm.max_map_count); dtwin/_maps.py clears JAX's caches before that happens.
XDIST := -n 2 --dist worksteal

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
