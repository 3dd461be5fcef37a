"""The notebooks run unattended: each is executed top to bottom with nbclient and fails on any error.

Kernel: ``dtwin``, this interpreter (the venv's python), installed into ``sys.prefix`` by
``ensure_kernel`` of ``notebooks/render.py`` on first use, so a fresh clone needs only
``make test``. ``MPLBACKEND=Agg``; short records by default (each notebook's ``FULL = False``).
The notebooks are stored without outputs (checked here too), and ``notebooks/_build.py``, which
writes them, reproduces them exactly. Notebooks run one after another on one xdist worker.

01 and 04 run in ``make test`` in their short form; 02 and 03 (the two longest, 211 s and
307 s of a fresh 2-core run's pytest time) run in ``make test-all`` (``SLOW``): what they show is
tested in ``make test`` by the drive comparison's and identification's own tests. Measured here, 2-core CPU
shared with other jobs (never quiet; warm JAX compilation cache in ``.venv/jax-cache``), each
notebook alone in ``pytest -n 0``, 2026-11-22:

- 03_identification: 248 s at load average 2–4 (06:42, code at 95bfd05), 302 s at load 4–8 (0.5 s of the bundled record, 4 free
  parameters, 1 start, 5 LM steps; series of 3 × 0.4 s records, severity free). Earlier runs
  of the same form: 573 s and 739 s at load 9–15 (the latter compiling after a change in
  dtwin/simulation/simulate.py). The fits through the ODE solve dominate (main fit about half).
- 04_what_is_missing: 35 s at load average 2–4 (06:42, code at 95bfd05), 89 s at load 9–11 (2 s record, one step, 3 candidates refit, 200
  bootstrap draws); 164 s and 252 s in earlier runs at load 7 and 14, before the faster
  simulate.
- 01 and 02: about 1–3 minutes each (not re-measured for this change).

Quiet-machine times were not measurable: expect them shorter. `FULL = True` runs are not timed.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

NOTEBOOKS = Path(__file__).resolve().parent.parent / "notebooks"

#: Notebooks whose subject does not exist yet, with the reason (skipped, not failed).
SKIP: dict[str, str] = {}

#: Notebooks too slow for `make test` even with FULL = False (marked slow, run by
#: `make test-all`), with what tests their subject in `make test`.
SLOW: dict[str, str] = {
    "02_the_motor.ipynb": "the drive comparison: tests/test_coupling.py, tests/test_motor*.py",
    "03_identification.ipynb": "identification: tests/test_identify_fit.py, "
                               "tests/test_one_fault_depth.py",
}



def _paths() -> list[Path]:
    return sorted(p for p in NOTEBOOKS.glob("*.ipynb") if not p.name.startswith("_"))


def _params():
    out = []
    for p in _paths():
        marks = [pytest.mark.skip(reason=SKIP[p.name])] if p.name in SKIP else []
        if p.name in SLOW:
            marks.append(pytest.mark.slow)
        out.append(pytest.param(p, id=p.stem, marks=marks))
    return out


def test_the_four_notebooks_exist():
    names = {p.name for p in _paths()}
    for n in ("01_the_twin", "02_the_motor", "03_identification", "04_what_is_missing"):
        assert f"{n}.ipynb" in names


@pytest.mark.parametrize("path", _paths(), ids=lambda p: p.stem)
def test_notebook_is_stored_without_outputs_and_has_parameters(path):
    nb = json.loads(path.read_text(encoding="utf-8"))
    code = [c for c in nb["cells"] if c["cell_type"] == "code"]
    for c in code:
        assert c.get("outputs", []) == [] and c.get("execution_count") is None, (
            f"{path.name}: strip outputs (rewrite with notebooks/_build.py)")
    if path.name not in SKIP:
        tagged = [c for c in code if "parameters" in c.get("metadata", {}).get("tags", [])]
        assert len(tagged) == 1 and "FULL = False" in "".join(tagged[0]["source"])


def test_build_script_reproduces_the_stored_notebooks(tmp_path):
    """`notebooks/_build.py` is the source: what it writes is what is stored."""
    subprocess.run([sys.executable, str(NOTEBOOKS / "_build.py"), str(tmp_path)], check=True,
                   capture_output=True)
    built = {p.name: p.read_bytes() for p in tmp_path.glob("*.ipynb")}
    stored = {p.name: p.read_bytes() for p in NOTEBOOKS.glob("*.ipynb")}
    assert set(built) == set(stored)
    changed = [n for n in built if built[n] != stored[n]]
    assert not changed, f"rerun notebooks/_build.py: the stored notebooks differ: {changed}"


def _render():
    """``notebooks/render.py`` (a script beside the notebooks, not part of the package)."""
    import importlib.util

    if "notebooks_render" not in sys.modules:
        spec = importlib.util.spec_from_file_location("notebooks_render", NOTEBOOKS / "render.py")
        mod = importlib.util.module_from_spec(spec)
        sys.modules["notebooks_render"] = mod
        spec.loader.exec_module(mod)
    return sys.modules["notebooks_render"]



@pytest.mark.parametrize("path", _params())
def test_notebook_runs_without_error(path):
    execute_notebook = _render().execute_notebook

    os.environ["MPLBACKEND"] = "Agg"
    nb, err = execute_notebook(path)
    if err is not None:
        pytest.fail(f"{path.name} failed:\n{str(err)[-4000:]}", pytrace=False)
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if o.get("output_type") == "error"]
    assert not errors
    figures = sum(1 for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
                  if "image/png" in o.get("data", {}))
    assert figures >= 1, f"{path.name} drew no figure"


def test_fit_figures_have_titles_axis_units_and_legends():
    """The fit figures the notebooks (and `dtwin identify`/`severity`) show: titled, axes with
    units, a legend (issue 9, requirement 4)."""
    import numpy as np

    from dtwin.identify.plotting.fit import plot_loss_history, plot_trajectories

    fig = plot_trajectories(["day 1", "day 2"], {"sun_fault": np.r_[0.1, 0.2],
                                                 "k_sun_planet": np.r_[2e8, 2e8]},
                            {"sun_fault": np.r_[0.0, 0.1], "k_sun_planet": np.r_[1e8, 1e8]},
                            {"sun_fault": np.r_[0.2, 0.3], "k_sun_planet": np.r_[3e8, 3e8]},
                            truth={"sun_fault": [0.1, 0.2]})
    top, bottom = fig.axes
    assert top.get_title() and top.get_legend() is not None
    assert "(dimensionless)" in top.get_ylabel() and "(N/m)" in bottom.get_ylabel()
    assert bottom.get_xlabel() == "record"
    ax = plot_loss_history([3.0, 2.0, 1.5]).axes[0]
    assert ax.get_title() and ax.get_legend() is not None
    assert "(" in ax.get_xlabel() and "(" in ax.get_ylabel()
