"""Names, units, sampling rates and arrays as record files hold them: the small shared helpers
of the format readers (``fmt_*.py``) and of :mod:`dtwin.io.readers` (which re-exports them).

A lower module than the readers, so that a format module never imports the dispatcher that
imports it.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import ChannelError, RecordError, UnreadableFileError
from .record import Record

#: Standard gravity (m/s^2), ISO 80000-3, for conversions between g and m/s^2.
STANDARD_GRAVITY = 9.80665


#: Column/array names recognised as a time axis (lower case, unit suffix removed).
TIME_NAMES = ("time", "t", "time_s", "times", "timestamp_s")
#: Names recognised as a sampling rate (scalar) in npz/MAT/HDF5 files (lower case).
RATE_NAMES = ("sample_rate", "fs", "sampling_rate", "samplerate", "sr", "sampling_frequency")
#: Names recognised as channel names (string arrays) in npz/MAT/HDF5 files (lower case).
NAME_KEYS = ("channels", "channel_names", "names", "labels")
#: Names recognised as channel units (string arrays) in npz/MAT/HDF5 files (lower case).
UNIT_KEYS = ("units", "unit")

_TIME_UNITS = {"s": 1.0, "sec": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "min": 60.0}
_VOLT_UNITS = {"v": 1.0, "mv": 1e-3, "uv": 1e-6, "µv": 1e-6}
#: Physical units a sensitivity may refer to (lower-case spelling → canonical unit).
_PHYS_UNITS = {
    "g": "g", "m/s^2": "m/s^2", "m/s2": "m/s^2", "m/s": "m/s", "mm/s": "mm/s", "m": "m",
    "mm": "mm", "um": "um", "µm": "um", "n": "N", "pa": "Pa",
}
#: Canonical physical unit → (quantity, factor to SI), for converting a sensitivity's unit.
_SI_FACTOR = {
    "g": ("acceleration", STANDARD_GRAVITY), "m/s^2": ("acceleration", 1.0),
    "m/s": ("velocity", 1.0), "mm/s": ("velocity", 1e-3),
    "m": ("displacement", 1.0), "mm": ("displacement", 1e-3), "um": ("displacement", 1e-6),
    "N": ("force", 1.0), "Pa": ("pressure", 1.0),
}
_AXIS_RE = re.compile(r"^(?P<stem>.+?)[_.\-]?(?P<axis>[xyzXYZ])$")


# --------------------------------------------------------------------------------------------
# small shared helpers (used by the fmt_* modules)
# --------------------------------------------------------------------------------------------


def normalise_unit(unit: str | None) -> str:
    """Canonical spelling of a unit string: ``m/s²`` → ``m/s^2``, surrounding blanks removed."""
    if unit is None:
        return ""
    u = str(unit).strip().replace("²", "^2").replace("³", "^3").replace("μ", "µ")
    if u.startswith("(") and u.endswith(")"):
        u = u[1:-1].strip()
    return u


_HEADER_UNIT_RE = re.compile(r"^(?P<name>.*?)\s*[\[(](?P<unit>[^\])]*)[\])]\s*$")


def split_name_unit(label: str) -> tuple[str, str]:
    """Split a column label ``"acc1_x [m/s^2]"`` or ``"acc (g)"`` into name and unit."""
    label = str(label).strip()
    m = _HEADER_UNIT_RE.match(label)
    if m and m.group("name"):
        return m.group("name").strip(), normalise_unit(m.group("unit"))
    return label, ""


def is_time_name(name: str) -> bool:
    """Whether a column/array name denotes the time axis."""
    return name.strip().lower() in TIME_NAMES


def time_to_seconds(t: np.ndarray, unit: str, where: str) -> np.ndarray:
    """Convert a time axis in `unit` (s, ms, us, min; empty = s) to seconds."""
    u = normalise_unit(unit).lower() or "s"
    if u not in _TIME_UNITS:
        raise RecordError(
            f"{where}: time unit {unit!r} not understood; use one of {sorted(_TIME_UNITS)} "
            "or pass sample_rate= and time_column=None"
        )
    return np.asarray(t, dtype=np.float64) * _TIME_UNITS[u]


def rate_from_time(t: np.ndarray, where: str) -> dict[str, Any]:
    """Sampling rate (Hz) implied by a time axis (s), and its worst relative step deviation.

    ``rate = (n - 1) / (t[-1] - t[0])``; ``nonuniformity = max |dt_k - dt_mean| / dt_mean``.
    """
    t = np.asarray(t, dtype=np.float64)
    if t.size < 2:
        raise RecordError(
            f"{where}: the time column has {t.size} sample(s), too few to infer the sampling "
            "rate; pass sample_rate= (Hz)"
        )
    if not np.all(np.isfinite(t)):
        bad = int(np.flatnonzero(~np.isfinite(t))[0])
        raise RecordError(f"{where}: the time column holds NaN/inf at sample {bad}; fix the file "
                          "or pass sample_rate= and time_column=None")
    span = float(t[-1] - t[0])
    if not span > 0.0:
        raise RecordError(
            f"{where}: the time column does not increase (from {t[0]} to {t[-1]} s); "
            "pass sample_rate= (Hz) and time_column=None"
        )
    dt = np.diff(t)
    dt_mean = span / (t.size - 1)
    return {
        "rate": (t.size - 1) / span,
        "start": float(t[0]),
        "nonuniformity": float(np.max(np.abs(dt - dt_mean)) / dt_mean),
    }


def resolve_rate(file_rate: float | None, given: float | None, where: str) -> float:
    """The sampling rate to use: the caller's if given (a file rate is kept in metadata), else
    the file's; neither is a :class:`RecordError` saying to pass ``sample_rate``."""
    rate = given if given is not None else file_rate
    if rate is None:
        raise RecordError(
            f"{where}: the file states no sampling rate; pass sample_rate= (Hz) "
            "(CLI: --sample-rate)"
        )
    try:
        rate = float(rate)
    except (TypeError, ValueError):
        raise RecordError(f"{where}: sampling rate {rate!r} is not a number (Hz)") from None
    if not (math.isfinite(rate) and rate > 0.0):
        raise RecordError(f"{where}: sampling rate must be a positive number of Hz, got {rate}")
    return rate


