"""WAV (RIFF) records: 8-, 16-, 24-, 32-bit integer and 32/64-bit float PCM via ``scipy.io.wavfile``.

Integer samples are scaled by full scale to ``[-1, 1)``: ``x = q / 2^(b-1)`` for a ``b``-bit
signed code ``q`` (scipy returns 24-bit data left-justified in int32, so dividing by ``2^31``
gives the same value), ``x = (q - 128) / 128`` for unsigned 8-bit; float samples are kept as
stored. WAV carries no physical unit: channels are named ``ch0, ch1, …`` with an empty unit.
With a recorder whose full scale is ``V_fs`` volts, ``x·V_fs`` is the voltage, so a sensor
sensitivity ``S`` (V/unit) is applied as ``S / V_fs`` (e.g. 100 mV/g at 5 V full scale →
``(20.0, "mV/g")``), or pass ``units="V"`` when full scale is 1 V.
"""

from __future__ import annotations

import struct
import warnings
from pathlib import Path

import numpy as np
from scipy.io import wavfile

from ..errors import RecordError, UnreadableFileError
from .readers import resolve_rate
from .record import Record

_FULL_SCALE = {"int16": 2.0**15, "int32": 2.0**31, "int64": 2.0**63}


def _fmt_chunk(path: Path) -> dict:
    """Format tag and bits per sample from the ``fmt `` chunk (only after scipy accepted the file)."""
    with open(path, "rb") as f:
        head = f.read(12)
        while True:
            hdr = f.read(8)
            if len(hdr) < 8:
                return {}
            cid, size = struct.unpack("<4sI", hdr)
            if cid == b"fmt ":
                body = f.read(min(size, 40))
                if len(body) < 16:
                    return {}
                tag, _nch, _rate, _bps, _align, bits = struct.unpack("<HHIIHH", body[:16])
                if tag == 0xFFFE and len(body) >= 26:
                    tag = struct.unpack("<H", body[24:26])[0]
                return {"format_tag": {1: "PCM", 3: "IEEE float"}.get(tag, str(tag)),
                        "bits_per_sample": bits, "riff": head[:4].decode("ascii", "replace")}
            f.seek(size + (size & 1), 1)


def read(
    path: Path, *, sample_rate: float | None, time_column: str | int | None, group: str | None
) -> Record:
    """Read a WAV file. **Returns:** a record in fractions of full scale (empty unit)."""
    where = str(path)
    if group is not None or time_column is not None:
        raise RecordError(f"{where}: WAV files have no groups or time column; drop group= and "
                          "time_column=")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            rate, q = wavfile.read(path)
        except (ValueError, EOFError, struct.error, IndexError, OverflowError) as e:
            raise UnreadableFileError(f"{where}: not a readable WAV file ({e})") from None
    if q.ndim == 1:
        q = q[:, None]
    dtype = q.dtype.name
    if q.dtype.kind == "f":
        data = q.astype(np.float64)
        full_scale = 1.0
    elif dtype == "uint8":
        data = (q.astype(np.float64) - 128.0) / 128.0
        full_scale = 128.0
    elif dtype in _FULL_SCALE:
        full_scale = _FULL_SCALE[dtype]
        data = q.astype(np.float64) / full_scale
    else:
        raise UnreadableFileError(f"{where}: WAV sample type {dtype} not supported")
    meta: dict = {"wav_dtype": dtype, "full_scale_code": full_scale, "file_sample_rate": float(rate)}
    try:
        meta.update(_fmt_chunk(path))
    except (struct.error, OSError):
        pass
    if caught:
        meta["warnings"] = [str(w.message) for w in caught]
    return Record(
        data=data.T.copy(),
        sample_rate=resolve_rate(float(rate) if rate > 0 else None, sample_rate, where),
        channels=tuple(f"ch{i}" for i in range(data.shape[1])),
        units=("",) * data.shape[1],
        metadata=meta,
    )
