"""The plan of a fleet run: what is done already, and the rest cut into tasks."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from dtwin.errors import OutputExistsError

from .identity import RecordJob, _make_job, read_fleet_manifest
from .settings import FleetSettings
from .store import _read_json, _result_path


@dataclasses.dataclass
class _Plan:
    fit_tasks: list[list[RecordJob]]
    discover_jobs: list[tuple[RecordJob, dict[str, Any]]]
    skipped: list[RecordJob]
    jobs: list[RecordJob]


def plan(paths: Sequence[str | os.PathLike], out: str | os.PathLike, settings: FleetSettings,
         spec_data: Mapping[str, Any], *, manifest: str | os.PathLike | None = None,
         force: bool = False) -> _Plan:
    """Read every record's identity, find what `out` already holds, and cut the rest into
    tasks (module docstring). **Raises:** `OutputExistsError` when `out` holds results of other
    settings or another spec for these records (unless `force`: they are redone)."""
    out = Path(out)
    man = read_fleet_manifest(manifest) if manifest is not None else None
    fp = settings.fingerprint(spec_data)
    jobs = [_make_job(Path(p), man) for p in paths]
    todo: list[RecordJob] = []
    skipped: list[RecordJob] = []
    discover_jobs: list[tuple[RecordJob, dict[str, Any]]] = []
    other = []
    for job in jobs:
        prev = _read_json(_result_path(out, job.key))
        if prev is not None and prev.get("settings_fingerprint") != fp:
            other.append(job.path)
        if (prev is not None and prev.get("status") == "ok" and prev.get("sha256") == job.sha256
                and prev.get("settings_fingerprint") == fp):
            skipped.append(job)
            if settings.discover and _read_json(_result_path(out, job.key, "discover")) is None:
                discover_jobs.append((job, prev))
        else:
            todo.append(job)
    if other and not force:
        raise OutputExistsError(
            f"{out} holds results of other fit settings or another spec for {len(other)} of "
            f"these records (e.g. {other[0]}); choose another --out or pass --force to refit them")
    groups: dict[tuple, list[RecordJob]] = {}
    for job in todo:
        groups.setdefault((job.sample_rate or 0.0, job.n_samples or 0), []).append(job)
    tasks = []
    for members in groups.values():
        for i in range(0, len(members), settings.batch_size):
            tasks.append(members[i: i + settings.batch_size])
    return _Plan(tasks, discover_jobs, skipped, jobs)

