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
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ChannelError, RecordError, UnreadableFileError
from . import fmt_native
from .record import Record

# the helpers shared with the format modules live one level lower (dtwin.io.values); the
# public ones are re-exported here, where callers have always found them
from .values import _AXIS_RE, _PHYS_UNITS, _SI_FACTOR, _VOLT_UNITS
from .values import NAME_KEYS as NAME_KEYS
from .values import RATE_NAMES as RATE_NAMES
from .values import STANDARD_GRAVITY as STANDARD_GRAVITY
from .values import TIME_NAMES as TIME_NAMES
from .values import UNIT_KEYS as UNIT_KEYS
from .values import as_signal as as_signal
from .values import is_time_name as is_time_name
from .values import normalise_unit as normalise_unit
from .values import rate_from_time as rate_from_time
from .values import records_from_arrays as records_from_arrays
from .values import resolve_rate as resolve_rate
from .values import scalar_float as scalar_float
from .values import split_name_unit as split_name_unit
from .values import str_list as str_list
from .values import time_to_seconds as time_to_seconds
from .values import to_str as to_str

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
    return fmt_native.write(record, path, force=force)
