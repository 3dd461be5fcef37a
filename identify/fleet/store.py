"""The results folder of a fleet run: where each record's result and failure live, atomic
writes of finished entries (driver side), and reading the results back."""

from __future__ import annotations

import datetime as _dt
import json
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from dtwin.io.output import atomic_write_bytes, to_jsonable

from .settings import SCHEMA


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def _records_dir(out: Path) -> Path:
    return out / "records"


def _result_path(out: Path, key: str, kind: str = "fit") -> Path:
    return _records_dir(out) / (f"{key}.json" if kind == "fit" else f"{key}.discover.json")


def _failed_path(out: Path, key: str, kind: str = "fit") -> Path:
    return out / "failed" / (f"{key}.json" if kind == "fit" else f"{key}.discover.json")


def _read_json(path: Path) -> dict[str, Any] | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None  # missing or torn (never, with atomic writes): the record is redone


def _write_json(path: Path, obj: Mapping[str, Any]) -> Path:
    return atomic_write_bytes(path, json.dumps(to_jsonable(obj), indent=1).encode(), force=True)


def load_results(out: str | os.PathLike, *, failed: bool = True) -> list[dict[str, Any]]:
    """Every per-record fit result in the results folder `out` (with its discovery under
    ``"discovery"`` when there is one), then, with `failed`, the failure entries of records
    without a result. Sorted by machine, timestamp, record."""
    out = Path(out)
    rows: list[dict[str, Any]] = []
    done: set[str] = set()
    for p in sorted(_records_dir(out).glob("*.json")):
        if p.name.endswith(".discover.json"):
            continue
        d = _read_json(p)
        if d is None or d.get("schema") != SCHEMA:
            continue
        disc = _read_json(_result_path(out, d["key"], "discover"))
        dfail = _read_json(_failed_path(out, d["key"], "discover"))
        d["discovery"] = disc if disc is not None else dfail
        rows.append(d)
        done.add(d["key"])
    if failed:
        for p in sorted((out / "failed").glob("*.json")):
            if p.name.endswith(".discover.json"):
                continue
            d = _read_json(p)
            if d is not None and d.get("key") not in done:
                rows.append(d)
    rows.sort(key=lambda r: (str(r.get("machine")), str(r.get("timestamp") or ""),
                             str(r.get("record"))))
    return rows


class _Writer:
    """Writes each finished entry atomically and keeps the counts (driver side)."""

    def __init__(self, out: Path, on_result: Callable[[dict[str, Any]], None] | None):
        self.out = out
        self.on_result = on_result
        self.fitted = self.failed = self.discovered = self.discover_failed = 0
        self.failures: list[dict[str, Any]] = []

    def __call__(self, entry: dict[str, Any]) -> None:
        kind, key = entry.get("kind", "fit"), entry["key"]
        if entry["status"] == "ok":
            _write_json(_result_path(self.out, key, kind), entry)
            fp = _failed_path(self.out, key, kind)
            if fp.exists():
                fp.unlink()
            if kind == "fit":
                self.fitted += 1
            else:
                self.discovered += 1
        else:
            _write_json(_failed_path(self.out, key, kind), entry)
            self.failures.append(entry)
            if kind == "fit":
                self.failed += 1
            else:
                self.discover_failed += 1
        if self.on_result is not None:
            self.on_result(entry)

