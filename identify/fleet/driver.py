"""The driver of a fleet run (:func:`run_fleet`): plan, run on an engine, write the run
manifest and the table."""

from __future__ import annotations

import dataclasses
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from dtwin.errors import SettingsError
from dtwin.io.output import versions
from dtwin.spec import Spec, load_spec, spec_to_dict

from ..fit import check_free
from . import ray_engine
from .identity import expand_records
from .local_engine import _run_local
from .plan import plan
from .settings import FAIL_ENV, FleetSettings
from .store import _now, _write_json, _Writer
from .table import write_table


@dataclasses.dataclass
class FleetRun:
    """Outcome of :func:`run_fleet`: counts, the engine used, the table written, timings."""

    out: Path
    engine: str
    records: int
    skipped: int
    fitted: int
    failed: int
    discovered: int
    discover_failed: int
    table: Path | None
    wall_time_s: float
    failures: list[dict[str, Any]]
    notes: list[str]

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["out"] = str(self.out)
        d["table"] = None if self.table is None else str(self.table)
        return d



def _engine(engine: str, address: str | None) -> tuple[str, list[str]]:
    """The engine `run_fleet` runs on (``auto``: Ray where installed or a cluster is named,
    else local) and a note when ``auto`` falls back to local."""
    if engine not in ("auto", "ray", "local"):
        raise SettingsError(f"engine must be auto, ray or local, got {engine!r}")
    notes: list[str] = []
    if engine == "auto":
        engine = "ray" if (ray_engine.ray_available() or address) else "local"
        if engine == "local":
            notes.append("Ray is not installed: records run one after another in this process "
                         "(pip install 'dtwin[fleet]' for Ray)")
    if engine == "ray" and not ray_engine.ray_available():
        raise ImportError("engine 'ray' needs Ray: pip install 'dtwin[fleet]' (ray>=2.9), or "
                          "run without --ray-address for the local engine")
    return engine, notes


def run_fleet(
    records: Sequence[str | os.PathLike],
    spec,
    out: str | os.PathLike,
    settings: FleetSettings = FleetSettings(),
    *,
    manifest: str | os.PathLike | None = None,
    engine: str = "auto",
    address: str | None = None,
    num_cpus: int | None = None,
    progress: bool = True,
    force: bool = False,
    table: bool = True,
    on_result: Callable[[dict[str, Any]], None] | None = None,
    command: Sequence[str] | None = None,
) -> FleetRun:
    """Identify every record of a fleet (module docstring).

    **Arguments:**

    - `records`: record paths or glob patterns (``records/**/*.dtwin.h5``).
    - `spec`: the gearbox spec (`dtwin.spec.Spec`, path or mapping), one for the fleet.
    - `out`: the results folder (created; re-used by a re-run, which skips what is done).
    - `settings`: :class:`FleetSettings`.
    - `manifest`: a fleet manifest CSV (``path, machine, timestamp``).
    - `engine`: ``auto`` (Ray if installed), ``ray`` or ``local`` (one after another here).
    - `address`: an existing Ray cluster (``ray://host:10001`` or ``auto``); `num_cpus`: CPUs
      of a local Ray started here (default: all).
    - `progress`: a rich progress bar over records (stderr).
    - `force`: refit records whose results were made with other settings, and write the table
      over an existing one.
    - `table`: gather the table at the end (:func:`write_table`).
    - `on_result`: called with every entry as soon as it is written (driver side).
    - `command`: the command line for the run manifest (default ``sys.argv``).

    **Returns:** :class:`FleetRun`. **Raises:** `OutputExistsError` (other settings in `out`),
    `RecordError` (no record matches), `ImportError` (``engine="ray"`` without Ray).
    """
    t0 = time.perf_counter()
    check_free(list(settings.free))  # unknown names fail before anything is read
    engine, notes = _engine(engine, address)
    spec = spec if isinstance(spec, Spec) else load_spec(spec)
    spec_data = spec_to_dict(spec)
    settings = settings.resolved(spec_data)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = expand_records(records)
    pl = plan(paths, out, settings, spec_data, manifest=manifest, force=force)
    fp = settings.fingerprint(spec_data)
    inject = os.environ.get(FAIL_ENV) or None
    attempts_dir = str(out / ".attempts") if inject else None
    writer = _Writer(out, on_result)
    started = _now()
    run_doc = {"started": started, "command": list(sys.argv if command is None else command),
               "engine": engine, "address": address, "settings": settings.to_dict(),
               "settings_fingerprint": fp, "spec": spec_data, "manifest": None if manifest is None
               else str(manifest), "records": [j.to_dict() for j in pl.jobs],
               "versions": versions(), "status": "running"}
    run_path = out / "runs" / f"{started.replace(':', '').replace('+0000', 'Z')}-{os.getpid()}.json"
    _write_json(run_path, run_doc)
    status = "interrupted"
    try:
        if engine == "ray":
            ray_engine._run_ray(pl, spec_data, settings, fp, writer, inject, attempts_dir, progress,
                     address, num_cpus, notes)
        else:
            _run_local(pl, spec_data, settings, fp, writer, inject, attempts_dir, progress)
        status = "finished"
    finally:
        run_doc.update(status=status, finished=_now(), skipped=len(pl.skipped),
                       fitted=writer.fitted, failed=writer.failed,
                       discovered=writer.discovered, discover_failed=writer.discover_failed,
                       notes=notes)
        _write_json(run_path, run_doc)
    table_path = None
    if table:
        table_path, tnote = write_table(out, force=force)
        if tnote:
            notes.append(tnote)
    return FleetRun(out, engine, len(pl.jobs), len(pl.skipped), writer.fitted, writer.failed,
                    writer.discovered, writer.discover_failed, table_path,
                    time.perf_counter() - t0, writer.failures, notes)

