"""MATLAB ``.mat`` records: v4/v5/v7 via ``scipy.io.loadmat``, v7.3 (HDF5) via h5py.

Variables are interpreted by :func:`dtwin.io.readers.records_from_arrays`: a scalar ``fs`` (or
``sample_rate``) is the sampling rate (Hz), a vector ``t``/``time`` the time axis (s), a cell
array ``channels`` names the columns of a matrix ``data``, otherwise each numeric vector is a
channel named after its variable and an ``N×3`` matrix ``acc1`` becomes ``acc1_x/y/z``.
`group` selects a struct (dotted path, e.g. ``"rec.bench"``) whose fields are read instead.

v7.3 files are HDF5 files with a 512-byte MATLAB header (userblock). Each variable is a dataset
carrying the attribute ``MATLAB_class`` (``double``, ``single``, ``int16`` …, ``char`` as
UTF-16 codes, ``cell`` as object references into ``#refs#``, ``struct`` as a group) and is
stored transposed (MATLAB is column-major): an ``m×n`` MATLAB array has HDF5 shape ``(n, m)``.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import scipy.io
from scipy.io.matlab import MatReadError

from ..errors import RecordError, UnreadableFileError
from .record import Record
from .values import records_from_arrays

_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_NUMERIC = {"double", "single", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32",
            "uint64", "logical"}
#: Exceptions scipy.io.loadmat raises on corrupt or truncated files.
_V5_ERRORS = (MatReadError, ValueError, TypeError, EOFError, OSError, IndexError, KeyError,
              struct.error, zlib.error, UnicodeError, OverflowError, NotImplementedError,
              AttributeError)


def is_v73(path: Path) -> bool:
    """Whether a ``.mat`` file is v7.3 (HDF5 signature after the 512-byte header)."""
    with open(path, "rb") as f:
        head = f.read(520)
    return head[512:520] == _HDF5_SIGNATURE or head[:8] == _HDF5_SIGNATURE


def has_matlab_header(path: Path) -> bool:
    """Whether a file starts with MATLAB's v7.3 text header (an HDF5 file written by MATLAB)."""
    with open(path, "rb") as f:
        return f.read(19) == b"MATLAB 7.3 MAT-file"


def _descend(tree: dict[str, Any], group: str | None, where: str) -> dict[str, Any]:
    if group is None:
        return tree
    node: Any = tree
    for part in group.split("."):
        if not isinstance(node, dict) or part not in node:
            keys = sorted(node) if isinstance(node, dict) else []
            raise RecordError(f"{where}: struct {group!r} not found (at {part!r}; fields: {keys})")
        node = node[part]
    if not isinstance(node, dict):
        raise RecordError(f"{where}: {group!r} is not a struct; pass the struct holding the "
                          "signals as group=")
    return node


def _read_v5(path: Path, where: str) -> dict[str, Any]:
    try:
        tree = scipy.io.loadmat(path, squeeze_me=True, simplify_cells=True)
    except _V5_ERRORS as e:
        raise UnreadableFileError(f"{where}: not a readable MATLAB file ({type(e).__name__}: "
                                  f"{e})") from None
    return {k: v for k, v in tree.items() if not k.startswith("__")}


def _decode_char(arr: np.ndarray) -> str | list[str]:
    codes = np.asarray(arr).T  # MATLAB rows
    if codes.ndim == 1 or codes.shape[0] == 1:
        return "".join(chr(int(c)) for c in codes.reshape(-1) if 0 < int(c) < 0x110000)
    return ["".join(chr(int(c)) for c in row if 0 < int(c) < 0x110000).rstrip() for row in codes]


def _h5_value(f: Any, obj: Any, where: str, depth: int = 0) -> Any:
    import h5py

    if depth > 8:
        raise UnreadableFileError(f"{where}: MATLAB structure nested too deeply")
    if obj is None:  # a dangling link in a damaged file
        raise UnreadableFileError(f"{where}: damaged MATLAB v7.3 file (a variable points "
                                  "nowhere)")
    cls = obj.attrs.get("MATLAB_class", b"")
    cls = cls.decode() if isinstance(cls, bytes) else str(cls)
    if isinstance(obj, h5py.Group):
        return {k: _h5_value(f, v, where, depth + 1) for k, v in obj.items()
                if not k.startswith("#")}
    if int(np.asarray(obj.attrs.get("MATLAB_empty", 0)).reshape(-1)[0]):
        return np.zeros(0)
    value = obj[()]
    if cls == "char":
        return _decode_char(value)
    if cls == "cell":
        refs = np.asarray(value).T.reshape(-1)
        items = [_h5_value(f, f[r], where, depth + 1) for r in refs]
        return items
    if cls in _NUMERIC or (cls == "" and np.asarray(value).dtype.kind in "biuf"):
        a = np.asarray(value)
        if a.dtype.names:
            raise UnreadableFileError(f"{where}: {obj.name} is complex; store real signals")
        return a.T
    return None  # unsupported class (function handles, objects): ignored


def _read_v73(path: Path, where: str) -> dict[str, Any]:
    import h5py

    try:
        with h5py.File(path, "r") as f:
            return {k: _h5_value(f, v, where) for k, v in f.items() if not k.startswith("#")}
    except (OSError, KeyError, ValueError, RuntimeError, TypeError, IndexError) as e:
        raise UnreadableFileError(f"{where}: not a readable MATLAB v7.3 (HDF5) file "
                                  f"({type(e).__name__}: {e})") from None


def read(
    path: Path, *, sample_rate: float | None, time_column: str | int | None, group: str | None
) -> Record:
    """Read a ``.mat`` file (any version). **Returns:** a record (units from ``units``)."""
    where = str(path)
    v73 = is_v73(path)
    tree = _read_v73(path, where) if v73 else _read_v5(path, where)
    node = _descend(tree, group, where)
    arrays = {k: v for k, v in node.items() if not isinstance(v, dict) and v is not None}
    if not node:
        raise UnreadableFileError(f"{where}: the file holds no variables")
    clean: dict[str, np.ndarray] = {}
    for k, v in arrays.items():
        if isinstance(v, (list, tuple)):
            clean[k] = np.asarray([str(x) for x in v], dtype=str)
        elif isinstance(v, str):
            clean[k] = np.asarray(v)
        else:
            clean[k] = np.asarray(v)
    if not clean and len([v for v in node.values() if isinstance(v, dict)]) >= 1:
        structs = sorted(k for k, v in node.items() if isinstance(v, dict))
        raise RecordError(f"{where}: the signals are inside structs {structs}; pass group= "
                          "one of them")
    return records_from_arrays(clean, where=where, sample_rate=sample_rate,
                               time_column=time_column,
                               metadata={"matlab_version": "7.3" if v73 else "5"})
