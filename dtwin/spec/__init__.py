"""Gearbox spec files (TOML): schema, validation, presets and the lumped parameters they imply.

A spec describes one planetary gearbox and how it runs, in SI units throughout (m, kg, s, rad,
Hz, N/m, N·m/rad). :func:`load_spec` reads a TOML file (or takes a mapping), checks every
value, fills the defaults and returns a frozen :class:`Spec`; all problems are collected and
raised together as one :class:`~dtwin.errors.SpecError` whose ``problems`` list names each field
(``"gears.module"``) with a message that says what to change, including likely unit slips
(``gears.module = 2: did you mean 2 mm = 0.002 m?``). Unknown sections and keys are errors, with
a close match suggested. Registered parameters (:mod:`dtwin.model.registry`) use the registry's
plausible range; the others use the ranges of :data:`SCHEMA`. The schema is documented field by
field in ``docs/spec.md``.

:func:`lumped_from_spec` turns a spec into :class:`~dtwin.model.lumped.LumpedParameters`: geometry from
:class:`~dtwin.model.gears.GearSet`, masses and inertias from the geometry and mesh stiffness from
ISO 6336-1 (:func:`dtwin.model.stiffness.mesh_stiffness_mean`) unless the spec gives them (sections
``[mesh]`` and ``[lumped]`` win over geometry).

Presets ship as TOML files inside the package, ``dtwin/spec/presets/``: ``paper-sim``,
``paper-bench``, ``paper-like``, ``lin-parker`` (:func:`preset`).

The room's modules: this one reads specs (:class:`Spec`, :func:`load_spec`, :func:`preset`,
:func:`spec_to_dict`); :mod:`~dtwin.spec.schema` holds the fields, :mod:`~dtwin.spec.validate`
the checks, :mod:`~dtwin.spec.lumped` the lumped parameters, :mod:`~dtwin.spec.motor` the
``[motor]`` table, :mod:`~dtwin.spec.build` spec → twin and :mod:`~dtwin.spec.writer` specs
written back.
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import os
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..errors import SpecError, UnreadableFileError
from .lumped import lumped_from_spec as lumped_from_spec
from .schema import SCHEMA as SCHEMA
from .schema import FieldSpec as FieldSpec
from .schema import schema_markdown as schema_markdown
from .validate import _gear_set, _validate

SPECS_DIR = Path(__file__).resolve().parent / "presets"
"""Folder of the bundled preset specs (``dtwin/spec/presets/*.toml``, installed with the package)."""


PRESETS = ("paper-sim", "paper-bench", "paper-like", "lin-parker")
"""Names of the bundled presets."""


@dataclasses.dataclass(frozen=True)
class Spec:
    """A validated gearbox spec: every section present, defaults filled, SI values.

    - `data`: nested dict ``section -> key -> value`` (plus ``faults``: list of dicts and
      ``bearings``: dict location -> dict); treat as read-only (use :func:`spec_to_dict` for a
      copy).
    - `source`: the file it was read from, if any.

    ``spec["gears"]["module"]`` reads a value; :meth:`gear_set` builds the
    :class:`~dtwin.model.gears.GearSet`.
    """

    data: Mapping[str, Any]
    source: str | None = None

    def __getitem__(self, section: str) -> Any:
        return self.data[section]

    @property
    def name(self) -> str:
        return self.data.get("name") or (Path(self.source).stem if self.source else "spec")

    def gear_set(self):
        """The :class:`~dtwin.model.gears.GearSet` of ``[gears]`` (warnings were shown at load)."""
        return _gear_set(self.data["gears"], quiet=True)


def load_spec(source: str | os.PathLike | Mapping[str, Any]) -> Spec:
    """Read and validate a spec.

    **Arguments:** `source`: path of a TOML file, or a mapping with the same structure.

    **Returns:** a :class:`Spec` with every section present and the defaults filled.

    **Raises:** :class:`~dtwin.errors.SpecError` listing every problem as (field path, message);
    :class:`~dtwin.errors.UnreadableFileError` if the file cannot be read.
    """
    if isinstance(source, Mapping):
        return Spec(_validate(source), None)
    path = Path(source)
    try:
        with open(path, "rb") as f:
            raw = tomllib.load(f)
    except FileNotFoundError:
        raise UnreadableFileError(f"spec file {path} does not exist") from None
    except tomllib.TOMLDecodeError as e:
        raise SpecError([("", f"{path} is not valid TOML: {e}")]) from None
    except UnicodeDecodeError as e:
        raise SpecError([("", f"{path} is not UTF-8 text (TOML must be UTF-8): {e}")]) from None
    except OSError as e:
        raise UnreadableFileError(f"cannot read spec file {path}: {e}") from None
    return Spec(_validate(raw), str(path))


def preset(name: str) -> Spec:
    """A bundled preset spec: ``paper-sim``, ``paper-bench``, ``paper-like`` or ``lin-parker``."""
    if name not in PRESETS:
        close = difflib.get_close_matches(name, PRESETS, n=1)
        hint = f" Did you mean {close[0]!r}?" if close else ""
        raise SpecError([("preset", f"unknown preset {name!r}.{hint} Presets: "
                          f"{', '.join(PRESETS)}")])
    return load_spec(SPECS_DIR / f"{name}.toml")


def spec_to_dict(spec: Spec) -> dict[str, Any]:
    """A deep, JSON-ready copy of the validated spec (defaults filled), for manifests."""
    out = copy.deepcopy(dict(spec.data))
    if spec.source is not None:
        out["source"] = spec.source
    return out


__all__ = [
    "PRESETS",
    "SCHEMA",
    "SPECS_DIR",
    "FieldSpec",
    "Spec",
    "load_spec",
    "lumped_from_spec",
    "preset",
    "schema_markdown",
    "spec_to_dict",
]
