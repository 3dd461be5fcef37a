"""A spec's values checked against the schema (:mod:`dtwin.spec.schema`): every problem
collected as (field path, message) with what to change, likely unit slips named
(``gears.module = 2: did you mean 2 mm = 0.002 m?``), unknown keys with a close match, the
gear set's rules and the cross-section checks; the defaults filled (:func:`_validate`)."""

from __future__ import annotations

import copy
import dataclasses
import difflib
import math
import warnings
from collections.abc import Mapping
from typing import Any

from ..errors import GeometryError, SpecError
from ..model.gears import (
    GearSet,
)
from .motor import drive_from_spec
from .schema import (
    _DEG,
    _SECTIONS,
    _TOP_LEVEL,
    BEARING_LOCATIONS,
    BEARING_SCHEMA,
    FAULT_SCHEMA,
    SCHEMA,
    SPEED_PROFILE_SCHEMA,
    FieldSpec,
    _fmt,
)


def _unit_hint(v: float, unit: str, lo: float | None, hi: float | None, path: str = "") -> str:
    """A 'did you mean' for a value that fits the range once converted from a common unit
    (rpm only for rotation frequencies, ``*.f_sun``)."""
    if lo is None or hi is None:
        return ""
    if unit == "Hz" and not path.split("[")[0].endswith("f_sun"):
        return ""
    candidates: list[tuple[float, str]] = {
        "m": [(1e-3, "mm"), (1e-6, "µm"), (1e-2, "cm")],
        "rad": [(_DEG, "°")],
        "Hz": [(1 / 60, "rpm")],
        "N/m": [(1e3, "N/mm"), (1e6, "N/µm")],
        "Pa": [(1e9, "GPa"), (1e6, "MPa")],
        "kg/m^3": [(1e3, "g/cm³")],
        "kg": [(1e-3, "g")],
        "kg*m^2": [(1e-6, "kg·mm²")],
    }.get(unit, [])
    for factor, name in candidates:
        w = v * factor
        if lo <= w <= hi and w != 0:
            sep = "" if name == "°" else " "
            return f": did you mean {_fmt(v)}{sep}{name} = {_fmt(w)} {unit}?"
    return ""


def _check_number(path: str, v: Any, f: FieldSpec, problems: list) -> Any:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        problems.append((path, f"must be a number ({f.unit}), got {v!r}"))
        return None
    if f.kind == "int" and not (isinstance(v, int) or float(v).is_integer()):
        problems.append((path, f"must be an integer, got {v!r}"))
        return None
    if not math.isfinite(float(v)):
        problems.append((path, f"must be finite, got {v!r}"))
        return None
    lo, hi = f.range()
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        hint = _unit_hint(float(v), f.unit, lo, hi, path)
        unit = "" if f.unit == "1" else f" {f.unit}"
        rng = (f"plausible range {_fmt(lo) if lo is not None else '-inf'} .. "
               f"{_fmt(hi) if hi is not None else 'inf'}{unit}")
        what = f"{path} = {_fmt(float(v))}"
        problems.append((path, f"{what}{hint} ({rng})" if hint else
                         f"{what} is outside the {rng}"))
        return None
    return int(v) if f.kind == "int" else float(v)


