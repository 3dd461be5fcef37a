"""Arrays out: every figure's data as CSV and NPZ with named columns and units, and tables as
pandas DataFrames.

Files written by :func:`write_columns` (1-D columns of equal length: a spectrum, a PSD, a
waveform):

- ``STEM.csv``: a header row ``name [unit],name [unit],…`` (the unit in brackets, ``[1]`` for
  dimensionless), then one row per sample, full float precision (``repr``), comma-separated;
  ``pandas.read_csv`` reads it as it is;
- ``STEM.npz``: one array per column under its bare name, plus ``units`` (a string array, same
  order as ``columns``) and ``columns``; ``numpy.load(path)`` reads it without pickle.

:func:`write_grid` writes a 2-D map (a waterfall, an order map): the NPZ holds the two axes and
the grid (shape ``(len(y), len(x))``); the CSV holds it in long form, one row per cell
(``x [unit],y [unit],z [unit]``).

Both go through :class:`dtwin.io.output.OutputFolder`, so they are atomic and listed in the
manifest.

:func:`export_arrays` writes the same arrays to one file a user names (``dtwin spectrum
--export``, ``dtwin view --export``), its format from the suffix: ``.csv`` and ``.npz`` hold one
array set (the first), ``.h5``/``.hdf5`` every set as an HDF5 group, one dataset per column with
its ``unit`` attribute (a grid as its two axes and the 2-D dataset, ``axes`` naming them).
"""

from __future__ import annotations

import dataclasses
import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import OutputExistsError, SettingsError

__all__ = ["EXPORT_SUFFIXES", "Columns", "Grid", "check_export_path", "columns_csv",
           "columns_dataframe", "export_arrays", "read_columns_csv", "write_columns", "write_grid"]


def _unit_text(unit: str | None) -> str:
    return unit if unit else "1"


def columns_csv(columns: Mapping[str, Any], units: Mapping[str, str | None]) -> str:
    """The CSV text of equal-length 1-D `columns` (name → array) with `units` (name → unit)."""
    names = list(columns)
    arrays = [np.asarray(columns[n]).ravel() for n in names]
    lengths = {a.size for a in arrays}
    if len(lengths) > 1:
        raise ValueError(f"columns differ in length: {dict(zip(names, map(len, arrays), strict=True))}")
    for n in names:
        if "," in n or "\n" in n:
            raise ValueError(f"column name {n!r} holds a comma or newline")
    buf = io.StringIO()
    buf.write(",".join(f"{n} [{_unit_text(units.get(n))}]" for n in names) + "\n")
    n = arrays[0].size if arrays else 0
    for i in range(0, n, _CHUNK):  # whole columns a chunk of rows at a time
        buf.write("\n".join(map(",".join, zip(*(_texts(a[i:i + _CHUNK]) for a in arrays),
                                              strict=True))))
        buf.write("\n")
    return buf.getvalue()


#: Rows formatted at once (the texts of a chunk are Python strings: ~80 bytes a cell).
_CHUNK = 1 << 16


def _texts(a: np.ndarray) -> list[str]:
    """The cells of one column as text (:func:`_cell` of each value): real floats through
    ``repr`` of Python floats and integers through ``str``, many rows at a time (a million rows
    in about a second); other kinds value by value."""
    if a.dtype.kind == "f":
        return list(map(repr, a.astype(np.float64).tolist()))
    if a.dtype.kind in "iu":
        return list(map(str, a.tolist()))
    return [_cell(v) for v in a]


def _cell(v: Any) -> str:
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    s = str(v)
    return f'"{s}"' if ("," in s or '"' in s) else s


def read_columns_csv(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """Read a CSV written by :func:`write_columns` back: ``(columns, units)`` (numeric columns)."""
    text = Path(path).read_text()
    header, *rows = text.strip("\n").split("\n")
    names, units = [], {}
    for h in header.split(","):
        name, _, rest = h.partition(" [")
        names.append(name)
        units[name] = rest.rstrip("]")
    data = np.array([[float(c) for c in r.split(",")] for r in rows]) if rows else np.empty((0, len(names)))
    return {n: data[:, i] for i, n in enumerate(names)}, units


def _npz_bytes(arrays: Mapping[str, Any], units: Sequence[str], names: Sequence[str]) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **{k: np.asarray(v) for k, v in arrays.items()},
             units=np.asarray(list(units), dtype=str), columns=np.asarray(list(names), dtype=str))
    return buf.getvalue()


