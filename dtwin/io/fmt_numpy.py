"""NumPy records: ``.npy`` (one array) and ``.npz`` (named arrays), loaded without pickle.

- ``.npy``: a 1-D array (one channel) or a 2-D array with channels along the shorter axis;
  channels are named ``ch0, ch1, …``; `sample_rate` must be given (a ``.npy`` holds no rate).
- ``.npz``: ``data`` (+ ``channels``, ``units`` string arrays) or one named 1-D array per
  channel, with ``sample_rate`` (or ``fs``) as a scalar and optionally ``time``; see
  :func:`dtwin.io.readers.records_from_arrays` for the rules.
"""

from __future__ import annotations

import tokenize
import zipfile
import zlib
from pathlib import Path

import numpy as np

from ..errors import RecordError, UnreadableFileError
from .record import Record
from .values import records_from_arrays

#: Exceptions numpy raises on corrupt files (the .npy header is parsed as a Python literal,
#: hence SyntaxError and tokenize errors; .npz is a zip archive).
_LOAD_ERRORS = (ValueError, OSError, EOFError, zipfile.BadZipFile, KeyError, UnicodeError,
                SyntaxError, tokenize.TokenError, MemoryError, OverflowError, NotImplementedError,
                zlib.error)


def read(
    path: Path, *, sample_rate: float | None, time_column: str | int | None, group: str | None
) -> Record:
    """Read ``.npy``/``.npz``. **Returns:** a record (units from ``units`` in npz, else empty)."""
    where = str(path)
    if group is not None:
        raise RecordError(f"{where}: NumPy files have no groups; drop group={group!r}")
    try:
        loaded = np.load(path, allow_pickle=False, mmap_mode=None)
        if isinstance(loaded, np.lib.npyio.NpzFile):
            with loaded:
                arrays = {k: loaded[k] for k in loaded.files}
        else:
            arrays = None
            arr = np.asarray(loaded)
    except _LOAD_ERRORS as e:
        raise UnreadableFileError(
            f"{where}: not a readable NumPy file ({type(e).__name__}: {e}); object arrays "
            "(pickles) are refused for safety: save plain numeric arrays"
        ) from None
    if arrays is not None:
        return records_from_arrays(arrays, where=where, sample_rate=sample_rate,
                                   time_column=time_column, metadata={})
    if time_column is not None:
        raise RecordError(f"{where}: a .npy file has no named time column; pass sample_rate=")
    if arr.ndim == 0 or arr.ndim > 2:
        raise UnreadableFileError(
            f"{where}: array of shape {arr.shape}; expected 1-D or (channels, samples)"
        )
    return records_from_arrays({"data": arr}, where=where, sample_rate=sample_rate,
                               time_column=None, metadata={})
