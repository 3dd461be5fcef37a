"""Record identity in a fleet run: which files, which machine and time each belongs to (fleet
manifest CSV, record metadata or folder), the file-name key of its results and its hash."""

from __future__ import annotations

import csv
import dataclasses
import datetime as _dt
import glob
import hashlib
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from dtwin.errors import DtwinError, RecordError, UnreadableFileError
from dtwin.io.output import sha256_file
from dtwin.io.readers import read_record


def expand_records(patterns: Iterable[str | os.PathLike]) -> list[Path]:
    """Record files matching glob `patterns` (``**`` recursive) or naming files, sorted and
    without duplicates. **Raises:** `RecordError` when nothing matches."""
    seen: dict[str, Path] = {}
    for pat in patterns:
        s = str(pat)
        hits = sorted(glob.glob(s, recursive=True)) if glob.has_magic(s) else [s]
        for h in hits:
            p = Path(h)
            if p.is_dir():
                continue
            seen.setdefault(str(p.resolve()), p)
    if not seen:
        raise RecordError(f"no record file matches {[str(p) for p in patterns]}; quote the "
                          "pattern so that the shell does not expand it ('records/**/*.h5')")
    return sorted(seen.values(), key=lambda p: str(p))


def _parse_timestamp(value: Any, where: str) -> str | None:
    """ISO 8601 UTC string of a timestamp (ISO text, naive = UTC; or epoch seconds)."""
    if value is None or (isinstance(value, str) and not value.strip()):
        return None
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        t = _dt.datetime.fromtimestamp(float(value), _dt.UTC)
    else:
        text = str(value).strip()
        try:
            t = _dt.datetime.fromtimestamp(float(text), _dt.UTC)
        except ValueError:
            try:
                t = _dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
            except ValueError:
                raise RecordError(f"{where}: timestamp {text!r} is neither ISO 8601 "
                                  "(2026-11-22T03:30:00Z) nor seconds since the epoch") from None
            if t.tzinfo is None:
                t = t.replace(tzinfo=_dt.UTC)
    return t.astimezone(_dt.UTC).isoformat()


def read_fleet_manifest(path: str | os.PathLike) -> dict[str, dict[str, str | None]]:
    """A fleet manifest CSV (header ``path,machine,timestamp``) → ``{resolved path: {machine,
    timestamp}}``; relative paths are taken relative to the CSV's folder.

    **Raises:** `RecordError` for a missing column, an empty machine or a bad timestamp."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as e:
        raise UnreadableFileError(f"fleet manifest {path}: {e}") from None
    rows = list(csv.DictReader(text.splitlines()))
    need = {"path", "machine", "timestamp"}
    have = {c.strip().lower() for c in (rows[0].keys() if rows else [])}
    if not rows or not need <= have:
        raise RecordError(f"fleet manifest {path} needs a header with the columns "
                          f"{sorted(need)} and one row per record; found {sorted(have)}")
    out: dict[str, dict[str, str | None]] = {}
    for i, row in enumerate(rows, start=2):
        row = {k.strip().lower(): (v or "").strip() for k, v in row.items() if k}
        p = Path(row["path"])
        if not p.is_absolute():
            p = path.parent / p
        if not row["machine"]:
            raise RecordError(f"fleet manifest {path}, line {i}: empty machine")
        out[str(p.resolve())] = {
            "machine": row["machine"],
            "timestamp": _parse_timestamp(row["timestamp"], f"{path}, line {i}"),
        }
    return out


def result_key(path: str | os.PathLike) -> str:
    """File-name key of a record's results: its name without extensions and 10 hex digits of
    the SHA-1 of its resolved path (two ``day1.h5`` of two machines do not collide)."""
    p = Path(path)
    stem = p.name.split(".")[0] or "record"
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in stem)[:60]
    return f"{safe}-{hashlib.sha1(str(p.resolve()).encode()).hexdigest()[:10]}"


def _sha256(path: Path) -> str:
    return sha256_file(path)


@dataclasses.dataclass(frozen=True)
class RecordJob:
    """One record of a fleet run: `path` (as given), `key` (:func:`result_key`), `machine`,
    `timestamp` (ISO UTC or None), `identity_source` (``manifest``, ``metadata``, ``folder``),
    `sha256`, `sample_rate` (Hz) and `n_samples` (None when the driver could not read it:
    the task then reports why)."""

    path: str
    key: str
    machine: str
    timestamp: str | None
    identity_source: str
    sha256: str
    sample_rate: float | None
    n_samples: int | None

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def _make_job(path: Path, manifest: Mapping[str, Mapping[str, Any]] | None) -> RecordJob:
    rate = n = None
    meta: dict[str, Any] = {}
    try:
        rec = read_record(path)
        rate, n = float(rec.sample_rate), int(rec.n_samples)
        meta = rec.metadata if isinstance(rec.metadata, dict) else {}
    except DtwinError:
        pass  # the task reads it again and reports the error for this record
    entry = (manifest or {}).get(str(path.resolve()))
    if entry is not None:
        machine, ts, src = str(entry["machine"]), entry.get("timestamp"), "manifest"
    elif meta.get("machine"):
        machine, src = str(meta["machine"]), "metadata"
        ts = _parse_timestamp(meta.get("timestamp"), str(path))
    else:
        machine, src = path.resolve().parent.name or "unknown", "folder"
        ts = _parse_timestamp(meta.get("timestamp"), str(path)) if meta.get("timestamp") else None
    return RecordJob(str(path), result_key(path), machine, ts, src, _sha256(path), rate, n)
