"""LabVIEW TDMS records via npTDMS.

A TDMS file holds groups of channels. `group` picks one; by default every channel of every
group is read, named ``group/channel`` unless the channel names are unique. Non-numeric
channels (timestamps, strings) are skipped and listed in ``metadata["skipped_channels"]``. The sampling rate is ``1 / wf_increment`` (s) of the channels (waveform
properties); the unit comes from the ``unit_string`` property.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from ..errors import RecordError, UnreadableFileError
from .record import Record
from .values import as_signal, resolve_rate

#: Exceptions npTDMS raises on corrupt or truncated files (it also raises plain ``Exception``
#: for a few unsupported layouts, converted in :func:`_is_nptdms_failure`).
_ERRORS = (ValueError, KeyError, EOFError, IndexError, struct.error, NotImplementedError,
           UnicodeError, OverflowError, RuntimeError, TypeError, MemoryError)


def read(
    path: Path, *, sample_rate: float | None, time_column: str | int | None, group: str | None
) -> Record:
    """Read a TDMS file. **Returns:** a record with TDMS units and the waveform rate."""
    from nptdms import TdmsFile

    where = str(path)
    if time_column is not None:
        raise RecordError(f"{where}: TDMS waveforms carry their own time base; drop "
                          "time_column= (or pass sample_rate=)")
    try:
        tdms = TdmsFile.read(path)
        groups = [g for g in tdms.groups() if len(g.channels()) > 0]
        if group is not None:
            sel = [g for g in groups if g.name == group]
            if not sel:
                raise RecordError(f"{where}: TDMS group {group!r} not found; groups with data "
                                  f"are {[g.name for g in groups]}")
            groups = sel
        chans = [(g.name, c) for g in groups for c in g.channels()]
        if not chans:
            raise UnreadableFileError(f"{where}: the TDMS file holds no channels")
        names_only = [c.name for _, c in chans]
        unique = len(set(names_only)) == len(names_only)
        names, units, signals, increments, skipped = [], [], [], [], []
        for gname, c in chans:
            nm = c.name if unique else f"{gname}/{c.name}"
            values = c[:]
            if np.asarray(values).dtype.kind not in "biuf":  # timestamps, strings: not signals
                skipped.append(nm)
                continue
            signals.append(as_signal(values, nm, where))
            names.append(nm)
            units.append(str(c.properties.get("unit_string", "")))
            inc = c.properties.get("wf_increment")
            increments.append(float(inc) if inc is not None else None)
        props = {k: str(v) for k, v in tdms.properties.items()}
    except _ERRORS as e:
        if isinstance(e, RecordError):
            raise
        raise UnreadableFileError(f"{where}: not a readable TDMS file ({type(e).__name__}: "
                                  f"{e})") from None
    except Exception as e:  # npTDMS raises bare Exception for some corrupt layouts
        if type(e) is not Exception:
            raise
        raise UnreadableFileError(f"{where}: not a readable TDMS file ({e})") from None
    if not signals:
        raise UnreadableFileError(f"{where}: no numeric channels (only {skipped}); a record "
                                  "needs sampled signals")
    lengths = {n: s.size for n, s in zip(names, signals, strict=True)}
    if len(set(lengths.values())) > 1:
        raise RecordError(f"{where}: TDMS channels have different lengths {lengths}; pick "
                          "channels of one acquisition with group= or channels=")
    incs = {i for i in increments if i is not None}
    if len(incs) > 1:
        raise RecordError(f"{where}: TDMS channels have different wf_increment {sorted(incs)} "
                          "s; pick one acquisition's channels with group=")
    file_rate = None
    if incs:
        inc = incs.pop()
        if not inc > 0:
            raise UnreadableFileError(f"{where}: wf_increment {inc} s is not positive")
        file_rate = 1.0 / inc
    meta: dict = {"tdms_properties": props}
    if skipped:
        meta["skipped_channels"] = skipped
    if file_rate is not None:
        meta["file_sample_rate"] = file_rate
    return Record(
        data=np.stack(signals),
        sample_rate=resolve_rate(file_rate, sample_rate, where),
        channels=tuple(names),
        units=tuple(units),
        metadata=meta,
    )
