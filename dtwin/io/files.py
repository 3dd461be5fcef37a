"""Result files at the lowest level: atomic writes, SHA-256 of inputs, JSON-able values.

Used by the result folders (:mod:`dtwin.io.output`), the record writer
(:mod:`dtwin.io.fmt_native`) and fleet runs; it imports nothing of dtwin's but its errors, so
that every writer can use it without import circles.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import tempfile
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import OutputExistsError


def sha256_file(path: str | os.PathLike, chunk: int = 1 << 20) -> str:
    """SHA-256 hex digest of a file, read in chunks (read-only)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def to_jsonable(obj: Any) -> Any:
    """Convert numpy/JAX arrays and scalars, paths and dataclasses to JSON-compatible values."""
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (str, bool)) or obj is None:
        return obj
    if isinstance(obj, int):
        return obj
    if isinstance(obj, float):
        return obj if np.isfinite(obj) else str(obj)
    if isinstance(obj, Path):
        return str(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return to_jsonable(dataclasses.asdict(obj))
    if hasattr(obj, "__array__") or isinstance(obj, np.generic):
        arr = np.asarray(obj)
        if arr.dtype.kind in "fc":
            arr = np.where(np.isfinite(arr), arr, np.nan) if arr.dtype.kind == "f" else arr
        val = arr.tolist()
        return _nan_to_str(val)
    if isinstance(obj, Iterable):
        return [to_jsonable(v) for v in obj]
    return str(obj)


def _nan_to_str(val: Any) -> Any:
    if isinstance(val, float):
        return val if val == val and abs(val) != float("inf") else str(val)
    if isinstance(val, list):
        return [_nan_to_str(v) for v in val]
    if isinstance(val, complex):
        return [val.real, val.imag]
    return val


def _default_mode() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def publish(tmp: str | os.PathLike, path: str | os.PathLike) -> None:
    """Give a finished temporary file the usual permissions (``mkstemp`` makes it 0600) and
    rename it onto `path` atomically."""
    os.chmod(tmp, _default_mode())
    os.replace(tmp, path)


def atomic_write_bytes(path: str | os.PathLike, data: bytes, *, force: bool = False) -> Path:
    """Write `data` to `path` atomically (temporary file in the same folder, then rename).

    Raises `OutputExistsError` if `path` exists and `force` is false.
    """
    path = Path(path)
    if path.exists() and not force:
        raise OutputExistsError(
            f"{path} already exists; choose another output folder or pass --force to overwrite"
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        publish(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path