def _check_value(path: str, v: Any, f: FieldSpec, problems: list) -> Any:
    if f.kind in ("int", "float"):
        return _check_number(path, v, f, problems)
    if f.kind == "str":
        if not f.choices and isinstance(v, str):  # free text (e.g. [calibration] provenance)
            return v
        if not isinstance(v, str) or v not in f.choices:
            close = [c for c in f.choices if isinstance(v, str) and v and c.startswith(v)]
            close = close or difflib.get_close_matches(str(v), f.choices, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            problems.append((path, f"must be one of {', '.join(f.choices)}, got {v!r}{hint}"))
            return None
        return v
    if f.kind == "bool":
        if not isinstance(v, bool):
            problems.append((path, f"must be true or false, got {v!r}"))
            return None
        return v
    if f.kind == "floats":
        if not isinstance(v, (list, tuple)):
            problems.append((path, f"must be a list of numbers ({f.unit}), got {v!r}"))
            return None
        out = []
        n_before = len(problems)
        item = dataclasses.replace(f, kind="float")
        for i, x in enumerate(v):
            out.append(_check_number(f"{path}[{i}]", x, item, problems))
        return out if len(problems) == n_before else None
    raise AssertionError(f.kind)


def _unknown(path: str, key: str, allowed: Any) -> tuple[str, str]:
    close = difflib.get_close_matches(key, list(allowed), n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    where = f"in [{path}]" if path else "at the top level"
    return (f"{path}.{key}" if path else key,
            f"unknown key {key!r} {where}{hint} (allowed: {', '.join(allowed)})")


def _check_table(path: str, table: Any, schema: Mapping[str, FieldSpec],
                 problems: list) -> dict[str, Any]:
    if not isinstance(table, Mapping):
        problems.append((path, f"must be a table, got {type(table).__name__}"))
        return {}
    out: dict[str, Any] = {}
    table = {k: v for k, v in table.items() if v is not None}  # None = absent (dict input)
    for key, val in table.items():
        if key not in schema:
            problems.append(_unknown(path, key, schema))
            continue
        out[key] = _check_value(f"{path}.{key}", val, schema[key], problems)
    for key, f in schema.items():
        if key not in table:
            if f.required:
                problems.append((f"{path}.{key}", f"is required ({f.doc}, {f.unit})"))
                out[key] = None
            else:
                out[key] = copy.deepcopy(f.default)
    return out


def _gear_set(g: Mapping[str, Any], *, quiet: bool):
    kw = {k: v for k, v in g.items() if v is not None}
    with warnings.catch_warnings():
        if quiet:
            warnings.simplefilter("ignore")
        return GearSet(**kw)


def _validate(raw: Mapping[str, Any]) -> dict[str, Any]:
    problems: list[tuple[str, str]] = []
    data: dict[str, Any] = {}
    for key in raw:
        if key not in _SECTIONS and key not in _TOP_LEVEL:
            problems.append(_unknown("", key, (*_SECTIONS, *_TOP_LEVEL)))
    for key in _TOP_LEVEL:
        v = raw.get(key)
        if v is not None and not isinstance(v, str):
            problems.append((key, f"must be a string, got {v!r}"))
        data[key] = v if isinstance(v, str) else None

    for section, schema in SCHEMA.items():
        table = raw.get(section, {})
        if section == "motor":
            data[section] = _check_motor(table, problems)
        elif section == "operating":
            data[section] = _check_operating(table, problems)
        else:
            data[section] = _check_table(section, table, schema, problems)

    # [damping]: zeta_mesh is a tie for both meshes
    d, draw = data["damping"], raw.get("damping", {})
    if isinstance(draw, Mapping) and d.get("zeta_mesh") is not None:
        for k in ("zeta_sun_planet", "zeta_ring_planet"):
            if draw.get(k) is not None and draw[k] != d["zeta_mesh"]:
                problems.append((f"damping.{k}", "given together with damping.zeta_mesh, which "
                                 "sets both mesh damping ratios; give one or the other"))
            d[k] = d["zeta_mesh"]

    # [lumped]: J and Ir2 of the same body exclude each other
    lum = data["lumped"]
    for b in ("sun", "ring", "carrier", "planet"):
        if lum.get(f"J_{b}") is not None and lum.get(f"Ir2_{b}") is not None:
            problems.append((f"lumped.Ir2_{b}", f"give lumped.J_{b} (kg·m²) or lumped.Ir2_{b} "
                             "(kg), not both"))

    # [[faults]]
    faults_raw = raw.get("faults", [])
    faults = []
    if isinstance(faults_raw, Mapping):
        faults_raw = [faults_raw]
    if not isinstance(faults_raw, list):
        problems.append(("faults", "must be an array of tables ([[faults]])"))
        faults_raw = []
    for i, fr in enumerate(faults_raw):
        faults.append(_check_table(f"faults[{i}]", fr, FAULT_SCHEMA, problems))
    data["faults"] = faults

    # [bearings.<location>]
    bearings: dict[str, Any] = {}
    braw = raw.get("bearings", {})
    if not isinstance(braw, Mapping):
        problems.append(("bearings", "must be a table of [bearings.sun|planet|carrier] tables"))
        braw = {}
    for loc, table in braw.items():
        if loc not in BEARING_LOCATIONS:
            problems.append(_unknown("bearings", loc, BEARING_LOCATIONS))
            continue
        b = _check_table(f"bearings.{loc}", table, BEARING_SCHEMA, problems)
        if b.get("ball_diameter") is not None and b.get("pitch_diameter") is not None and \
                b["ball_diameter"] >= b["pitch_diameter"]:
            problems.append((f"bearings.{loc}.ball_diameter", "must be smaller than "
                             "pitch_diameter"))
        bearings[loc] = b
    data["bearings"] = bearings

    _check_cross(data, problems)
    if problems:
        raise SpecError(problems)
    return data


def _check_motor(table: Any, problems: list) -> dict[str, Any]:
    """`[motor]`: validated by the motor module (`dtwin.spec.motor.drive_from_spec`), which
    knows every drive's parameters, defaults and plausible ranges; problems carry their paths."""
    if not isinstance(table, Mapping):
        problems.append(("motor", "must be a table"))
        return {"type": "ideal"}
    out: dict[str, Any] = {"type": _check_value("motor.type", table.get("type", "ideal"),
                                                SCHEMA["motor"]["type"], problems)}
    for k, v in table.items():
        if k == "type":
            continue
        out[k] = dict(v) if isinstance(v, Mapping) else v
    try:
        drive_from_spec(dict(out))
    except SpecError as e:
        problems.extend(e.problems)
    return out


def _check_operating(table: Any, problems: list) -> dict[str, Any]:
    if not isinstance(table, Mapping):
        problems.append(("operating", "must be a table"))
        return {}
    plain = {k: v for k, v in table.items() if k != "speed_profile"}
    out = _check_table("operating", plain, SCHEMA["operating"], problems)
    out["speed_profile"] = None
    if table.get("speed_profile") is not None:
        sp = _check_table("operating.speed_profile", table["speed_profile"],
                          SPEED_PROFILE_SCHEMA, problems)
        t, f = sp.get("t"), sp.get("f_sun")
        if t is not None and f is not None:
            if len(t) != len(f) or len(t) < 2:
                problems.append(("operating.speed_profile", "t and f_sun need the same length "
                                 f"(at least 2), got {len(t)} and {len(f)}"))
            elif any(b <= a for a, b in zip(t, t[1:], strict=False)):
                problems.append(("operating.speed_profile.t", "times must increase strictly"))
        out["speed_profile"] = sp
    return out


def _tooth_count_rule(g: Mapping[str, Any], found: list) -> list:
    """The gear set's problems, with a centre distance the spec never gave restated as the
    tooth-count rule it breaks: without ``centre_distance`` or shifts, dtwin takes the mean of
    the two meshes' standard centre distances, which exists only when ``z_ring`` is within a few
    teeth of ``z_sun + 2 z_planet`` (profile shift closes a small difference, not a large one)."""
    given = any(g.get(k) is not None for k in ("centre_distance", "x_sun", "x_planet", "x_ring"))
    if given:
        return list(found)
    zs, zp, zr = int(g["z_sun"]), int(g["z_planet"]), int(g["z_ring"])
    out = []
    for path, msg in found:
        if path == "gears.centre_distance":
            path, msg = "gears.z_ring", (
                f"z_ring = {zr} but z_sun + 2 z_planet = {zs + 2 * zp} (z_sun = {zs}, z_planet = "
                f"{zp}): the rule z_ring = z_sun + 2 z_planet, which profile shift bends by a "
                "tooth or two only, is broken by too much for the sun-planet and ring-planet "
                "meshes to share one carrier radius; change z_ring, z_sun or z_planet (or give "
                "gears.centre_distance or the profile shifts of your gearbox)")
        if (path, msg) not in out:
            out.append((path, msg))
    return out


def _check_cross(data: dict[str, Any], problems: list) -> None:
    """Checks that need several fields: the gear geometry, fault indices, per-planet lists."""
    s = data["sensor"]
    hz, db = s.get("frf_hz"), s.get("frf_db")
    if hz is not None and any(b <= a for a, b in zip(hz, hz[1:], strict=False)):
        problems.append(("sensor.frf_hz", "knots must be increasing (Hz)"))
    if (hz is None) != (db is None) or (hz is not None and len(hz) != len(db)):
        problems.append(("sensor.frf_db", "give sensor.frf_hz and sensor.frf_db together, one "
                         "gain per knot"))
    g = data["gears"]
    if any(g.get(k) is None for k in ("z_sun", "z_planet", "z_ring", "n_planets", "module",
                                      "face_width")):
        return  # already reported
    if any(p.startswith("gears.") for p, _ in problems):
        return
    try:
        gs = _gear_set(g, quiet=False)
    except GeometryError as e:
        problems.extend(_tooth_count_rule(g, e.problems))
        return
    n = gs.n_planets
    z = {"sun": gs.z_sun, "planet": gs.z_planet, "ring": gs.z_ring}
    for i, f in enumerate(data["faults"]):
        loc = f.get("location")
        if loc in z and f.get("tooth") is not None and f["tooth"] >= z[loc]:
            problems.append((f"faults[{i}].tooth", f"the {loc} has teeth 0..{z[loc] - 1}, got "
                             f"{f['tooth']}"))
        if loc == "planet" and f.get("planet") is not None and f["planet"] >= n:
            problems.append((f"faults[{i}].planet", f"planets are numbered 0..{n - 1}, got "
                             f"{f['planet']}"))
        if loc != "planet" and f.get("flank") is not None:
            problems.append((f"faults[{i}].flank", "only planet faults have a flank (sun|ring|"
                             "both)"))
    imp = data["imperfections"]
    for k in ("planet_position_errors", "load_sharing"):
        if imp.get(k) is not None and len(imp[k]) != n:
            problems.append((f"imperfections.{k}", f"needs one value per planet ({n}), got "
                             f"{len(imp[k])}"))
