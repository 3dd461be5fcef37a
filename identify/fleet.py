"""Fleet runs: identify many records of one gearbox type, batched on one machine or as Ray tasks.

A wind farm or a production line records hundreds of gearboxes every day. :func:`run_fleet`
fits every record (:mod:`dtwin.identify.fit`) and keeps one result file per record, so that a fleet
of records becomes a table (:func:`write_table`) and per-machine trends
(:mod:`dtwin.identify.trends`).

**Work units.** Records are read once by the driver (machine, timestamp, SHA-256, length and
rate), grouped by ``(sample rate, samples)`` and cut into tasks of ``batch_size`` records
(:func:`plan`). The residuals are taken in the **order domain** by default
(``FleetSettings.grid="orders"``: :class:`dtwin.identify.residuals.Features` with ``grid="orders"``
and ``f_max``): spectra sampled on a fixed grid of orders of the input speed, harmonics and
solver limits set by the fleet's highest speed ``f_max``, so a problem's shapes and statics
depend only on the record's length and rate — records at different speeds share one compiled
fit. A task (:func:`fit_task`) builds each record's problem
(:func:`dtwin.identify.fit.make_problem`), splits its records by problem *structure*
(:func:`dtwin.identify.fit.stack_problems`' condition: in the order domain, length and rate, so the
split is a no-op after :func:`plan`'s grouping; with ``grid="hz"`` also the speed rounded to
0.1 Hz) and fits each sub-group with :func:`dtwin.identify.fit.fit_batch` (one compiled, ``vmap``-ed
optimistix call, one start θ = 0 per record) or, for a single record, :func:`dtwin.identify.fit.fit`
(multi-start when ``starts > 1``).

**Engines.** ``engine="ray"``: each task is a Ray task (``num_cpus=1``; local Ray started with
``num_cpus`` unless an existing cluster's ``address`` is given, or Ray already initialised),
``max_retries`` for killed workers and ``retry_exceptions=True`` for exceptions. A record that
is wrong in itself (:class:`~dtwin.errors.DtwinError`: unreadable, NaN, too short, fit error) is
*reported*, not retried: the task returns a failure entry for it and fits the others. Any other
exception (a crash, out of memory, an injected failure) is retried by Ray and, when the retries
are spent, reported for every record of the task. ``engine="local"`` runs the same tasks one
after another in this process, with the same retries; ``engine="auto"`` takes Ray when it is
installed.

**Results** (``RESULTS/``): ``records/<key>.json`` per fitted record (schema
``dtwin.fleet.result/1``: identity, values, 95 % intervals, flags, gap, operating point and the
full :meth:`dtwin.identify.fit.FitResult.to_dict`), ``records/<key>.discover.json`` per discovery,
``failed/<key>.json`` for records that failed (removed when they succeed later), ``runs/<UTC
time>.json`` (a manifest per run: command, settings, spec, versions, counts) and the table.
The *driver* writes each file atomically (:func:`dtwin.io.output.atomic_write_bytes`) as soon
as its task finishes, so a killed worker or an interrupted run loses no finished result; a
re-run skips every record whose result exists for the same record bytes (SHA-256) and the same
settings and spec (:meth:`FleetSettings.fingerprint`), and runs only the missing ones.

**Identity.** Machine and timestamp come from the fleet manifest CSV (columns ``path, machine,
timestamp``; paths relative to the CSV's folder or absolute) when one is given, else from the
record's metadata (``machine``, ``timestamp``), else the machine is the record's parent folder
name and the timestamp is unknown. Timestamps are ISO 8601 (a naive time is taken as UTC) or
seconds since the epoch.

**Gap.** ``gap_db`` is :mod:`dtwin.identify.gap`'s level difference applied to the fit's own points:
``sqrt(mean (L_meas − L_model)²)`` in dB over the points standing 12 dB over the measured floor
in either spectrum, at the fitted parameters (in-sample; the held-out gap is discovery's).

**Failure injection** (tests, drills): ``DTWIN_FLEET_FAIL="<substring>[:raise|exit][@N]"`` in
the driver's environment makes the tasks of records whose path contains the substring raise
``RuntimeError`` (``raise``) or kill their worker process (``exit``, Ray only), on the first `N`
attempts (every attempt without ``@N``).
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import glob
import hashlib
import json
import os
import socket
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dtwin.errors import DtwinError, OutputExistsError, RecordError

__all__ = [
    "FleetRun", "FleetSettings", "RecordJob", "SCHEMA", "TABLE_NAME", "discover_task",
    "expand_records", "fit_gap_db", "fit_task", "load_results", "plan", "ray_available",
    "read_fleet_manifest", "result_key", "run_fleet", "table_rows", "write_table",
]

#: Schema tag of a per-record result file.
SCHEMA = "dtwin.fleet.result/1"
#: Default file name of the gathered table (Parquet; ``.csv`` without pyarrow).
TABLE_NAME = "table.parquet"
#: Environment variable of the failure injection (module docstring).
FAIL_ENV = "DTWIN_FLEET_FAIL"
_GAP_THRESHOLD_DB = 12.0


def ray_available() -> bool:
    """Whether Ray can be imported (the optional extra ``dtwin[fleet]``)."""
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


def _pyarrow_available() -> bool:
    try:
        import pyarrow  # noqa: F401
        import pyarrow.parquet  # noqa: F401
    except ImportError:
        return False
    return True


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


# ================================================================================= settings
@dataclasses.dataclass(frozen=True)
class FleetSettings:
    """What is fitted to every record of a fleet, and how the run is cut into tasks.

    - `free`: registry names fitted (e.g. ``("sun_fault",)``); `kind`: the twin
      (``torsional`` or ``translational``); `initial`: ``((name, value), ...)`` starting values
      (SI); `f_sun`: input speed (Hz) for every record (None: estimated from each record).
    - `solver`, `starts`, `refine`, `max_steps`, `tol`, `channel`: as :func:`dtwin.identify.fit.fit`.
    - `grid`: ``orders`` (default: the order domain, module docstring) or ``hz`` (DFT bins, as
      ``dtwin identify``; records batch together only within 0.1 Hz of speed).
    - `order_step`: step of the order grid (orders of the input speed; None: one DFT bin at
      `f_max`); `f_max` (Hz): the highest input speed of the fleet (None: 1.05 × `f_sun`, or
      × the spec's ``operating.f_sun`` — the operating-point search spans ±5 % of it). Both
      are part of the fit settings (a record faster than `f_max` is reported).
    - `batch_size`: records per task, fitted in one ``vmap``-ed call when they share a
      structure (1: one record per task); batching uses one start per record.
    - `max_retries`: retries of a task whose worker died or that raised a non-dtwin exception.
    - `discover`: run :func:`dtwin.identify.discover.discover` on every fitted record (its own task);
      `discover_options`: ``((field, value), ...)`` of
      :class:`dtwin.identify.discover.DiscoverySettings`.
    """

    free: tuple[str, ...] = ("sun_fault",)
    kind: str = "torsional"
    initial: tuple[tuple[str, float], ...] = ()
    f_sun: float | None = None
    solver: str = "lm"
    starts: int = 1
    refine: int = 1
    max_steps: int = 40
    tol: float = 1e-4
    channel: int | str = 0
    grid: str = "orders"
    order_step: float | None = None
    f_max: float | None = None
    batch_size: int = 1
    max_retries: int = 2
    discover: bool = False
    discover_options: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self):
        object.__setattr__(self, "free", tuple(self.free))
        init = self.initial.items() if isinstance(self.initial, Mapping) else self.initial
        object.__setattr__(self, "initial", tuple((str(k), float(v)) for k, v in init))
        opts = (self.discover_options.items() if isinstance(self.discover_options, Mapping)
                else self.discover_options)
        object.__setattr__(self, "discover_options", tuple((str(k), v) for k, v in opts))
        if not self.free:
            raise ValueError("FleetSettings.free: name at least one registry parameter")
        if self.kind not in ("torsional", "translational"):
            raise ValueError(f"FleetSettings.kind must be torsional or translational, got "
                             f"{self.kind!r}")
        if self.grid not in ("orders", "hz"):
            raise ValueError(f"FleetSettings.grid must be orders or hz, got {self.grid!r}")
        if self.grid == "hz" and (self.order_step is not None or self.f_max is not None):
            raise ValueError("FleetSettings.order_step and f_max belong to grid='orders'")
        if self.batch_size < 1:
            raise ValueError(f"FleetSettings.batch_size must be >= 1, got {self.batch_size}")
        if self.max_retries < 0:
            raise ValueError(f"FleetSettings.max_retries must be >= 0, got {self.max_retries}")
        if self.batch_size > 1 and (self.starts > 1 or self.refine > 1):
            raise ValueError("batched fits (batch_size > 1) use one start per record: "
                             "set starts=1, refine=1 or batch_size=1")

    def resolved(self, spec_data: Mapping[str, Any]) -> FleetSettings:
        """These settings with `f_max` filled in (order domain): 1.05 × `f_sun`, or × the
        spec's nominal input speed. **Raises:** `ValueError` when neither is known."""
        if self.grid != "orders" or self.f_max is not None:
            return self
        f = self.f_sun
        if f is None:
            f = (dict(spec_data).get("operating") or {}).get("f_sun")
        if f is None:
            raise ValueError("the order domain needs the fleet's highest speed: pass f_max "
                             "(--f-max), f_sun (--f-sun) or a spec with operating.f_sun")
        return dataclasses.replace(self, f_max=round(1.05 * float(f), 6))

    def fit_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`dtwin.identify.fit.fit` / ``fit_batch`` (without the starts);
        call on :meth:`resolved` settings."""
        from .residuals import Features

        kw: dict[str, Any] = dict(kind=self.kind, solver=self.solver, max_steps=self.max_steps,
                                  tol=self.tol, channel=self.channel, f_sun=self.f_sun)
        if self.initial:
            kw["initial"] = dict(self.initial)
        if self.grid == "orders":
            if self.f_max is None:
                raise ValueError("FleetSettings.fit_kwargs: resolve f_max first (resolved())")
            kw["features"] = Features(grid="orders", f_max=float(self.f_max),
                                      order_step=None if self.order_step is None
                                      else float(self.order_step))
        return kw

    def fingerprint(self, spec_data: Mapping[str, Any]) -> str:
        """SHA-256 (16 hex digits) of everything that changes a fit result: the fit settings
        and the spec (not the batching, retries or discovery)."""
        from dtwin.io.output import to_jsonable

        fit = {k: getattr(self, k) for k in ("free", "kind", "initial", "f_sun", "solver",
                                             "starts", "refine", "max_steps", "tol", "channel",
                                             "grid", "order_step", "f_max")}
        spec = {k: v for k, v in dict(spec_data).items() if k != "source"}
        blob = json.dumps(to_jsonable({"fit": fit, "spec": spec}), sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()[:16]

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["initial"] = dict(self.initial)
        d["discover_options"] = dict(self.discover_options)
        return d


# ================================================================================= inputs
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
    import csv

    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as e:
        from dtwin.errors import UnreadableFileError

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
    from dtwin.io.output import sha256_file

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
    from dtwin.io.readers import read_record

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


# ================================================================================= results dir
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
    from dtwin.io.output import atomic_write_bytes, to_jsonable

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


# ================================================================================= plan
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


# ================================================================================= tasks
def _inject(job: Mapping[str, Any], inject: str | None, attempts_dir: str | None,
            in_ray: bool) -> None:
    """Failure injection (module docstring)."""
    if not inject:
        return
    target, _, times = inject.partition("@")
    target, _, mode = target.partition(":")
    if not target or target not in job["path"]:
        return
    if times:
        marker = Path(attempts_dir or ".") / f"{job['key']}.attempts"
        marker.parent.mkdir(parents=True, exist_ok=True)
        with open(marker, "a") as f:
            f.write("x")
        if marker.stat().st_size > int(times):
            return
    if mode == "exit" and in_ray:
        os._exit(17)
    raise RuntimeError(f"injected failure ({FAIL_ENV}={inject!r}) in the task of {job['path']}")


def _identity(job: Mapping[str, Any]) -> dict[str, Any]:
    return {"record": job["path"], "key": job["key"], "machine": job["machine"],
            "timestamp": job["timestamp"], "identity_source": job["identity_source"],
            "sha256": job["sha256"]}


def failure_entry(job: Mapping[str, Any], error: BaseException | str, *, stage: str,
                  fingerprint: str, kind: str = "fit", attempts: int | None = None
                  ) -> dict[str, Any]:
    """The result entry of a record that failed at `stage` (``read``, ``fit``, ``task``,
    ``discover``) with `error`."""
    if isinstance(error, BaseException):
        etype, msg = type(error).__name__, str(error)
    else:
        etype, msg = "Error", str(error)
    return {"schema": SCHEMA, "kind": kind, "status": "failed", **_identity(job),
            "settings_fingerprint": fingerprint, "stage": stage, "error_type": etype,
            "error": msg[-4000:], "attempts": attempts, "host": socket.gethostname(),
            "finished": _now()}


def fit_gap_db(res) -> float:
    """In-sample gap (dB) of a fit over its own points (module docstring).

    The residuals at the optimum are the fit's own (`FitResult.residuals`, from its last
    accepted step): ``r = log(model level) − log(A_meas + F)`` per point, so the model level is
    ``exp(meas + r)``."""
    problem = res.problem
    r = np.asarray(res.residuals)
    d2, off = [], 0
    for obs in problem.observations:
        m = int(obs.meas.shape[0])
        meas = np.asarray(obs.meas)
        floor = np.asarray(obs.floor)
        lr = r[off: off + m] / obs.weight
        off += obs.size
        thr = floor * 10.0 ** (_GAP_THRESHOLD_DB / 20.0)
        a_meas, a_model = np.exp(meas), np.exp(meas + lr)
        mask = ((a_meas - floor) > thr) | ((a_model - floor) > thr)
        d2.append(((20.0 / np.log(10.0)) * lr[mask]) ** 2)
    d = np.concatenate(d2) if d2 else np.zeros(0)
    return float(np.sqrt(d.mean())) if d.size else 0.0


def _fit_entry(job: Mapping[str, Any], res, *, fingerprint: str, engine: str, batched: int,
               wall: float) -> dict[str, Any]:
    unc = res.uncertainty
    intervals = {}
    std = {}
    if unc is not None:
        for i, n in enumerate(res.names):
            intervals[n] = [float(unc.interval[i][0]), float(unc.interval[i][1])]
            std[n] = float(unc.std[i])
    try:
        gap = fit_gap_db(res)
    except Exception as e:  # noqa: BLE001 — the gap is a summary; the fit stands without it
        gap = float("nan")
        res.message += f"; gap not computed ({type(e).__name__}: {e})"
    ops = res.operating_points[0] if res.operating_points else {}
    return {
        "schema": SCHEMA, "kind": "fit", "status": "ok", **_identity(job),
        "settings_fingerprint": fingerprint, "names": list(res.names),
        "values": dict(res.values), "intervals_95": intervals, "std": std,
        "not_determined": dict(res.not_determined), "converged": bool(res.converged),
        "at_bound": list(res.at_bound), "message": res.message, "loss": float(res.loss),
        "iterations": int(res.iterations), "f_sun": ops.get("f_sun"), "operating_point": ops,
        "gap_db": gap, "engine": engine, "batched_with": batched, "wall_time_s": wall,
        "host": socket.gethostname(), "pid": os.getpid(), "finished": _now(),
        "fit": res.to_dict(),
    }


def _structure(problem):
    import equinox as eqx
    import jax

    static = eqx.partition(problem, eqx.is_array)[1]
    shapes = jax.tree.map(lambda a: a.shape, eqx.filter(problem, eqx.is_array))
    return static, shapes


def fit_task(jobs: Sequence[Mapping[str, Any]], spec_data: Mapping[str, Any],
             settings: FleetSettings, *, fingerprint: str, engine: str = "local",
             inject: str | None = None, attempts_dir: str | None = None) -> list[dict[str, Any]]:
    """Fit the records of one task (module docstring); one entry per record, ``ok`` or
    ``failed``. A `DtwinError` of one record is reported for that record; any other exception
    propagates (Ray retries the task)."""
    from dtwin.io.readers import read_record
    from dtwin.spec import load_spec

    from .fit import fit, fit_batch, make_problem

    spec = load_spec(spec_data)
    settings = settings.resolved(spec_data)
    kw = settings.fit_kwargs()
    free = list(settings.free)
    entries: dict[str, dict[str, Any]] = {}
    ready: list[tuple[Mapping[str, Any], Any, Any]] = []
    for job in jobs:
        _inject(job, inject, attempts_dir, engine == "ray")
        try:
            rec = read_record(job["path"])
            prob, _ = make_problem(rec, spec, free, **{k: v for k, v in kw.items()
                                                      if k not in ("solver", "max_steps", "tol")})
            ready.append((job, rec, prob))
        except DtwinError as e:
            entries[job["key"]] = failure_entry(job, e, stage="read", fingerprint=fingerprint)
    groups: list[list[tuple[Mapping[str, Any], Any, Any]]] = []
    sigs: list[Any] = []
    for item in ready:
        s = _structure(item[2])
        for g, sg in zip(groups, sigs, strict=True):
            if sg == s:
                g.append(item)
                break
        else:
            groups.append([item])
            sigs.append(s)

    def single(job, rec):
        t0 = time.perf_counter()
        try:
            res = fit(rec, spec, free, starts=settings.starts, refine=settings.refine, **kw)
            return _fit_entry(job, res, fingerprint=fingerprint, engine=engine, batched=1,
                              wall=time.perf_counter() - t0)
        except DtwinError as e:
            return failure_entry(job, e, stage="fit", fingerprint=fingerprint)

    for g in groups:
        if len(g) == 1:
            job, rec, _ = g[0]
            entries[job["key"]] = single(job, rec)
            continue
        t0 = time.perf_counter()
        try:
            results = fit_batch([r for _, r, _ in g], spec, free, **kw)
        except DtwinError:
            for job, rec, _ in g:  # isolate the record that fails
                entries[job["key"]] = single(job, rec)
            continue
        wall = (time.perf_counter() - t0) / len(g)
        for (job, _, _), res in zip(g, results, strict=True):
            entries[job["key"]] = _fit_entry(job, res, fingerprint=fingerprint, engine=engine,
                                             batched=len(g), wall=wall)
    return [entries[j["key"]] for j in jobs]


def _fitted_twin(spec, settings: FleetSettings, values: Mapping[str, float], f_sun: float | None):
    from dtwin.build import build_twin

    from .params import ParameterSet

    twin = build_twin(spec, kind=settings.kind, f_sun=f_sun)
    names = [n for n in settings.free if n in values and n != "sensor_gain"]
    if not names:
        return twin
    pset = ParameterSet.build(names, twin, initial={n: float(values[n]) for n in names})
    return pset.apply(pset.prepare(twin), pset.values(np.zeros(len(names))))


def discover_task(job: Mapping[str, Any], spec_data: Mapping[str, Any], settings: FleetSettings,
                  fit_entry: Mapping[str, Any], *, fingerprint: str, engine: str = "local",
                  inject: str | None = None, attempts_dir: str | None = None) -> dict[str, Any]:
    """Discovery on one record about its fitted twin (:func:`dtwin.identify.discover.discover`):
    effects named with their main parameter, held-out gap before and after, unexplained lines.
    A `DtwinError` is reported; other exceptions propagate (retried)."""
    from dtwin.io.readers import read_record
    from dtwin.spec import load_spec

    from .discover import DiscoverySettings, discover

    _inject({**job, "path": job["path"] + "#discover"}, inject, attempts_dir, engine == "ray")
    t0 = time.perf_counter()
    try:
        spec = load_spec(spec_data)
        rec = read_record(job["path"])
        twin = _fitted_twin(spec, settings, fit_entry.get("values", {}), fit_entry.get("f_sun"))
        res = discover(rec.select([settings.channel]), spec, base_twin=twin, kind=settings.kind,
                       settings=DiscoverySettings(**dict(settings.discover_options)))
    except DtwinError as e:
        return failure_entry(job, e, stage="discover", fingerprint=fingerprint, kind="discover")
    return {
        "schema": SCHEMA, "kind": "discover", "status": "ok", **_identity(job),
        "settings_fingerprint": fingerprint,
        "effects": [s.named for s in res.steps],
        "groups": [s.group for s in res.steps],
        "main": [dict(s.main, effect=s.effect) for s in res.steps],
        "gap_initial_db": res.initial_gap.total, "gap_final_db": res.final_gap.total,
        "unexplained": [r.to_dict() for r in res.unexplained], "stop_reason": res.stop_reason,
        "engine": engine, "wall_time_s": time.perf_counter() - t0, "host": socket.gethostname(),
        "finished": _now(), "result": res.to_dict(),
    }


# ================================================================================= the run
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


def _progress(total: int, enabled: bool):
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    return Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TimeElapsedColumn(), TimeRemainingColumn(),
                    console=Console(stderr=True), disable=not enabled, transient=False)


def _run_local(pl: _Plan, spec_data, settings, fp, writer: _Writer, inject, attempts_dir,
               progress: bool) -> None:
    def attempt(fn, *args, **kw):
        err: BaseException | None = None
        for _ in range(settings.max_retries + 1):
            try:
                return fn(*args, **kw), None
            except (KeyboardInterrupt, SystemExit):
                raise
            except Exception as e:  # noqa: BLE001 — retried, then reported per record
                err = e
        return None, err

    n_disc = len(pl.discover_jobs) + (sum(map(len, pl.fit_tasks)) if settings.discover else 0)
    with _progress(sum(map(len, pl.fit_tasks)) + n_disc, progress) as bar:
        tid = bar.add_task("fleet fits", total=sum(map(len, pl.fit_tasks)))
        did = bar.add_task("discovery", total=n_disc, visible=settings.discover)
        disc = list(pl.discover_jobs)
        for task in pl.fit_tasks:
            payload = [j.to_dict() for j in task]
            out, err = attempt(fit_task, payload, spec_data, settings, fingerprint=fp,
                               engine="local", inject=inject, attempts_dir=attempts_dir)
            if err is not None:
                out = [failure_entry(j, err, stage="task", fingerprint=fp,
                                     attempts=settings.max_retries + 1) for j in payload]
            for job, entry in zip(task, out, strict=True):
                writer(entry)
                if settings.discover and entry["status"] == "ok":
                    disc.append((job, entry))
                elif settings.discover:
                    bar.advance(did)
            bar.advance(tid, len(task))
        for job, entry in disc:
            res, err = attempt(discover_task, job.to_dict(), spec_data, settings, entry,
                               fingerprint=fp, engine="local", inject=inject,
                               attempts_dir=attempts_dir)
            if err is not None:
                res = failure_entry(job.to_dict(), err, stage="discover", fingerprint=fp,
                                    kind="discover", attempts=settings.max_retries + 1)
            writer(res)
            bar.advance(did)


def _run_ray(pl: _Plan, spec_data, settings, fp, writer: _Writer, inject, attempts_dir,
             progress: bool, address: str | None, num_cpus: int | None, notes: list[str]) -> None:
    import ray

    started = False
    if not ray.is_initialized():
        kw: dict[str, Any] = dict(include_dashboard=False, log_to_driver=False,
                                  configure_logging=False)
        if address is not None:
            ray.init(address=address, **kw)
        else:
            ray.init(num_cpus=num_cpus, **kw)
        started = True
    notes.append(f"ray {ray.__version__}: {ray.cluster_resources().get('CPU', 0):g} CPUs"
                 + (f" at {address}" if address else " (local)"))
    opts = dict(num_cpus=1, max_retries=settings.max_retries, retry_exceptions=True)
    remote_fit = ray.remote(fit_task).options(**opts)
    remote_disc = ray.remote(discover_task).options(**opts)
    try:
        spec_ref = ray.put(dict(spec_data))
        pending: dict[Any, tuple[str, Any]] = {}
        for task in pl.fit_tasks:
            payload = [j.to_dict() for j in task]
            ref = remote_fit.remote(payload, spec_ref, settings, fingerprint=fp, engine="ray",
                                    inject=inject, attempts_dir=attempts_dir)
            pending[ref] = ("fit", task)

        def submit_discovery(job: RecordJob, entry: dict[str, Any]) -> None:
            ref = remote_disc.remote(job.to_dict(), spec_ref, settings, entry, fingerprint=fp,
                                     engine="ray", inject=inject, attempts_dir=attempts_dir)
            pending[ref] = ("discover", job)

        for job, entry in pl.discover_jobs:
            submit_discovery(job, entry)
        n_fit = sum(map(len, pl.fit_tasks))
        n_disc = len(pl.discover_jobs) + (n_fit if settings.discover else 0)
        with _progress(n_fit + n_disc, progress) as bar:
            tid = bar.add_task("fleet fits (ray)", total=n_fit)
            did = bar.add_task("discovery (ray)", total=n_disc, visible=settings.discover)
            while pending:
                done, _ = ray.wait(list(pending), num_returns=1)
                for ref in done:
                    what, item = pending.pop(ref)
                    if what == "fit":
                        try:
                            entries = ray.get(ref)
                        except (ray.exceptions.RayError, DtwinError) as e:
                            entries = [failure_entry(j.to_dict(), _cause(e), stage="task",
                                                     fingerprint=fp,
                                                     attempts=settings.max_retries + 1)
                                       for j in item]
                        for job, entry in zip(item, entries, strict=True):
                            writer(entry)
                            if settings.discover and entry["status"] == "ok":
                                submit_discovery(job, entry)
                            elif settings.discover:
                                bar.advance(did)
                        bar.advance(tid, len(item))
                    else:
                        try:
                            entry = ray.get(ref)
                        except (ray.exceptions.RayError, DtwinError) as e:
                            entry = failure_entry(item.to_dict(), _cause(e), stage="discover",
                                                  fingerprint=fp, kind="discover",
                                                  attempts=settings.max_retries + 1)
                        writer(entry)
                        bar.advance(did)
    finally:
        if started:
            ray.shutdown()


def _cause(e: BaseException) -> BaseException:
    """The user exception inside a `RayTaskError`, else the error itself."""
    cause = getattr(e, "cause", None)
    return cause if isinstance(cause, BaseException) else e


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
    from dtwin.io.output import versions
    from dtwin.spec import Spec, load_spec

    from .fit import check_free

    t0 = time.perf_counter()
    check_free(list(settings.free))  # unknown names fail before anything is read
    if engine not in ("auto", "ray", "local"):
        raise ValueError(f"engine must be auto, ray or local, got {engine!r}")
    notes: list[str] = []
    if engine == "auto":
        engine = "ray" if (ray_available() or address) else "local"
        if engine == "local":
            notes.append("Ray is not installed: records run one after another in this process "
                         "(pip install 'dtwin[fleet]' for Ray)")
    if engine == "ray" and not ray_available():
        raise ImportError("engine 'ray' needs Ray: pip install 'dtwin[fleet]' (ray>=2.9), or "
                          "run without --ray-address for the local engine")
    spec = spec if isinstance(spec, Spec) else load_spec(spec)
    from dtwin.spec import spec_to_dict

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
            _run_ray(pl, spec_data, settings, fp, writer, inject, attempts_dir, progress,
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


# ================================================================================= the table
def table_rows(results: Sequence[Mapping[str, Any]]) -> tuple[list[dict[str, Any]], list[str]]:
    """Flat rows of the fleet table, one per record, and the parameter names (union).

    Columns: ``record, machine, timestamp, status, converged, loss, gap_db, f_sun,
    iterations``, per parameter ``<name>, <name>_lo95, <name>_hi95, <name>_determined``, then
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
    from dtwin.io.output import atomic_write_bytes

    out = Path(out)
    rows, _ = table_rows(load_results(out))
    note = None
    if fmt not in ("auto", "parquet", "csv"):
        raise ValueError(f"fmt must be auto, parquet or csv, got {fmt!r}")
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
        import io

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
        import csv
        import io

        buf = io.StringIO()
        cols = list(rows[0]) if rows else ["record", "machine", "timestamp", "status"]
        w = csv.DictWriter(buf, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow({k: "" if v is None else v for k, v in r.items()})
        atomic_write_bytes(target, buf.getvalue().encode(), force=True)
    return target, note
