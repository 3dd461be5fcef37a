# dtwin — two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
export JAX_ENABLE_X64 := 1
export MPLBACKEND := Agg
# Persistent JAX compilation cache lives inside the venv (see dtwin/_config.py).
export DTWIN_JAX_CACHE := $(abspath $(VENV))/jax-cache

.PHONY: venv demo test test-all lint bench notebooks clean

$(STAMP): pyproject.toml
	test -d $(VENV) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e ".[test]"
	touch $(STAMP)

venv: $(STAMP)

lint: $(STAMP)
	$(VENV)/bin/ruff check dtwin identify tests benchmarks data

test: lint
	$(VENV)/bin/pytest -q -m "not slow" -n 2 --dist loadgroup

test-all: lint
	$(VENV)/bin/pytest -q -n 2 --dist loadgroup

demo: $(STAMP)
	$(PY) -m dtwin.identify.demo --out demo-output

bench: $(STAMP)
	$(PY) benchmarks/run_all.py

notebooks: $(STAMP)
	$(PY) notebooks/render.py notebooks demo-output/notebooks

clean:
	rm -rf $(VENV) demo-output .pytest_cache
