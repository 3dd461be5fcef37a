"""Read a recorded vibration file into a :class:`~dtwin.io.record.Record`: one entry point.

:func:`read_record` picks the reader by extension (one module per format, ``fmt_*.py``), then
applies the same post-processing to every format, in this order:

1. **tachometer**: the channel named by `tacho` is taken out of the signals into ``Record.tacho``;
2. **channel selection** by name, index or group name (``"acc1"`` selects ``acc1_x``,
   ``acc1_y``, ``acc1_z``), in the order given;
3. **units** given by the caller override what the file says (files such as WAV and ``.npy``
   carry none);
4. **sensitivity** ``{channel: (value, "mV/g")}`` converts a voltage channel to the physical
   quantity, ``x_phys = x_volt / S`` with ``S`` in volts per unit (a channel with no unit is
   taken to be in volts; this assumption is recorded in ``metadata["sensitivity"]``);
5. **channel groups**: names ending in ``_x``, ``_y``, ``_z`` with a common stem (``acc1_x``,
   ``acc1_y``, ``acc1_z``) form a group (a triaxial accelerometer as one sensor).

Files are only ever opened for reading. Every failure is one of the documented error classes
(:class:`~dtwin.errors.UnreadableFileError` for a file that cannot be parsed,
:class:`~dtwin.errors.RecordError` for a record that cannot be built, e.g. no sampling rate,
:class:`~dtwin.errors.ChannelError` for an unknown channel), with a message that says what to
change. Quality checks (NaN, clipping, rate too low for the mesh frequency…) are in
:mod:`dtwin.io.validate`, so that a flawed record can still be inspected.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import math
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ChannelError, RecordError, UnreadableFileError
from .record import Record

#: Standard gravity (m/s^2), ISO 80000-3, for conversions between g and m/s^2.
STANDARD_GRAVITY = 9.80665

#: Extension → format module (``dtwin.io.fmt_<name>``). ``.dtwin.h5`` is checked first.
EXTENSIONS: dict[str, str] = {
    ".dtwin.h5": "native",
    ".csv": "csv",
    ".tsv": "csv",
    ".txt": "csv",
    ".wav": "wav",
    ".npy": "numpy",
    ".npz": "numpy",
    ".mat": "matlab",
    ".h5": "hdf5",
    ".hdf5": "hdf5",
    ".tdms": "tdms",
    ".uff": "uff",
    ".unv": "uff",
}

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


# --------------------------------------------------------------------------------------------
# format detection
# --------------------------------------------------------------------------------------------


def format_of(path: str | os.PathLike) -> str:
    """The format name (module ``fmt_<name>``) for a file name, from its extension."""
    name = Path(path).name.lower()
    if name.endswith(".dtwin.h5"):
        return "native"
    suffix = Path(name).suffix
    if suffix in EXTENSIONS:
        return EXTENSIONS[suffix]
    raise UnreadableFileError(
        f"{path}: unknown file extension {suffix!r}; supported: "
        f"{', '.join(sorted(EXTENSIONS))} (or pass fmt= one of "
        f"{sorted(set(EXTENSIONS.values()))})"
    )


# --------------------------------------------------------------------------------------------
# post-processing shared by every format
# --------------------------------------------------------------------------------------------


def detect_groups(channels: Sequence[str]) -> dict[str, tuple[str, ...]]:
    """Channel groups from axis suffixes: ``acc1_x, acc1_y, acc1_z`` → ``{"acc1": (...)}``.

    A group needs at least two channels with the same stem and distinct axes x/y/z.
    """
    stems: dict[str, list[tuple[str, str]]] = {}
    for c in channels:
        m = _AXIS_RE.match(c)
        if m and m.group("stem") and m.group("stem") != c:
            stems.setdefault(m.group("stem"), []).append((m.group("axis").lower(), c))
    groups: dict[str, tuple[str, ...]] = {}
    for stem, members in stems.items():
        axes = [a for a, _ in members]
        if len(members) >= 2 and len(set(axes)) == len(axes) and stem not in channels:
            groups[stem] = tuple(c for _, c in sorted(members))
    return groups


def _expand_selection(
    record: Record, channels: Sequence[str | int], groups: Mapping[str, tuple[str, ...]]
) -> list[int]:
    idx: list[int] = []
    for c in channels:
        if isinstance(c, str) and c not in record.channels and c in groups:
            idx.extend(record.index(m) for m in groups[c])
        elif isinstance(c, str) and c not in record.channels:
            raise ChannelError(
                f"unknown channel {c!r}; the file has channels {list(record.channels)}"
                + (f" and groups {sorted(groups)}" if groups else "")
            )
        else:
            idx.append(record.index(c))
    return idx


def parse_sensitivity(spec: Any, channel: str) -> tuple[float, str, str]:
    """Parse ``(value, "mV/g")`` or ``(value, "mV/g", "m/s^2")`` → (volts per output unit,
    output unit, text as given).

    The numerator is a voltage (``V``, ``mV``, ``uV``); the denominator the physical unit
    (``g``, ``m/s^2``, ``m/s``, ``mm/s``, ``m``, ``mm``, ``um``, ``N``, ``Pa``), optionally in
    parentheses: ``"mV/(m/s^2)"``. The optional third item converts the output to another unit
    of the same quantity (``g`` ↔ ``m/s^2`` with :data:`STANDARD_GRAVITY`, ``mm/s`` ↔ ``m/s``,
    ``um``/``mm``/``m``): ``S_out = S · factor(unit) / factor(out)``.
    """
    if not (isinstance(spec, Sequence) and not isinstance(spec, str) and len(spec) in (2, 3)):
        raise RecordError(
            f"sensitivity for {channel!r} must be a pair (value, unit) such as (100.0, 'mV/g'), "
            f"or (value, unit, output unit) such as (100.0, 'mV/g', 'm/s^2'); got {spec!r}"
        )
    value, text = spec[0], spec[1]
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise RecordError(f"sensitivity for {channel!r}: {value!r} is not a number") from None
    if not (math.isfinite(value) and value > 0.0):
        raise RecordError(f"sensitivity for {channel!r} must be positive and finite, got {value}")
    t = normalise_unit(str(text))
    num, sep, den = t.partition("/")
    den = normalise_unit(den)
    if not sep or num.strip().lower() not in _VOLT_UNITS or den.lower() not in _PHYS_UNITS:
        raise RecordError(
            f"sensitivity unit {text!r} for {channel!r} not understood; write "
            "'<voltage>/<quantity>' with voltage V, mV or uV and quantity one of "
            f"{sorted(set(_PHYS_UNITS.values()))}, e.g. 'mV/g' or 'mV/(m/s^2)'"
        )
    volts_per_unit = value * _VOLT_UNITS[num.strip().lower()]
    unit = _PHYS_UNITS[den.lower()]
    if len(spec) == 3:
        out = _PHYS_UNITS.get(normalise_unit(str(spec[2])).lower())
        if out is None or _SI_FACTOR[out][0] != _SI_FACTOR[unit][0]:
            raise RecordError(
                f"sensitivity for {channel!r}: cannot express {_SI_FACTOR[unit][0]} in "
                f"{spec[2]!r}; choose one of "
                f"{[u for u, (q, _) in _SI_FACTOR.items() if q == _SI_FACTOR[unit][0]]}"
            )
        volts_per_unit *= _SI_FACTOR[out][1] / _SI_FACTOR[unit][1]
        text = f"{text} -> {out}"
        unit = out
    return volts_per_unit, unit, str(text)


def _apply_sensitivity(
    data: np.ndarray,
    channels: tuple[str, ...],
    units: list[str],
    groups: Mapping[str, tuple[str, ...]],
    sensitivity: Mapping[str | int, Any],
) -> dict[str, Any]:
    applied: dict[str, Any] = {}
    for key, spec in sensitivity.items():
        if isinstance(key, str) and key in channels:
            targets = [key]
        elif isinstance(key, str) and key in groups:
            targets = list(groups[key])
        elif isinstance(key, str):
            raise ChannelError(
                f"sensitivity given for unknown channel {key!r}; channels are {list(channels)}"
            )
        elif isinstance(key, (int, np.integer)) and not isinstance(key, bool):
            targets = [key]
        else:
            raise RecordError(f"sensitivity keys are channel names, group names or indices, "
                              f"got {key!r}")
        for tgt in targets:
            i = channels.index(tgt) if isinstance(tgt, str) else int(tgt)
            if not -len(channels) <= i < len(channels):
                raise ChannelError(
                    f"sensitivity given for channel index {tgt}; the record has "
                    f"{len(channels)} channels"
                )
            i %= len(channels)
            name = channels[i]
            volts_per_unit, phys, text = parse_sensitivity(spec, name)
            unit_in = units[i]
            if unit_in and unit_in.lower() not in _VOLT_UNITS:
                raise RecordError(
                    f"channel {name!r} is already in {unit_in!r}, not a voltage: drop its "
                    "sensitivity, or pass units={" + repr(name) + ": 'V'} if the file's unit "
                    "label is wrong"
                )
            to_volt = _VOLT_UNITS[unit_in.lower()] if unit_in else 1.0
            data[i] = data[i] * (to_volt / volts_per_unit)
            units[i] = phys
            applied[name] = {
                "sensitivity": f"{spec[0]} {text}",
                "volts_per_unit": volts_per_unit,
                "input_unit": unit_in or "V (assumed: the file gave no unit)",
                "output_unit": phys,
            }
    return applied


def _units_override(
    units: str | Sequence[str] | Mapping[str | int, str], channels: tuple[str, ...], current: list[str]
) -> list[str]:
    out = list(current)
    if isinstance(units, str):
        return [normalise_unit(units)] * len(channels)
    if isinstance(units, Mapping):
        for k, u in units.items():
            if isinstance(k, str):
                if k not in channels:
                    raise ChannelError(
                        f"units given for unknown channel {k!r}; channels are {list(channels)}"
                    )
                out[channels.index(k)] = normalise_unit(u)
            elif not isinstance(k, (int, np.integer)) or isinstance(k, bool):
                raise RecordError(f"units keys are channel names or indices, got {k!r}")
            else:
                if not -len(channels) <= int(k) < len(channels):
                    raise ChannelError(f"units given for channel index {k}; there are "
                                       f"{len(channels)} channels")
                out[int(k)] = normalise_unit(u)
        return out
    units = list(units)
    if len(units) != len(channels):
        raise RecordError(
            f"{len(units)} units given for {len(channels)} channels {list(channels)}; give one "
            "unit per selected channel, a single unit for all, or a mapping name → unit"
        )
    return [normalise_unit(u) for u in units]


def read_record(
    path: str | os.PathLike,
    *,
    channels: Sequence[str | int] | None = None,
    sample_rate: float | None = None,
    time_column: str | int | None = None,
    units: str | Sequence[str] | Mapping[str | int, str] | None = None,
    sensitivity: Mapping[str | int, tuple[float, str] | tuple[float, str, str]] | None = None,
    tacho: str | int | None = None,
    tacho_ppr: int | None = None,
    tacho_shaft: str | None = None,
    group: str | None = None,
    fmt: str | None = None,
) -> Record:
    """Read a vibration record from a file (opened read-only).

    **Arguments:**

    - `path`: the file; the format follows from the extension (``.csv .tsv .txt .wav .npy
      .npz .mat .h5 .hdf5 .tdms .uff .unv .dtwin.h5``) unless `fmt` is given.
    - `channels`: channels to keep, by name, index or group name (default: all but the tacho).
    - `sample_rate`: sampling rate (Hz); needed when the file states none (CSV without time
      column, ``.npy``); when the file states one too, the file's is kept in
      ``metadata["file_sample_rate"]`` and :func:`dtwin.io.validate.check_record` reports a
      disagreement.
    - `time_column`: name (or CSV column index) of the time axis (s) if not auto-detected.
    - `units`: physical units overriding the file's: one for all, one per selected channel,
      or a mapping channel → unit.
    - `sensitivity`: ``{channel or group: (value, "mV/g")}``; converts volts to the quantity
      (a third item, e.g. ``(100.0, "mV/g", "m/s^2")``, gives the output unit).
    - `tacho`: the tachometer channel (name/index), moved to ``Record.tacho``.
    - `tacho_ppr`: tachometer pulses per revolution (positive integer).
    - `tacho_shaft`: ``"sun"`` (input) or ``"carrier"`` (output).
    - `group`: container inside the file: TDMS group, HDF5/MATLAB v7.3 group or struct path.
    - `fmt`: force a format (``csv wav numpy matlab hdf5 tdms uff native``).

    **Returns:** a :class:`~dtwin.io.record.Record` with ``data`` in physical units and
    ``metadata`` holding the source path, format and what was applied.
    """
    p = Path(path)
    if not p.exists():
        raise UnreadableFileError(f"{p}: no such file; check the path")
    if not p.is_file():
        raise UnreadableFileError(f"{p} is not a regular file")
    name = fmt if fmt is not None else format_of(p)
    if name not in set(EXTENSIONS.values()):
        raise UnreadableFileError(
            f"unknown format {fmt!r}; use one of {sorted(set(EXTENSIONS.values()))}"
        )
    if sample_rate is not None:
        sample_rate = resolve_rate(None, sample_rate, str(p))
    if tacho_ppr is not None and (int(tacho_ppr) != tacho_ppr or int(tacho_ppr) < 1):
        raise RecordError(f"tacho_ppr must be a positive whole number of pulses, got {tacho_ppr}")
    if tacho_shaft is not None and tacho_shaft not in ("sun", "carrier"):
        raise RecordError(f"tacho_shaft must be 'sun' (input) or 'carrier' (output), "
                          f"got {tacho_shaft!r}")
    module = importlib.import_module(f"{__package__}.fmt_{name}")
    raw: Record = module.read(p, sample_rate=sample_rate, time_column=time_column, group=group)
    return finish_record(
        raw, path=p, fmt=name, channels=channels, units=units, sensitivity=sensitivity,
        tacho=tacho, tacho_ppr=tacho_ppr, tacho_shaft=tacho_shaft,
    )


def finish_record(
    raw: Record,
    *,
    path: Path | None = None,
    fmt: str | None = None,
    channels: Sequence[str | int] | None = None,
    units: str | Sequence[str] | Mapping[str | int, str] | None = None,
    sensitivity: Mapping[str | int, tuple[float, str] | tuple[float, str, str]] | None = None,
    tacho: str | int | None = None,
    tacho_ppr: int | None = None,
    tacho_shaft: str | None = None,
) -> Record:
    """Apply tacho extraction, channel selection, units, sensitivity and grouping (see module
    docstring) to a record as a format reader returned it."""
    groups_raw = {**detect_groups(raw.channels), **raw.groups}
    tacho_sig = raw.tacho
    keep = list(range(len(raw.channels)))
    meta = dict(raw.metadata)
    if tacho is not None:
        ti = raw.index(tacho)
        tacho_sig = raw.data[ti].copy()
        meta["tacho_channel"] = raw.channels[ti]
        keep.remove(ti)
    if channels is not None:
        if isinstance(channels, (str, int)):
            channels = [channels]
        keep = _expand_selection(raw, list(channels), groups_raw)
        if tacho is not None and raw.index(tacho) in keep:
            raise RecordError(
                f"channel {raw.channels[raw.index(tacho)]!r} is selected both as a signal and "
                "as the tacho; remove it from channels="
            )
    data = raw.data[keep].copy()
    chans = tuple(raw.channels[i] for i in keep)
    unit_list = [raw.units[i] for i in keep]
    if units is not None:
        unit_list = _units_override(units, chans, unit_list)
    groups = {g: m for g, m in {**detect_groups(chans), **raw.groups}.items()
              if all(c in chans for c in m)}
    if sensitivity:
        if not isinstance(sensitivity, Mapping):
            raise RecordError("sensitivity must be a mapping {channel: (value, 'mV/g')}")
        meta["sensitivity"] = _apply_sensitivity(data, chans, unit_list, groups, sensitivity)
    if path is not None:
        previous = meta.get("source")
        if previous is not None and previous != str(path):
            meta["derived_from"] = {"source": previous, "format": meta.get("format")}
        meta["source"] = str(path)
    if fmt is not None:
        meta["format"] = fmt
    return dataclasses.replace(
        raw,
        data=data,
        channels=chans,
        units=tuple(unit_list),
        tacho=tacho_sig,
        tacho_ppr=int(tacho_ppr) if tacho_ppr is not None else raw.tacho_ppr,
        tacho_shaft=tacho_shaft if tacho_shaft is not None else raw.tacho_shaft,
        groups=groups,
        metadata=meta,
    )


def write_record(record: Record, path: str | os.PathLike, *, force: bool = False) -> Path:
    """Write a record in dtwin's own format (``*.dtwin.h5``), atomically; see
    :func:`dtwin.io.fmt_native.write`."""
    from .fmt_native import write

    return write(record, path, force=force)
