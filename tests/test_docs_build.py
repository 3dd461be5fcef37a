"""The user's documentation builds (issue #54): ``mkdocs build --strict`` of ``mkdocs.yml``,
the guides of ``docs/`` and an API reference generated from the docstrings (mkdocstrings).

A warning fails the build: a page missing from the navigation, a link to a page of ``docs/``
that does not exist or to an anchor it lacks, an object of the API page that cannot be found.
Links from a guide to files of the repository outside ``docs/`` (the README, the benchmarks)
are not pages of the site and are not checked here (tests/test_readme.py checks the README's).
Skipped where mkdocs is not installed (``pip install -e ".[docs]"``; ``make`` installs it).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_docs_build_strict_with_the_api_reference(tmp_path):
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings_handlers.python")
    site = tmp_path / "site"
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q",
                           "-f", str(ROOT / "mkdocs.yml"), "-d", str(site)],
                          cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-4000:]
    # every guide of docs/ is a page of the site
    for page in sorted((ROOT / "docs").glob("*.md")):
        html = site / ("index.html" if page.stem == "index" else f"{page.stem}/index.html")
        assert html.is_file(), f"docs/{page.name} is not in the site (mkdocs.yml's nav)"
    # the API reference holds the public functions, with their docstrings
    api = (site / "api" / "index.html").read_text()
    for name in ("dtwin.build_twin", "dtwin.simulation.simulate.simulate", "dtwin.read_record",
                 "identify.estimate_severity", "identify.discover.discover",
                 "identify.DiscoverySettings", "identify.calibrate.calibrate",
                 "identify.fleet.run_fleet", "dtwin.io.export.export_arrays"):
        assert f'id="{name}"' in api, name
    assert "Units are SI" in api  # the page says which units the signatures use
