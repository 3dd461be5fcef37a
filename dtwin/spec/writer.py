"""Spec mappings written back as TOML (what `dtwin calibrate` writes; `dtwin.spec` reads it).

Python's standard library reads TOML (``tomllib``) but does not write it. A spec is a small,
regular document: top-level strings, tables of scalars and lists of numbers, nested tables
(``[motor.pmsm]``, ``[bearings.sun]``) and the array of tables ``[[faults]]``; this module
writes exactly that subset. Values that are None (a field left at "not given") are omitted.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

__all__ = ["spec_to_toml"]


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() else json.dumps(k)


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if hasattr(v, "item"):  # numpy scalars
        return _value(v.item())
    raise TypeError(f"cannot write {type(v).__name__} value {v!r} as TOML")


def _is_table(v: Any) -> bool:
    return isinstance(v, Mapping)


def _is_table_array(v: Any) -> bool:
    return isinstance(v, (list, tuple)) and bool(v) and all(isinstance(x, Mapping) for x in v)


def _emit(out: list[str], path: str, table: Mapping[str, Any]) -> None:
    scalars = [(k, v) for k, v in table.items()
               if v is not None and not _is_table(v) and not _is_table_array(v)]
    subtables = [(k, v) for k, v in table.items() if _is_table(v)]
    arrays = [(k, v) for k, v in table.items() if _is_table_array(v)]
    if path and (scalars or not (subtables or arrays)):
        out.append(f"\n[{path}]")
    for k, v in scalars:
        out.append(f"{_key(k)} = {_value(v)}")
    for k, v in subtables:
        if any(x is not None for x in v.values()):
            _emit(out, f"{path}.{_key(k)}" if path else _key(k), v)
    for k, v in arrays:
        name = f"{path}.{_key(k)}" if path else _key(k)
        for item in v:
            out.append(f"\n[[{name}]]")
            for kk, vv in item.items():
                if vv is not None:
                    out.append(f"{_key(kk)} = {_value(vv)}")


def spec_to_toml(data: Mapping[str, Any], header: str | None = None) -> str:
    """TOML text of a spec mapping (module docstring), with `header` as leading comments."""
    out: list[str] = []
    if header:
        out += [f"# {line}".rstrip() for line in header.splitlines()]
    _emit(out, "", {k: v for k, v in data.items()})
    return "\n".join(out).lstrip("\n") + "\n"
