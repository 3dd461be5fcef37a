"""Delimited text records: CSV (``,`` or ``;``), TSV (tab) and whitespace-separated ``.txt``.

Layout: an optional header row of column labels (``acc1_x [m/s^2]`` or ``acc (g)`` give the
unit in brackets), then one row per sample. Lines starting with ``#`` are comments. A column
named ``time``/``t``/``time_s`` (or given by `time_column`) is the time axis in seconds (``[ms]``
and ``[us]`` labels are converted) and gives the sampling rate ``(n - 1) / (t_end - t_0)``;
without one, pass `sample_rate`. Without a header row the columns are named ``ch0, ch1, …``.
"""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np

from ..errors import ChannelError, RecordError, UnreadableFileError
from .record import Record
from .values import is_time_name, rate_from_time, resolve_rate, split_name_unit, time_to_seconds


def _delimiter(line: str, suffix: str) -> str | None:
    if "\t" in line or suffix == ".tsv":
        return "\t"
    if ";" in line and "," not in line:
        return ";"
    if "," in line or suffix == ".csv":
        return ","
    return None  # whitespace


def _is_number(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def _parse_rows(body: list[str], delim: str | None, n_col: int, offset: int,
                where: str) -> np.ndarray:
    """Numbers of the data lines, shape (lines, columns); numpy's parser first (fast), then a
    line-by-line pass that names the first bad line if numpy refuses the text."""
    if not body:
        return np.empty((0, n_col))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            rows = np.loadtxt(io.StringIO("\n".join(body)), delimiter=delim, ndmin=2,
                              dtype=np.float64, comments=None)
        if rows.shape == (len(body), n_col):
            return rows
    except (ValueError, UserWarning):
        pass
    rows = np.empty((len(body), n_col), dtype=np.float64)
    for k, line in enumerate(body):
        toks = line.split(delim) if delim else line.split()
        if len(toks) != n_col:
            raise UnreadableFileError(
                f"{where}: data line {k + 1 + offset} has {len(toks)} fields, the header has "
                f"{n_col}; the file may be truncated or use another delimiter"
            )
        try:
            rows[k] = [float(tok) for tok in toks]
        except ValueError:
            raise UnreadableFileError(
                f"{where}: data line {k + 1 + offset} holds a value that is not a number: "
                f"{line[:80]!r}"
            ) from None
    return rows


def read(
    path: Path, *, sample_rate: float | None, time_column: str | int | None, group: str | None
) -> Record:
    """Read a delimited text file. **Returns:** a record (units from the header, else empty)."""
    where = str(path)
    if group is not None:
        raise RecordError(f"{where}: text files have no groups; drop group={group!r}")
    try:
        with open(path, encoding="utf-8-sig", newline="") as f:
            text = f.read()
    except UnicodeDecodeError as e:
        raise UnreadableFileError(
            f"{where}: not a UTF-8 text file ({e.reason} at byte {e.start}); is it really "
            "CSV/TSV? Use the matching extension for binary formats"
        ) from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise UnreadableFileError(f"{where}: the file is empty (no header, no samples)")
    delim = _delimiter(lines[0], path.suffix.lower())
    first = [tok.strip() for tok in (lines[0].split(delim) if delim else lines[0].split())]
    has_header = not all(_is_number(tok) for tok in first if tok)
    if has_header:
        labels = [split_name_unit(tok) for tok in first]
        body = lines[1:]
    else:
        labels = [(f"ch{i}", "") for i in range(len(first))]
        body = lines
    names = [n for n, _ in labels]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise UnreadableFileError(f"{where}: duplicate column names {dup}; rename them")
    n_col = len(labels)
    rows = _parse_rows(body, delim, n_col, int(has_header), where)
    meta: dict = {"header": has_header, "delimiter": delim or "whitespace"}
    time_idx: int | None = None
    if time_column is not None:
        if isinstance(time_column, int):
            if not -n_col <= time_column < n_col:
                raise ChannelError(f"{where}: time column index {time_column} out of range "
                                   f"(the file has {n_col} columns)")
            time_idx = time_column % n_col
        elif time_column in names:
            time_idx = names.index(time_column)
        else:
            raise ChannelError(f"{where}: time column {time_column!r} not found; columns are "
                               f"{names}")
    else:
        for i, nm in enumerate(names):
            if is_time_name(nm):
                time_idx = i
                break
    file_rate = None
    if time_idx is not None:
        t = time_to_seconds(rows[:, time_idx], labels[time_idx][1], where)
        info = rate_from_time(t, where)
        info["name"] = names[time_idx]
        meta["time_column"] = info
        file_rate = info["rate"]
        meta["file_sample_rate"] = file_rate
    rate = resolve_rate(file_rate, sample_rate, where)
    keep = [i for i in range(n_col) if i != time_idx]
    if not keep:
        raise UnreadableFileError(f"{where}: the file holds only a time column, no signals")
    return Record(
        data=rows[:, keep].T.copy(),
        sample_rate=rate,
        channels=tuple(names[i] for i in keep),
        units=tuple(labels[i][1] for i in keep),
        metadata=meta,
    )
