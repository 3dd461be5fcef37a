"""Fleet runs: identify many records of one gearbox type, batched on one machine or as Ray tasks.

A wind farm or a production line records hundreds of gearboxes every day. :func:`run_fleet`
fits every record (:mod:`dtwin.identify.fit`) and keeps one result file per record, so that a fleet
of records becomes a table (:func:`write_table`) and per-machine trends
(:mod:`dtwin.identify.trends`).

**Work units.** Records are read once by the driver (machine, timestamp, SHA-256, length and
rate), grouped by ``(sample rate, samples)`` and cut into tasks of ``batch_size`` records
(:func:`plan`, module ``plan``). The residuals are taken in the **order domain** by default
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

**A tooth fault's depth** (``free`` holds ``sun_fault``, ``planet_fault`` or ``ring_fault``;
:func:`dtwin.identify.severity.fault_location`): the twin is the one ``dtwin severity`` fits
(:data:`dtwin.spec.build.SEVERITY_KIND`, unless ``FleetSettings.kind`` names one), batched or not,
and a record fitted alone is fitted by :func:`dtwin.identify.severity.estimate_severity` itself
— the calibration's two excitation/response splits, the low band of a sun or ring fault, the
healthy-tooth test — so its value and interval (kept under ``severity`` in its result, with the
peak stiffness loss) are ``dtwin severity``'s on the same record, spec and grid (``grid="hz"``
for the very number ``dtwin severity`` prints; the order domain samples the same spectrum on
another grid). A batched fit shares the twin and the split rule but not the low band.

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

**Modules:** ``settings`` (:class:`FleetSettings`, schema and file names), ``identity``
(records, machines, timestamps, keys), ``store`` (the results folder), ``plan``, ``tasks``
(:func:`fit_task`, :func:`discover_task`), ``local_engine``, ``ray_engine``, ``driver``
(:func:`run_fleet`), ``table`` (:func:`write_table`).

**Failure injection** (tests, drills): ``DTWIN_FLEET_FAIL="<substring>[:raise|exit][@N]"`` in
the driver's environment makes the tasks of records whose path contains the substring raise
``RuntimeError`` (``raise``) or kill their worker process (``exit``, Ray only), on the first `N`
attempts (every attempt without ``@N``).
"""

from .driver import FleetRun as FleetRun
from .driver import run_fleet as run_fleet
from .identity import RecordJob as RecordJob
from .identity import _make_job as _make_job
from .identity import expand_records as expand_records
from .identity import read_fleet_manifest as read_fleet_manifest
from .identity import result_key as result_key
from .plan import plan as plan
from .ray_engine import ray_available as ray_available
from .settings import FAIL_ENV as FAIL_ENV
from .settings import SCHEMA as SCHEMA
from .settings import TABLE_NAME as TABLE_NAME
from .settings import FleetSettings as FleetSettings
from .store import load_results as load_results
from .table import table_rows as table_rows
from .table import write_table as write_table
from .tasks import _structure as _structure
from .tasks import discover_task as discover_task
from .tasks import failure_entry as failure_entry
from .tasks import fit_gap_db as fit_gap_db
from .tasks import fit_task as fit_task

__all__ = [
    "FAIL_ENV",
    "FleetRun",
    "FleetSettings",
    "RecordJob",
    "SCHEMA",
    "TABLE_NAME",
    "discover_task",
    "expand_records",
    "failure_entry",
    "fit_gap_db",
    "fit_task",
    "load_results",
    "plan",
    "ray_available",
    "read_fleet_manifest",
    "result_key",
    "run_fleet",
    "table_rows",
    "write_table",
]