def write_columns(folder, stem: str, columns: Mapping[str, Any],
                  units: Mapping[str, str | None]) -> list[Path]:
    """Write ``STEM.csv`` and ``STEM.npz`` of 1-D `columns` into `folder` (an
    :class:`~dtwin.io.output.OutputFolder`); **returns** the two paths."""
    names = list(columns)
    csv = folder.write_text(f"{stem}.csv", columns_csv(columns, units))
    npz = folder.write_bytes(f"{stem}.npz", _npz_bytes(
        columns, [_unit_text(units.get(n)) for n in names], names))
    return [csv, npz]


def write_grid(folder, stem: str, x: tuple[str, Any, str | None], y: tuple[str, Any, str | None],
               z: tuple[str, Any, str | None]) -> list[Path]:
    """Write a 2-D map: `x`, `y`, `z` are ``(name, values, unit)``, ``z`` of shape
    ``(len(y), len(x))``. NPZ: the axes and the grid; CSV: long form (module docstring)."""
    (xn, xv, xu), (yn, yv, yu), (zn, zv, zu) = x, y, z
    xv, yv, zv = np.asarray(xv), np.asarray(yv), np.asarray(zv)
    if zv.shape != (yv.size, xv.size):
        raise ValueError(f"{zn} has shape {zv.shape}, expected ({yv.size}, {xv.size})")
    xx, yy = np.meshgrid(xv, yv)
    units = {xn: xu, yn: yu, zn: zu}
    csv = folder.write_text(f"{stem}.csv", columns_csv(
        {xn: xx.ravel(), yn: yy.ravel(), zn: zv.ravel()}, units))
    npz = folder.write_bytes(f"{stem}.npz", _npz_bytes(
        {xn: xv, yn: yv, zn: zv}, [_unit_text(units[n]) for n in (xn, yn, zn)], [xn, yn, zn]))
    return [csv, npz]


def columns_dataframe(columns: Mapping[str, Any], units: Mapping[str, str | None] | None = None):
    """A pandas DataFrame of `columns`, units kept in ``df.attrs["units"]`` (pandas is needed:
    ``pip install dtwin[fleet]`` or ``pandas``)."""
    try:
        import pandas as pd
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("DataFrames need pandas: pip install 'dtwin[fleet]' (or pandas)") from e
    df = pd.DataFrame({k: np.asarray(v) if not isinstance(v, list) else v
                       for k, v in columns.items()})
    df.attrs["units"] = {k: _unit_text((units or {}).get(k)) for k in columns}
    return df


def _stem(name: str) -> str:
    return name[: -len(".csv")] if name.endswith(".csv") else name


@dataclasses.dataclass
class Columns:
    """1-D columns to write later into a run's folder: ``files["spectrum.csv"] =
    Columns({...}, {...})`` writes ``spectrum.csv`` and ``spectrum.npz``
    (:func:`write_columns`; :func:`dtwin.cli.options.emit` calls :meth:`write_into`)."""

    columns: Mapping[str, Any]
    units: Mapping[str, str | None]

    def write_into(self, folder: Any, name: str) -> list[Path]:
        return write_columns(folder, _stem(name), self.columns, self.units)


@dataclasses.dataclass
class Grid:
    """A 2-D map to write later (:func:`write_grid`): `x`, `y`, `z` are ``(name, values,
    unit)``."""

    x: tuple[str, Any, str | None]
    y: tuple[str, Any, str | None]
    z: tuple[str, Any, str | None]

    def write_into(self, folder: Any, name: str) -> list[Path]:
        return write_grid(folder, _stem(name), self.x, self.y, self.z)


#: File suffixes :func:`export_arrays` writes, and the format of each.
EXPORT_SUFFIXES = {".csv": "CSV", ".npz": "NPZ", ".h5": "HDF5", ".hdf5": "HDF5"}


def _suffix(path: Path) -> str:
    return path.suffix.lower()


