"""The project installs from a wheel, not only as an editable checkout.

A wheel is built from the repository, installed into a fresh virtual environment (its
dependencies are borrowed from the test environment through a ``.pth`` line, so no network is
needed), and used from a folder outside the checkout: the console script answers
``dtwin freqs --preset paper-sim`` (the presets ship inside the package) and the identification
package imports as ``dtwin.identify`` (the top-level name ``identify`` belongs to another
distribution on PyPI and must stay free).
"""

from __future__ import annotations

import json
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _declared_packages() -> set[str]:
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    return set(cfg["packages"])


def _source_packages() -> set[str]:
    """Every folder holding an ``__init__.py`` under dtwin/ and identify/, as import names."""
    out = set()
    for init in (ROOT / "dtwin").rglob("__init__.py"):
        out.add(".".join(init.parent.relative_to(ROOT).parts))
    for init in (ROOT / "identify").rglob("__init__.py"):
        out.add(".".join(("dtwin",) + init.parent.relative_to(ROOT).parts))
    return {p for p in out if "__pycache__" not in p}


def test_every_package_is_declared():
    """pyproject lists packages explicitly (identify/ is mapped to dtwin.identify): a new
    sub-package that is not listed would be missing from the wheel."""
    assert _source_packages() == _declared_packages()


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
         "-w", str(out), str(ROOT)],
        check=True, capture_output=True, text=True,
    )
    (whl,) = out.glob("dtwin-*.whl")
    return whl


def test_wheel_contents(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    assert "dtwin/spec/presets/paper-sim.toml" in names
    assert "dtwin/identify/fit.py" in names
    assert "dtwin/identify/discover/effects/base.py" in names
    assert not [n for n in names if n.startswith("identify/")], "identify must not be top-level"


def test_wheel_installs_and_runs(wheel, tmp_path):
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    py = venv / "bin" / "python"
    site = subprocess.run(
        [str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True, capture_output=True, text=True,
    ).stdout.strip()
    # the dependencies (jax, diffrax, ...) come from the test environment's site-packages; a
    # path listed in a .pth is not a site dir, so the editable install's finder there is inert.
    (Path(site) / "_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(py), "install", "--no-deps", "-q",
         str(wheel)],
        check=True, capture_output=True, text=True,
    )
    work = tmp_path / "elsewhere"
    work.mkdir()
    env = {"PATH": f"{venv / 'bin'}:/usr/bin:/bin", "HOME": str(tmp_path), "MPLBACKEND": "Agg"}
    freqs = subprocess.run(
        [str(venv / "bin" / "dtwin"), "freqs", "--preset", "paper-sim", "--json"],
        cwd=work, env=env, capture_output=True, text=True, timeout=300,
    )
    assert freqs.returncode == 0, freqs.stderr
    got = json.loads(freqs.stdout)
    text = json.dumps(got)
    assert "500" in text  # f_mesh of the paper's simulation gearbox, 500.3 Hz (Table 2)
    probe = (
        "import dtwin, dtwin.identify, dtwin.identify.fit;"
        "print(dtwin.__file__); print(dtwin.identify.__file__); print(dtwin.__version__)"
    )
    imp = subprocess.run([str(py), "-c", probe], cwd=work, env=env, capture_output=True,
                         text=True, timeout=300)
    assert imp.returncode == 0, imp.stderr
    dtwin_file, ident_file, version = imp.stdout.split("\n")[:3]
    assert dtwin_file.startswith(str(venv)), "dtwin must come from the installed wheel"
    assert ident_file.startswith(str(venv)) and "dtwin/identify" in ident_file
    assert version == "0.1.0"
