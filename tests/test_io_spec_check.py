"""``dtwin spec check`` and malformed specs fed to :func:`dtwin.spec.load_spec`.

Property: whatever a spec holds (values of the wrong type or unit, NaN, missing or unknown keys,
random TOML bytes), loading it either succeeds or raises :class:`~dtwin.errors.SpecError` whose
``problems`` are (field path, message) pairs with a message, never another exception. The CLI
prints every problem with its path and exits with 2; 0 for the bundled presets.
"""

from __future__ import annotations

import copy
import json
import os
import tempfile
import tomllib
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dtwin.cli import main
from dtwin.errors import SpecError, UnreadableFileError

spec_mod = pytest.importorskip("dtwin.spec")

SETTINGS = settings(max_examples=int(os.environ.get("DTWIN_FUZZ_EXAMPLES", "40")),
                    deadline=3000, suppress_health_check=[HealthCheck.too_slow])
PRESET_FILES = sorted(spec_mod.SPECS_DIR.glob("*.toml"))
with open(spec_mod.SPECS_DIR / "paper-sim.toml", "rb") as _f:
    BASE = tomllib.load(_f)


def _paths(tree, prefix=()):
    for k, v in tree.items():
        yield (*prefix, k)
        if isinstance(v, dict):
            yield from _paths(v, (*prefix, k))


PATHS = list(_paths(BASE))
spec_mod.load_spec(BASE)  # the first load compiles JAX code: keep it out of the deadline
VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-10**12, 10**12),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12),
    st.lists(st.floats(-1e3, 1e3), max_size=4), st.dictionaries(st.text(max_size=6),
                                                                st.integers(), max_size=3),
)


def _assert_documented(spec_source):
    try:
        spec_mod.load_spec(spec_source)
    except SpecError as e:
        assert e.problems, "SpecError without problems"
        for path, message in e.problems:
            assert isinstance(path, str) and isinstance(message, str) and message.strip()
        assert str(e).strip()


@SETTINGS
@given(edits=st.lists(st.tuples(st.sampled_from(PATHS), VALUES), min_size=1, max_size=5),
       drops=st.lists(st.sampled_from(PATHS), max_size=2),
       extra=st.dictionaries(st.text(min_size=1, max_size=8), VALUES, max_size=2))
def test_mutated_specs_give_spec_errors(edits, drops, extra):
    spec = copy.deepcopy(BASE)
    for path, value in edits:
        node = spec
        for k in path[:-1]:
            if not isinstance(node.get(k), dict):
                break
            node = node[k]
        else:
            node[path[-1]] = value
    for path in drops:
        node = spec
        for k in path[:-1]:
            node = node.get(k) if isinstance(node.get(k), dict) else {}
        node.pop(path[-1], None)
    spec.update(extra)
    _assert_documented(spec)


@SETTINGS
@given(data=st.binary(max_size=600))
def test_random_toml_bytes(data):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "spec.toml"
        path.write_bytes(data)
        try:
            _assert_documented(path)
        except UnreadableFileError as e:
            assert str(e).strip()


def test_unit_slip_and_unknown_key_reported_with_paths(tmp_path, capsys):
    """A module given in mm (2 instead of 0.002 m) and a misspelt key: both at once, exit 2."""
    spec = copy.deepcopy(BASE)
    spec["gears"]["module"] = 2.0
    spec["gears"]["facewidth"] = 0.02
    text = _to_toml(spec)
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(SystemExit) as ex:
        main(["spec", "check", str(path), "--json"])
    assert ex.value.code == 2
    report = json.loads(capsys.readouterr().out)
    paths = {p["path"] for p in report["problems"]}
    assert report["ok"] is False and {"gears.module", "gears.facewidth"} <= paths
    assert any("0.002 m" in p["message"] for p in report["problems"])
    with pytest.raises(SystemExit) as ex:
        main(["spec", "check", str(path)])
    assert ex.value.code == 2
    table = capsys.readouterr().out
    assert "gears.module" in table and "gears.facewidth" in table


@pytest.mark.parametrize("path", PRESET_FILES, ids=lambda p: p.stem)
def test_presets_pass(path, capsys):
    main(["spec", "check", str(path), "--json"])  # returns normally: exit code 0
    report = json.loads(capsys.readouterr().out)
    assert report["ok"] is True and report["problems"] == []
    assert report["spec"]["gears"]["z_sun"] == tomllib.loads(path.read_text())["gears"]["z_sun"]


def test_binary_file_reported_by_the_cli(tmp_path, capsys):
    path = tmp_path / "spec.toml"
    path.write_bytes(b"\x80\x81 not text")
    with pytest.raises(SystemExit) as ex:
        main(["spec", "check", str(path), "--json"])
    assert ex.value.code == 2
    report = json.loads(capsys.readouterr().out)
    assert report["ok"] is False and "UTF-8" in report["problems"][0]["message"]


def test_missing_file_exit_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as ex:
        main(["spec", "check", str(tmp_path / "nope.toml")])
    assert ex.value.code == 2
    assert "nope.toml" in capsys.readouterr().out


def _to_toml(tree, prefix=""):
    """Minimal TOML writer for the spec's layout (tables of scalars and arrays of tables)."""
    lines, tables = [], []
    for k, v in tree.items():
        if isinstance(v, dict):
            tables.append((k, v))
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for item in v:
                lines.append(f"\n[[{prefix}{k}]]")
                lines.append(_to_toml(item, f"{prefix}{k}."))
        else:
            lines.append(f"{k} = {json.dumps(v)}")
    for k, v in tables:
        lines.append(f"\n[{prefix}{k}]")
        lines.append(_to_toml(v, f"{prefix}{k}."))
    return "\n".join(lines)
