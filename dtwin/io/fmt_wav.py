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
from .record import Record
from .values import resolve_rate

_FULL_SCALE = {"int16": 2.0**15, "int32": 2.0**31, "int64": 2.0**63}


def scan_header(path: Path) -> dict:
    """Walk the RIFF chunks and check the ``fmt `` and ``data`` chunks before scipy parses them.

    scipy trusts the header (a zero channel count or block size divides by zero, a missing
    ``data`` chunk fails inside scipy); this walk refuses such files with a clear message.

    **Returns:** format tag, bits per sample, channel count, container (RIFF/RIFX/RF64).
    """
    where = str(path)
    size_on_disk = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(12)
        if len(head) < 12 or head[:4] not in (b"RIFF", b"RIFX", b"RF64") or head[8:] != b"WAVE":
            raise UnreadableFileError(f"{where}: not a WAV file (no RIFF/WAVE header)")
        endian = ">" if head[:4] == b"RIFX" else "<"
        declared = struct.unpack(endian + "I", head[4:8])[0] + 8
        end = size_on_disk if head[:4] == b"RF64" else min(declared, size_on_disk)
        info: dict = {"container": head[:4].decode("ascii")}
        pos = 12
        while pos < end:
            f.seek(pos)
            hdr = f.read(8)
            if len(hdr) < 8:
                break
            cid, size = struct.unpack(endian + "4sI", hdr)
            if cid == b"fmt ":
                body = f.read(min(size, 40))
                if len(body) < 16:
                    raise UnreadableFileError(f"{where}: WAV 'fmt ' chunk is truncated")
                tag, nch, _rate, _bps, align, bits = struct.unpack(endian + "HHIIHH", body[:16])
                if tag == 0xFFFE and len(body) >= 26:
                    tag = struct.unpack(endian + "H", body[24:26])[0]
                if nch < 1 or align < 1 or bits < 1:
                    raise UnreadableFileError(
                        f"{where}: WAV header is corrupt ({nch} channels, block size {align}, "
                        f"{bits} bits per sample)")
                info.update(format_tag={1: "PCM", 3: "IEEE float"}.get(tag, str(tag)),
                            bits_per_sample=bits, n_channels=nch, block_align=align)
            elif cid == b"data":
                if "bits_per_sample" not in info:
                    raise UnreadableFileError(f"{where}: WAV 'data' chunk before the 'fmt ' chunk")
                info["data_bytes"] = size
                _check_data(where, info, size, size_on_disk - (pos + 8), head[:4] == b"RF64")
                return info
            pos += 8 + size + (size & 1)
    raise UnreadableFileError(f"{where}: WAV file without a 'data' chunk (truncated or corrupt)")


def _check_data(where: str, info: dict, size: int, available: int, rf64: bool) -> None:
    """The ``data`` chunk against the ``fmt `` chunk and the file: a frame is ``n_channels ×
    ceil(bits/8)`` bytes (the header's block size must say so), the chunk holds whole frames,
    and the file holds the bytes the chunk states (a cut file holds fewer). RF64 and streaming
    writers state ``0xFFFFFFFF``: the size is not checked then."""
    bits, nch, align = info["bits_per_sample"], info["n_channels"], info["block_align"]
    frame = nch * ((bits + 7) // 8)
    if align != frame:
        raise UnreadableFileError(
            f"{where}: WAV header is inconsistent: {bits} bits per sample × {nch} channel(s) "
            f"make {frame}-byte frames, but its block size says {align} bytes; the header's "
            "bit depth does not match the data: re-export the file from the recorder")
    if rf64 or size == 0xFFFFFFFF:
        return
    if size > available:
        raise UnreadableFileError(
            f"{where}: WAV file is truncated: its header states {size} bytes of data "
            f"({size // align} frames) but the file holds {max(available, 0)} "
            f"({max(available, 0) // align} frames); the copy or the recording was cut: copy the "
            "file again from the recorder")
    if size % align:
        raise UnreadableFileError(
            f"{where}: WAV data of {size} bytes is not a whole number of {align}-byte frames "
            f"({bits} bits × {nch} channel(s)); the header's bit depth or channel count does "
            "not match the data: re-export the file from the recorder")


def read(
    path: Path, *, sample_rate: float | None, time_column: str | int | None, group: str | None
) -> Record:
    """Read a WAV file. **Returns:** a record in fractions of full scale (empty unit)."""
    where = str(path)
    if group is not None or time_column is not None:
        raise RecordError(f"{where}: WAV files have no groups or time column; drop group= and "
                          "time_column=")
    header = scan_header(path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            rate, q = wavfile.read(path)
        except (ValueError, EOFError, struct.error, IndexError, OverflowError,
                ZeroDivisionError, MemoryError) as e:
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
    meta.update(header)
    if caught:
        meta["warnings"] = [str(w.message) for w in caught]
    return Record(
        data=data.T.copy(),
        sample_rate=resolve_rate(float(rate) if rate > 0 else None, sample_rate, where),
        channels=tuple(f"ch{i}" for i in range(data.shape[1])),
        units=("",) * data.shape[1],
        metadata=meta,
    )