def as_signal(arr: Any, name: str, where: str) -> np.ndarray:
    """A real float64 1-D view of a stored channel; anything else is an `UnreadableFileError`."""
    a = np.asarray(arr)
    if a.dtype.kind not in "biuf":
        raise UnreadableFileError(
            f"{where}: channel {name!r} holds {a.dtype} values, not real numbers"
        )
    return a.astype(np.float64, copy=False).reshape(-1)


def to_str(value: Any) -> str:
    """Decode bytes/numpy strings stored in files to ``str``."""
    if isinstance(value, (bytes, np.bytes_)):
        return bytes(value).decode("utf-8", errors="replace")
    if isinstance(value, np.ndarray) and value.shape == ():
        return to_str(value.item())
    return str(value)


def str_list(value: Any) -> list[str]:
    """A list of strings from a stored string array, JSON list or comma-separated string."""
    if isinstance(value, (str, bytes, np.bytes_, np.str_)):
        s = to_str(value)
        try:
            parsed = json.loads(s)
        except json.JSONDecodeError:
            parsed = None
        if isinstance(parsed, list):
            return [str(v) for v in parsed]
        return [p.strip() for p in s.split(",")] if s else []
    arr = np.asarray(value, dtype=object).reshape(-1)
    return [to_str(v).strip() for v in arr]


def scalar_float(value: Any, name: str, where: str) -> float:
    """A stored scalar (e.g. ``fs``) as float; a non-scalar is an `UnreadableFileError`."""
    a = np.asarray(value)
    if a.size != 1 or a.dtype.kind not in "biuf":
        raise UnreadableFileError(
            f"{where}: {name!r} should be a single number (Hz), found shape {a.shape} {a.dtype}"
        )
    return float(a.reshape(()))


