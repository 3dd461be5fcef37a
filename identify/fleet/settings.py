"""Settings of a fleet run (:class:`FleetSettings`), the schema tags and file names of its
results."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Mapping
from typing import Any

from dtwin.errors import SettingsError
from dtwin.io.output import to_jsonable

from ..residuals import Features

#: Schema tag of a per-record result file.
SCHEMA = "dtwin.fleet.result/1"
#: Default file name of the gathered table (Parquet; ``.csv`` without pyarrow).
TABLE_NAME = "table.parquet"
#: Environment variable of the failure injection (package docstring).
FAIL_ENV = "DTWIN_FLEET_FAIL"


@dataclasses.dataclass(frozen=True)
class FleetSettings:
    """What is fitted to every record of a fleet, and how the run is cut into tasks.

    - `free`: registry names fitted (e.g. ``("sun_fault",)``); `kind`: the twin
      (``torsional`` or ``translational``; None: the kind a calibrated spec was calibrated
      with, otherwise torsional, :func:`dtwin.spec.build.twin_kind`); `initial`:
      ``((name, value), ...)`` starting values (SI); `f_sun`: input speed (Hz) for every
      record (None: each record's, :func:`dtwin.identify.operating_point.resolve_speed`);
      `tacho`: ``(channel, pulses per revolution, shaft)`` of a tachometer channel in every
      record (``--tacho``), read as the record's tachometer, or None.
    - `solver`, `starts`, `refine`, `max_steps`, `tol`, `channel`, `splits`: as
      :func:`dtwin.identify.fit.fit` (`splits` None: a calibrated spec's fault severities are
      fitted with both ends of its excitation/response split, :mod:`dtwin.identify.split`).
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
    kind: str | None = None
    initial: tuple[tuple[str, float], ...] = ()
    f_sun: float | None = None
    tacho: tuple[str | int, int, str] | None = None
    solver: str = "lm"
    starts: int = 1
    refine: int = 1
    max_steps: int = 40
    tol: float = 1e-4
    channel: int | str = 0
    splits: bool | None = None
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
        if self.tacho is not None:
            object.__setattr__(self, "tacho", tuple(self.tacho))
        if not self.free:
            raise SettingsError("FleetSettings.free: name at least one registry parameter")
        if self.kind is not None and self.kind not in ("torsional", "translational"):
            raise SettingsError(f"FleetSettings.kind must be torsional or translational, got "
                             f"{self.kind!r}")
        if self.grid not in ("orders", "hz"):
            raise SettingsError(f"FleetSettings.grid must be orders or hz, got {self.grid!r}")
        if self.grid == "hz" and (self.order_step is not None or self.f_max is not None):
            raise SettingsError("FleetSettings.order_step and f_max belong to grid='orders'")
        if self.batch_size < 1:
            raise SettingsError(f"FleetSettings.batch_size must be >= 1, got {self.batch_size}")
        if self.max_retries < 0:
            raise SettingsError(f"FleetSettings.max_retries must be >= 0, got {self.max_retries}")
        if self.batch_size > 1 and (self.starts > 1 or self.refine > 1):
            raise SettingsError("batched fits (batch_size > 1) use one start per record: "
                             "set starts=1, refine=1 or batch_size=1")

    def resolved(self, spec_data: Mapping[str, Any]) -> FleetSettings:
        """These settings with `f_max` filled in (order domain): 1.05 × `f_sun`, or × the
        spec's nominal input speed. **Raises:** `SettingsError` when neither is known."""
        if self.grid != "orders" or self.f_max is not None:
            return self
        f = self.f_sun
        if f is None:
            f = (dict(spec_data).get("operating") or {}).get("f_sun")
        if f is None:
            raise SettingsError("the order domain needs the fleet's highest speed: pass f_max "
                             "(--f-max), f_sun (--f-sun) or a spec with operating.f_sun")
        return dataclasses.replace(self, f_max=round(1.05 * float(f), 6))

    def record_reading(self) -> dict[str, Any]:
        """Keyword arguments of :func:`dtwin.io.readers.read_record` for every record (the
        tachometer channel)."""
        if self.tacho is None:
            return {}
        ch, ppr, shaft = self.tacho
        return {"tacho": ch, "tacho_ppr": int(ppr), "tacho_shaft": shaft}

    def fit_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`dtwin.identify.fit.fit` / ``fit_batch`` (without the starts);
        call on :meth:`resolved` settings."""
        kw: dict[str, Any] = dict(kind=self.kind, solver=self.solver, max_steps=self.max_steps,
                                  tol=self.tol, channel=self.channel, f_sun=self.f_sun,
                                  splits=self.splits)
        if self.initial:
            kw["initial"] = dict(self.initial)
        if self.grid == "orders":
            if self.f_max is None:
                raise SettingsError("FleetSettings.fit_kwargs: resolve f_max first (resolved())")
            kw["features"] = Features(grid="orders", f_max=float(self.f_max),
                                      order_step=None if self.order_step is None
                                      else float(self.order_step))
        return kw

    def problem_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`dtwin.identify.fit.make_problem`: :meth:`fit_kwargs`
        without the solver's."""
        return {k: v for k, v in self.fit_kwargs().items()
                if k not in ("solver", "max_steps", "tol", "splits")}

    def fingerprint(self, spec_data: Mapping[str, Any]) -> str:
        """SHA-256 (16 hex digits) of everything that changes a fit result: the fit settings
        and the spec (not the batching, retries or discovery)."""
        fit = {k: getattr(self, k) for k in ("free", "kind", "initial", "f_sun", "solver",
                                             "starts", "refine", "max_steps", "tol", "channel",
                                             "splits", "grid", "order_step", "f_max")}
        if self.tacho is not None:
            fit["tacho"] = self.tacho
        spec = {k: v for k, v in dict(spec_data).items() if k != "source"}
        blob = json.dumps(to_jsonable({"fit": fit, "spec": spec}), sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()[:16]

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["initial"] = dict(self.initial)
        d["discover_options"] = dict(self.discover_options)
        return d
