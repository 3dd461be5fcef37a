"""The fleet table: one row per record, gathered from the results folder (Parquet or CSV)."""

from __future__ import annotations

import csv
import datetime as _dt
import io
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from dtwin.errors import OutputExistsError, SettingsError
from dtwin.io.output import atomic_write_bytes

from .settings import TABLE_NAME
from .store import load_results


def _pyarrow_available() -> bool:
    try:
        import pyarrow  # noqa: F401  (optional extra, imported only to test for it)
        import pyarrow.parquet  # noqa: F401
    except ImportError:
        return False
    return True


def table_rows(results: Sequence[Mapping[str, Any]]) -> tuple[list[dict[str, Any]], list[str]]:
    """Flat rows of the fleet table, one per record, and the parameter names (union).

    Columns: ``record, machine, timestamp, status, converged, loss, gap_db, f_sun,
    iterations, lack_of_fit, widened`` (the loss over the loss the noise alone leaves, and the
    factor every interval was widened by for it, :mod:`dtwin.identify.uncertainty`),
    ``excitation`` (the end of a calibrated spec's excitation/response split reported,
    :mod:`dtwin.identify.split`; empty where one was fitted), per
    parameter ``<name>, <name>_lo95, <name>_hi95, <name>_determined``, then
    ``effects`` (discovered effects, ``;``-joined), ``discover_gap_initial_db``,
    ``discover_gap_final_db``, ``discover_status``, ``error``, ``key``, ``sha256``."""
    names: list[str] = []
    for r in results:
        for n in r.get("names", []):
            if n not in names:
                names.append(n)
    rows = []
    for r in results:
        ok = r.get("status") == "ok"
        row: dict[str, Any] = {
            "record": r.get("record"), "machine": r.get("machine"),
            "timestamp": r.get("timestamp"), "status": r.get("status"),
            "converged": bool(r.get("converged")) if ok else None,
            "loss": _num(r.get("loss")), "gap_db": _num(r.get("gap_db")),
            "f_sun": _num(r.get("f_sun")), "iterations": r.get("iterations"),
        }
        unc = (r.get("fit") or {}).get("uncertainty") or {}
        row["lack_of_fit"] = _num(unc.get("lack_of_fit"))
        row["widened"] = _num(unc.get("widened"))
        row["excitation"] = r.get("excitation") or None
        iv = r.get("intervals_95", {}) or {}
        nd = r.get("not_determined", {}) or {}
        for n in names:
            v = (r.get("values") or {}).get(n)
            row[n] = _num(v)
            lo, hi = iv.get(n, (None, None))
            row[f"{n}_lo95"], row[f"{n}_hi95"] = _num(lo), _num(hi)
            row[f"{n}_determined"] = (n not in nd) if (ok and n in (r.get("values") or {})) \
                else None
        d = r.get("discovery") or {}
        row["effects"] = ";".join(d.get("effects", [])) if d.get("status") == "ok" else None
        row["discover_gap_initial_db"] = _num(d.get("gap_initial_db"))
        row["discover_gap_final_db"] = _num(d.get("gap_final_db"))
        row["discover_status"] = d.get("status")
        row["error"] = None if ok else f"{r.get('error_type')}: {r.get('error')}"
        row["key"], row["sha256"] = r.get("key"), r.get("sha256")
        rows.append(row)
    return rows, names


def _num(v: Any) -> float | None:
    if v is None:
        return None
    try:
        return float(v)
    except (TypeError, ValueError):
        return None


def _table_target(out: Path, name: str, force: bool) -> Path:
    target = out / name
    if force or not target.exists():
        return target
    stem, dot, ext = name.partition(".")
    stamp = _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%S%fZ")
    return out / f"{stem}-{stamp}{dot}{ext}"


def write_table(out: str | os.PathLike, path: str | os.PathLike | None = None, *,
                force: bool = False, fmt: str = "auto") -> tuple[Path, str | None]:
    """Gather the results in `out` into one table (:func:`table_rows`).

    Parquet (``pyarrow``; timestamps as UTC ``timestamp[us]``) or, without pyarrow or with
    ``fmt="csv"``, CSV. Written to `path` (default ``out/table.parquet``); an existing table is
    never overwritten without `force`: the rebuilt table goes to a new, time-stamped file next to
    it. **Returns:** ``(path written, note or None)`` — the note says when CSV replaced
    Parquet."""
    out = Path(out)
    rows, _ = table_rows(load_results(out))
    note = None
    if fmt not in ("auto", "parquet", "csv"):
        raise SettingsError(f"fmt must be auto, parquet or csv, got {fmt!r}")
    use_parquet = fmt != "csv" and _pyarrow_available()
    if fmt == "parquet" and not use_parquet:
        raise ImportError("Parquet needs pyarrow: pip install 'dtwin[fleet]'")
    if not use_parquet and fmt == "auto":
        note = "pyarrow is not installed: the table is CSV (pip install 'dtwin[fleet]')"
    if path is None:
        name = TABLE_NAME if use_parquet else TABLE_NAME.replace(".parquet", ".csv")
        target = _table_target(out, name, force)
    else:
        target = Path(path)
        if target.exists() and not force:
            raise OutputExistsError(f"{target} exists; pass --force to overwrite it")
    if use_parquet:
        # pyarrow: optional extra (dtwin[fleet]), imported when a Parquet table is written
        import pyarrow as pa
        import pyarrow.parquet as pq

        cols = list(rows[0]) if rows else ["record", "machine", "timestamp", "status"]
        data = {c: [r.get(c) for r in rows] for c in cols}
        if "timestamp" in data:
            data["timestamp"] = [None if t is None else _dt.datetime.fromisoformat(t)
                                 for t in data["timestamp"]]
        arrays = {}
        for c, vals in data.items():
            if c == "timestamp":
                arrays[c] = pa.array(vals, type=pa.timestamp("us", tz="UTC"))
            elif all(v is None or isinstance(v, bool) for v in vals) and any(
                    isinstance(v, bool) for v in vals):
                arrays[c] = pa.array(vals, type=pa.bool_())
            elif all(v is None or isinstance(v, (int, float)) and not isinstance(v, bool)
                     for v in vals) and any(v is not None for v in vals):
                arrays[c] = pa.array([None if v is None else float(v) for v in vals],
                                     type=pa.float64())
            else:
                arrays[c] = pa.array([None if v is None else str(v) for v in vals],
                                     type=pa.string())
        tbl = pa.table(arrays)
        buf = io.BytesIO()
        pq.write_table(tbl, buf)
        atomic_write_bytes(target, buf.getvalue(), force=True)
    else:
        buf = io.StringIO()
        cols = list(rows[0]) if rows else ["record", "machine", "timestamp", "status"]
        w = csv.DictWriter(buf, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow({k: "" if v is None else v for k, v in r.items()})
        atomic_write_bytes(target, buf.getvalue().encode(), force=True)
    return target, note
