"""``dtwin spec check`` on impossible tooth counts (issue 53): each problem names the field and
the rule it breaks, never a field the spec did not give."""

from __future__ import annotations

import json

import pytest

from dtwin.cli import main

_SPEC = """name = "t"
[gears]
z_sun = {zs}
z_planet = {zp}
z_ring = {zr}
n_planets = {n}
module = 0.002
face_width = 0.02
"""


def _check(tmp_path, capsys, zs, zp, zr, n):
    path = tmp_path / "spec.toml"
    path.write_text(_SPEC.format(zs=zs, zp=zp, zr=zr, n=n))
    with pytest.raises(SystemExit) as e:
        main(["spec", "check", str(path), "--json"])
    assert e.value.code == 2
    return json.loads(capsys.readouterr().out)["problems"]


@pytest.mark.parametrize("zr", [100, 60])
def test_ring_far_from_the_tooth_count_rule(tmp_path, capsys, zr):
    """z_ring 20 teeth away from z_sun + 2 z_planet = 80: named as gears.z_ring with the rule
    and both figures (not as a centre distance the spec never gave)."""
    (p,) = _check(tmp_path, capsys, 20, 30, zr, 3)
    assert p["path"] == "gears.z_ring"
    assert "z_ring = z_sun + 2 z_planet" in p["message"]
    assert f"z_ring = {zr} but z_sun + 2 z_planet = 80" in p["message"]
    assert "centre_distance" not in p["path"]


def test_too_many_planets_to_fit(tmp_path, capsys):
    """Seven planets of 30 teeth (tip diameter m (z + 2) = 64 mm) on a carrier of radius
    a = m (z_s + z_p)/2 = 50 mm: neighbouring centres 2 a sin(π/7) = 43.4 mm apart."""
    (p,) = _check(tmp_path, capsys, 20, 30, 80, 7)
    assert p["path"] == "gears.n_planets"
    assert "43.39 mm" in p["message"] and "64.00 mm" in p["message"]


def test_ring_with_too_few_teeth(tmp_path, capsys):
    (p,) = _check(tmp_path, capsys, 20, 30, 31, 3)
    assert p["path"] == "gears.z_ring" and "z_planet" in p["message"]


@pytest.mark.parametrize("field,teeth", [
    ("z_sun", (-20, 30, 80, 3)), ("z_planet", (20, -30, 80, 3)), ("z_ring", (20, 30, -80, 3)),
    ("z_sun", (0, 30, 60, 3)), ("n_planets", (20, 30, 80, -3)),
])
def test_negative_or_zero_counts_name_their_field(tmp_path, capsys, field, teeth):
    """A negative (or zero) tooth or planet count: one problem, on that field, with its
    value; not a tooth-count rule or a collision reported on a field the spec gave right."""
    (p,) = _check(tmp_path, capsys, *teeth)
    value = teeth[("z_sun", "z_planet", "z_ring", "n_planets").index(field)]
    assert p["path"] == f"gears.{field}", p
    assert f"gears.{field} = {value} " in p["message"] and "range" in p["message"], p