def records_from_arrays(
    arrays: Mapping[str, np.ndarray],
    *,
    where: str,
    sample_rate: float | None,
    time_column: str | int | None,
    file_rate: float | None = None,
    names: Sequence[str] | None = None,
    units: Mapping[str, str] | Sequence[str] | None = None,
    metadata: Mapping[str, Any] | None = None,
) -> Record:
    """Build a record from named numeric arrays (npz, MATLAB, HDF5 share this layout logic).

    Layout rules:

    - a scalar named like a rate (:data:`RATE_NAMES`) gives the sampling rate (Hz);
    - a vector named like time (:data:`TIME_NAMES`, or `time_column`) gives the time axis (s);
    - string arrays named ``channels``/``names`` and ``units`` name the channels of ``data``;
    - an array ``data`` (1-D, or 2-D with channels along the shorter axis) holds the channels;
    - otherwise every numeric 1-D array (or 2-D with one axis of length 1, e.g. a MATLAB column)
      is one channel named by its key, and a 2-D array with 3 columns ``acc1`` becomes
      ``acc1_x``, ``acc1_y``, ``acc1_z`` (other widths: ``acc1_0``, ``acc1_1`` …).
    """
    meta: dict[str, Any] = dict(metadata or {})
    lower = {k.lower(): k for k in arrays}
    channel_arrays: dict[str, np.ndarray] = {}
    time_key: str | None = None

    if isinstance(time_column, int):
        raise RecordError(f"{where}: time_column must be an array name here, not an index")
    if time_column is not None:
        if time_column not in arrays:
            raise ChannelError(
                f"{where}: time column {time_column!r} not found; arrays are {sorted(arrays)}"
            )
        time_key = time_column
    for key in arrays:
        if time_key is None and is_time_name(key) and np.asarray(arrays[key]).size > 1:
            time_key = key
    if file_rate is None:
        for rn in RATE_NAMES:
            if rn in lower and np.asarray(arrays[lower[rn]]).size == 1:
                file_rate = scalar_float(arrays[lower[rn]], lower[rn], where)
                break
    if names is None:
        for nk in NAME_KEYS:
            if nk in lower:
                names = str_list(arrays[lower[nk]])
                break
    if units is None:
        for uk in UNIT_KEYS:
            if uk in lower and np.asarray(arrays[lower[uk]]).dtype.kind in "USO":
                units = str_list(arrays[lower[uk]])
                break
    skip = {lower[k] for k in (*RATE_NAMES, *NAME_KEYS, *UNIT_KEYS) if k in lower}
    if time_key is not None:
        skip.add(time_key)

    if "data" in lower:
        data = np.asarray(arrays[lower["data"]])
        if data.ndim == 1:
            data = data[None, :]
        elif data.ndim == 2:
            if data.shape[0] > data.shape[1]:
                data = data.T
        else:
            raise UnreadableFileError(
                f"{where}: 'data' has {data.ndim} dimensions; expected (channels, samples)"
            )
        n_ch = data.shape[0]
        if names is None:
            names = [f"ch{i}" for i in range(n_ch)]
        names = list(names)
        if len(names) != n_ch:
            raise UnreadableFileError(
                f"{where}: {len(names)} channel names for {n_ch} channels in 'data'"
            )
        for i, nm in enumerate(names):
            channel_arrays[nm] = as_signal(data[i], nm, where)
    else:
        for key, arr in arrays.items():
            if key in skip:
                continue
            a = np.asarray(arr)
            if a.dtype.kind not in "biuf" or a.size < 1:
                continue
            if a.ndim == 0 or a.size == 1:
                meta.setdefault("scalars", {})[key] = float(a.reshape(()))
                continue
            if a.ndim == 1 or (a.ndim == 2 and 1 in a.shape):
                channel_arrays[key] = as_signal(a, key, where)
            elif a.ndim == 2:
                m = a if a.shape[0] <= a.shape[1] else a.T
                suffixes = "xyz" if m.shape[0] == 3 else [str(i) for i in range(m.shape[0])]
                for i, s in enumerate(suffixes):
                    channel_arrays[f"{key}_{s}"] = as_signal(m[i], f"{key}_{s}", where)
            else:
                raise UnreadableFileError(
                    f"{where}: array {key!r} has {a.ndim} dimensions; store channels as 1-D "
                    "arrays or a (channels, samples) matrix"
                )
        if names is not None and len(names) == len(channel_arrays):
            channel_arrays = dict(zip(names, channel_arrays.values(), strict=True))
    if not channel_arrays:
        raise UnreadableFileError(
            f"{where}: no numeric signal arrays found (arrays: {sorted(arrays)}); store the "
            "signals as 1-D arrays or a 'data' matrix"
        )
    lengths = {k: v.size for k, v in channel_arrays.items()}
    if len(set(lengths.values())) > 1:
        raise RecordError(
            f"{where}: channels have different lengths {lengths}; a record needs channels of "
            "equal length sampled at one rate"
        )
    n = next(iter(lengths.values()))
    if time_key is not None:
        t = as_signal(arrays[time_key], time_key, where)
        if t.size != n:
            raise RecordError(
                f"{where}: time axis {time_key!r} has {t.size} samples, channels have {n}"
            )
        tinfo = rate_from_time(t, where)
        tinfo["name"] = time_key
        meta["time_column"] = tinfo
        if file_rate is None:
            file_rate = tinfo["rate"]
    if file_rate is not None:
        meta["file_sample_rate"] = float(file_rate)
    rate = resolve_rate(file_rate, sample_rate, where)
    chans = list(channel_arrays)
    if units is None:
        unit_list = [""] * len(chans)
    elif isinstance(units, Mapping):
        unit_list = [normalise_unit(units.get(c, "")) for c in chans]
    else:
        unit_list = [normalise_unit(u) for u in units]
        if len(unit_list) != len(chans):
            unit_list = (unit_list + [""] * len(chans))[: len(chans)]
    data = np.stack([channel_arrays[c] for c in chans]) if chans else np.zeros((0, n))
    return Record(data=data, sample_rate=rate, channels=tuple(chans), units=tuple(unit_list),
                  metadata=meta)