def check_export_path(path: str | Path, *, force: bool = False,
                      inputs: Sequence[str | Path] = (), option: str = "--export") -> Path:
    """Check a file named for :func:`export_arrays` before any work: a known suffix, a folder
    that is writable or can be created, not one of the `inputs` (a record is never
    overwritten), and no existing file unless `force`. Raises :class:`~dtwin.errors.SettingsError` naming
    `option`; **returns** the path."""
    import os


    path = Path(path)
    if _suffix(path) not in EXPORT_SUFFIXES:
        raise SettingsError(f"{option}: {path.name} has no known suffix; end it in "
                            + ", ".join(EXPORT_SUFFIXES) + " (CSV, NumPy, HDF5)")
    resolved = path.resolve()
    for p in inputs:
        if Path(p).resolve() == resolved:
            raise SettingsError(f"{option}: {path} is an input of the command; name another "
                                "file (inputs are never overwritten)")
    if path.exists() and path.is_dir():
        raise SettingsError(f"{option}: {path} is a folder; give a file name")
    probe = path.parent
    while not probe.exists() and probe.parent != probe:  # missing folders are created
        probe = probe.parent
    if not probe.is_dir():
        raise SettingsError(f"{option}: {probe} is a file, so {path} cannot be created; choose "
                            "another name")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise SettingsError(f"{option}: {probe} is not writable; choose a folder you can write "
                            "to")
    if path.exists() and not force:
        raise OutputExistsError(f"{option}: {path} exists; choose another name or pass --force "
                                "to overwrite")
    return path


def _set_arrays(item: Columns | Grid) -> tuple[dict[str, np.ndarray], dict[str, str], list[str]]:
    """Columns of an array set (a grid in long form), their units and, for a grid, its axes."""
    if isinstance(item, Grid):
        (xn, xv, xu), (yn, yv, yu), (zn, zv, zu) = item.x, item.y, item.z
        xx, yy = np.meshgrid(np.asarray(xv), np.asarray(yv))
        return ({xn: xx.ravel(), yn: yy.ravel(), zn: np.asarray(zv).ravel()},
                {xn: _unit_text(xu), yn: _unit_text(yu), zn: _unit_text(zu)}, [xn, yn])
    return ({k: np.asarray(v) for k, v in item.columns.items()},
            {k: _unit_text(item.units.get(k)) for k in item.columns}, [])


def _hdf5_bytes(sets: Mapping[str, Columns | Grid], attrs: Mapping[str, Any]) -> bytes:
    import h5py

    buf = io.BytesIO()
    with h5py.File(buf, "w") as f:
        for k, v in attrs.items():
            f.attrs[k] = v if isinstance(v, (int, float, np.number)) else str(v)
        for name, item in sets.items():
            g = f.create_group(name)
            if isinstance(item, Grid):
                for n, vals, unit in (item.x, item.y, item.z):
                    d = g.create_dataset(n, data=np.asarray(vals))
                    d.attrs["unit"] = _unit_text(unit)
                g.attrs["axes"] = np.asarray([item.y[0], item.x[0]], dtype=h5py.string_dtype())
                continue
            for n, vals in item.columns.items():
                d = g.create_dataset(n, data=np.asarray(vals))
                d.attrs["unit"] = _unit_text(item.units.get(n))
            g.attrs["columns"] = np.asarray(list(item.columns), dtype=h5py.string_dtype())
    return buf.getvalue()


def export_arrays(path: str | Path, sets: Mapping[str, Columns | Grid], *,
                  attrs: Mapping[str, Any] | None = None) -> Path:
    """Write array sets to one file, atomically (a temporary file, then a rename).

    **Arguments:**

    - `path`: the file (missing folders are created); ``.csv`` (header ``name [unit]``, full precision) and ``.npz`` hold
      the first set (a grid in long form), ``.h5``/``.hdf5`` every set as a group.
    - `sets`: name → :class:`Columns` or :class:`Grid` (e.g. ``{"spectrum": Columns(...)}``).
    - `attrs`: file attributes (HDF5 only): the record, the command, the input speed.

    **Returns:** the path written. Check it first with :func:`check_export_path`.
    """
    import os
    import tempfile

    path = Path(path)
    if not sets:
        raise ValueError("nothing to export")
    fmt = EXPORT_SUFFIXES[_suffix(path)]
    if fmt == "HDF5":
        data = _hdf5_bytes(sets, dict(attrs or {}))
    else:
        columns, units, _ = _set_arrays(next(iter(sets.values())))
        names = list(columns)
        data = (columns_csv(columns, units).encode() if fmt == "CSV"
                else _npz_bytes(columns, [units[n] for n in names], names))
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
