"""LabVIEW TDMS records via npTDMS.

A TDMS file holds groups of channels. `group` picks one; by default every channel of every
group is read, named ``group/channel`` unless the channel names are unique. Non-numeric
channels (timestamps, strings) are skipped and listed in ``metadata["skipped_channels"]``. The sampling rate is ``1 / wf_increment`` (s) of the channels (waveform
properties); the unit comes from the ``unit_string`` property.
"""

from __future__ import annotations

import logging
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


class _TruncationWatch(logging.Handler):
    """Collects npTDMS's log warnings that a segment holds less data than its header states, or
    that the last segment's metadata is incomplete (npTDMS logs them and reads what is there, or
    nothing: a cut file would pass as a shorter record, or as one without channels), and keeps
    every npTDMS log line off the console while the file is read (npTDMS gives its loggers a
    console handler of their own, so turning propagation off alone does not silence them)."""

    _LOGGERS = ("nptdms.reader", "nptdms.tdms_segment")
    _CUT = ("less data than expected", "not a multiple of the chunk size",
            "metadata is incomplete")

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        msg = record.getMessage()
        if any(cut in msg for cut in self._CUT):
            self.messages.append(msg)

    def __enter__(self) -> _TruncationWatch:
        self._saved = []
        for name in self._LOGGERS:
            log = logging.getLogger(name)
            self._saved.append((log, log.propagate, list(log.handlers)))
            for h in list(log.handlers):
                log.removeHandler(h)
            log.addHandler(self)
            log.propagate = False
        return self

    def __exit__(self, *exc: object) -> None:
        for log, propagate, handlers in self._saved:
            log.removeHandler(self)
            for h in handlers:
                log.addHandler(h)
            log.propagate = propagate


#: Bytes of a TDMS segment's lead-in (tag ``TDSm``, table of contents, version, two offsets).
_LEAD_IN = 28


def _check_lead_in(path: Path) -> None:
    """Refuse a file shorter than one segment's lead-in: npTDMS reads such a file as one
    without channels. One that starts with the ``TDSm`` tag was cut."""
    size = path.stat().st_size
    if size >= _LEAD_IN:
        return
    with open(path, "rb") as f:
        head = f.read(4)
    if size and b"TDSm"[:len(head)] == head:
        raise UnreadableFileError(
            f"{path}: the TDMS file is truncated: {size} bytes, fewer than the {_LEAD_IN} of "
            "its first segment's lead-in; the copy or the recording was cut: copy the file "
            "again from the recorder")
    raise UnreadableFileError(f"{path}: not a TDMS file ({size} bytes, no 'TDSm' segment)")


def read(
    path: Path, *, sample_rate: float | None, time_column: str | int | None, group: str | None
) -> Record:
    """Read a TDMS file. **Returns:** a record with TDMS units and the waveform rate."""
    from nptdms import TdmsFile

    where = str(path)
    if time_column is not None:
        raise RecordError(f"{where}: TDMS waveforms carry their own time base; drop "
                          "time_column= (or pass sample_rate=)")
    _check_lead_in(path)
    try:
        with _TruncationWatch() as cut:
            tdms = TdmsFile.read(path)
        if cut.messages:
            what = ("its last segment's metadata is incomplete" if "metadata" in cut.messages[0]
                    else "its last segment holds less data than its header states")
            raise UnreadableFileError(
                f"{where}: the TDMS file is truncated: {what} (npTDMS: {cut.messages[0]}); the "
                "copy or the recording was cut: copy the file again from the recorder")
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
