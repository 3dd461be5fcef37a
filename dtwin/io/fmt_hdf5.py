"""Generic HDF5 records (``.h5``/``.hdf5``) via h5py.

Layout read (inside `group`, default the root, or its only subgroup):

- one dataset per channel (1-D, or 2-D ``(n, 3)`` → ``name_x/y/z``), named after the channel,
  with an optional ``units``/``unit`` attribute; or a dataset ``data`` ``(channels, samples)``
  with a ``channels`` attribute or dataset naming its rows;
- the sampling rate (Hz) as an attribute ``sample_rate`` (or ``fs``) of the group or the
  datasets, or as a scalar dataset ``fs``/``sample_rate``; or a ``time`` dataset (s).

Files written by dtwin itself (root attribute ``dtwin_format``) are handed to
:mod:`dtwin.io.fmt_native`; MATLAB v7.3 files (HDF5 with a MATLAB header) to
:mod:`dtwin.io.fmt_matlab`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RecordError, UnreadableFileError
from . import fmt_matlab, fmt_native
from .record import Record
from .values import (
    NAME_KEYS,
    RATE_NAMES,
    UNIT_KEYS,
    records_from_arrays,
    scalar_float,
    str_list,
    to_str,
)

#: Exceptions h5py raises on corrupt, truncated or unexpected files.
H5_ERRORS = (OSError, KeyError, ValueError, RuntimeError, TypeError, IndexError)


def _attr_rate(attrs: Any, where: str) -> float | None:
    for k in attrs:
        if k.lower() in RATE_NAMES:
            return scalar_float(attrs[k], k, where)
    return None


def _read_group(g: Any, where: str, sample_rate: float | None, time_column: Any) -> Record:
    import h5py

    arrays: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    names = None
    file_rate = _attr_rate(g.attrs, where)
    for k in g.attrs:
        if k.lower() in NAME_KEYS:
            names = str_list(g.attrs[k])
    data_units: list[str] | None = None
    for k, ds in g.items():
        if not isinstance(ds, h5py.Dataset):
            continue
        arrays[k] = np.asarray(ds[()])
        for ak in ds.attrs:
            val = ds.attrs[ak]
            if ak.lower() in UNIT_KEYS:
                if np.ndim(val) == 0:
                    units[k] = to_str(val)
                elif k == "data":
                    data_units = str_list(val)
            if ak.lower() in NAME_KEYS and k == "data":
                names = str_list(val)
        if file_rate is None:
            file_rate = _attr_rate(ds.attrs, where)
    unit_arg: Any = units or None
    if "data" in arrays:
        unit_arg = data_units
    return records_from_arrays(arrays, where=where, sample_rate=sample_rate,
                               time_column=time_column, file_rate=file_rate, names=names,
                               units=unit_arg, metadata={"hdf5_group": g.name})


def read(
    path: Path, *, sample_rate: float | None, time_column: str | int | None, group: str | None
) -> Record:
    """Read an HDF5 file. **Returns:** a record (units from dataset attributes)."""
    import h5py  # at read time: h5py loads HDF5's C library

    where = str(path)
    try:
        if fmt_matlab.has_matlab_header(path):
            return fmt_matlab.read(path, sample_rate=sample_rate, time_column=time_column,
                                   group=group)
        with h5py.File(path, "r") as f:
            if "dtwin_format" not in f.attrs:
                if group is not None:
                    if group not in f or not isinstance(f[group], h5py.Group):
                        raise RecordError(f"{where}: group {group!r} not found; groups are "
                                          f"{_groups(f)}")
                    g = f[group]
                else:
                    g = f
                    has_data = any(isinstance(v, h5py.Dataset) for v in f.values())
                    subgroups = [v for v in f.values() if isinstance(v, h5py.Group)]
                    if not has_data and len(subgroups) == 1:
                        g = subgroups[0]
                    elif not has_data and subgroups:
                        raise RecordError(f"{where}: several groups hold data; pass group= one "
                                          f"of {_groups(f)}")
                return _read_group(g, where, sample_rate, time_column)
    except H5_ERRORS as e:
        if isinstance(e, RecordError):
            raise
        raise UnreadableFileError(f"{where}: not a readable HDF5 file ({type(e).__name__}: "
                                  f"{e})") from None
    # a file written by dtwin: read by its own reader (after closing it here)
    return fmt_native.read(path, sample_rate=sample_rate, time_column=time_column, group=group)


def _groups(f: Any) -> list[str]:
    import h5py

    out: list[str] = []
    f.visititems(lambda name, obj: out.append(name) if isinstance(obj, h5py.Group) else None)
    return out
