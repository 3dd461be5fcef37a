"""Fault severity from records: one estimate with its interval, and a series (degradation).

:func:`estimate_severity` fits the severity of the fault at a named location
(``<location>_fault``, a registry name), optionally with further free parameters (mesh
stiffness, damping), and returns it with its 95 % interval — a profile-likelihood interval when
the estimate lies near 0 or 1 (:mod:`dtwin.identify.uncertainty`).

:func:`severity_series` runs the same fit over a series of records (e.g. one per day of a
machine's life): all records of one length and rate share one compiled fit (the observations
differ only in their arrays), so after the first record each fit costs only its iterations.
The trajectories of the severity and of the other free parameters, with their intervals, come
back as :class:`SeveritySeries`; :func:`dtwin.identify.api.plot_severity_series` draws them (the
paper's degradation-model idea).

**Peak stiffness loss.** Severity is what the fault type's own geometry measures (face width
removed, pitted area, crack depth); every estimate is also reported as the fault's peak
mesh-stiffness loss at the faulty tooth (:func:`dtwin.model.faults.peak_stiffness_loss`), the quantity
comparable across benches, fault models and twins: the largest fractional drop of the faulty
tooth's mesh stiffness while that tooth is in mesh, relative to the healthy stiffness at the
same instant (``reference="instant"``; the twin's healthy waveform). The fraction depends on
the healthy waveform at the faulty tooth's contact, which one housing sensor does not
determine (the sun meshes' excitation is not separable from the ring's,
:mod:`dtwin.identify.calibrate`), so its interval runs from the lower severity bound taken
relative to the waveform's largest value (``1.75 c'``) to the upper bound taken relative to its
smallest (``c'``): any healthy waveform between the single-pair and double-contact stiffness
gives a peak inside it.

**The sideband ratio** (``method="ratio"``, the default for one steady record with the
fault's severity the only free parameter). Within the first mesh band of the record, the
power the fault adds on its sidebands over the power of the gearbox's own lines is read, and
the twin is simulated at a grid of severities to find where its ratio meets the record's
(:mod:`dtwin.identify.line_ratio`). The sensor's gain and transfer path and the window
cancel in that ratio; the healthy mesh excitation does not (below, "The healthy lines'
excitation"). A
least-squares fit of the spectrum's log levels (``method="spectrum"``, below) weighs every
sideband alone and is pulled by how the twin spreads a fault's power over its lines rather
than by how much it makes: on records of independent simulators it read some sun and planet
faults 7–50× small where the ratio read every one 0.98–2.6× (docs/identification.md, "The depth
of a tooth fault: the sideband ratio"). The first band's sideband power fixes the stiffness a
pass of the faulty tooth removes, not how it is shared between depth and duration, and the
loss's shape is not known on a real machine: the twin's own fault is read (by default the
sharp loss over the contact) and the interval is the hull over it and the other shapes of
:data:`SHAPE_GRID` (with ``ramps``, over those shapes, the first reported). The interval holds the record's
noise and the delete-one-slice jackknife of the band's lines (how far the reading rests on one
part of the band); where no fault line stands over the noise the depth reads 0 with an
interval up to the detection limit, and where the twin's deepest fault makes less sideband
power than the record holds the status says the model does not fit the record. The first band
is read; the others are read alike, and a stiffness loss of one depth makes every band's
sidebands in the twin's proportions: where two bands' 95 % intervals exclude each other
(:func:`bands_disagree`; a band held at the grid's top reaches up without end), the record's
sidebands do not have the shape a stiffness loss makes — a profile deviation, a fault of
another kind — and the status is NOT DETERMINED and names the two (the "ok" of the spectrum
fit's band jackknife, below, asks the same).

**The healthy lines' excitation.** The ratio weighs the stiffness the fault removes (times the
static mesh deflection) against the healthy mesh excitation: the stiffness waveform's under
the load plus any calibrated transmission error. A healthy record at one load measures that
excitation only in product with the sensor's response (:mod:`dtwin.identify.excitation_response`),
so a calibrated spec is read at both ends of its split: as calibrated, and with the stiffness
waveform's excitation alone and a flat response (:func:`~dtwin.identify.excitation_response.stiffness_split`;
the first loss shape only, its interval widened by the factors the shapes' hull widens the
calibrated reading's). The calibrated reading is reported; the interval is the hull over both,
and where the two readings lie further apart than the half-width limit
(:data:`~dtwin.identify.uncertainty.HALF_WIDTH_LIMIT` of the reading) the status is NOT
DETERMINED and names both. On the independent records of the paper's gearbox the two ends
read a sun fault 0.19 and 0.33 (truth 0.09): one load cannot tell them apart — the stiffness
waveform's excitation grows with the load and a transmission error does not, so healthy
records at two loads could.

The other paragraphs below describe the spectrum fit (``method="spectrum"``, and the default
with other free parameters or a run-up).

**The loss's shape.** How sharply the loss rises and falls as the faulty tooth enters and
leaves the mesh (``fault.ramp``) and how far beyond its own contact it is felt
(``fault.spread``), in mesh cycles, are not known on a real machine, and at 5 kHz they set the
level of the fault's sidebands near the mesh harmonics as much as the peak does. With
``ramps=`` the fit is repeated for each shape (one compiled fit serves them all; ``"grid"``:
:data:`RAMP_GRID`, ``"shapes"``: :data:`SHAPE_GRID`), the shape of least loss is reported, and
the intervals of severity and peak loss are the union over the shapes the data cannot reject.
A shape is rejected when its ``‖r‖²`` exceeds the best one's by more than the larger of (a)
``χ²₁(95 %)`` in units of the residual variance (neighbour-correlation and lack-of-fit factors
included: the profile likelihood over the shape) and (b) what the best shape leaves
unexplained beyond the noise, ``‖r‖² − E`` (:func:`expected_noise_rss`): a loss difference
smaller than the model-form error the best fit still carries cannot tell two shapes apart.

**The twin.** A severity is fitted with the translational twin unless a `kind` is given
(:data:`dtwin.spec.build.SEVERITY_KIND`), whatever kind the spec names or was calibrated with: a
local tooth fault loads one mesh at a time, a floating sun moves under that loss, and the
torsional twin, whose sun and planets cannot move sideways, makes a sun or planet fault
several times louder and so reads it several times small (docs/identification.md, "The twin of
a severity"). Where the spec was calibrated with the other twin, its calibrated excitation,
window and response are taken as they are and the estimate's `note` says so.

**The calibration's split** (``splits=None``: on for a calibrated spec with a calibrated mesh
excitation or response shape; :mod:`dtwin.identify.excitation_response`). A healthy record cannot tell the
calibration's transmission error and raised response from the stiffness waveform's excitation
and a flat response; a tooth fault's sidebands pass the response uncancelled, so the faulty
record can. Every loss shape is fitted with both ends of the split
(:func:`~dtwin.identify.excitation_response.stiffness_split`), and the splits are scored as the loss shapes
are: the split of least loss is reported (`SeverityEstimate.excitation`), and the intervals are
the union over the splits the record cannot reject. One more fit per shape.

**A planet fault's flank** (``flanks=None``: on for a planet fault whose flank the spec does
not name). A planet tooth meets the sun on one flank and the ring on the other, and a fault may
weaken either or both (pitting of one flank, a crack or a missing tooth through both). The
flank decides which mesh loses stiffness, and so the phase and level of every sideband: a fit
on the wrong flank reads a one-flank fault far too small, with a loss several times the right
one's (docs/identification.md). The flank is a static field of the fault (a
new compiled fit each), so the fit is repeated on each flank of :data:`PLANET_FLANKS` and the
flanks are scored as the loss shapes are: the flank of least loss is reported
(`SeverityEstimate.flank`) and the intervals are the union over the flanks the record cannot
reject. Three fits where there was one; a spec whose ``[[faults]]`` entry at the planet names
its ``flank`` is taken at its word.

**The low band** (``low_band=None``, the default: on for a sun or ring fault on a steady
spectrum record, :data:`LOW_BAND_LOCATIONS`; :func:`with_low_band`). The residuals of
:mod:`dtwin.identify.residuals` look at bands around the mesh harmonics, where a tooth fault's
sidebands at a low sampling rate stand only a few dB above the noise and depend on the loss's
shape. Below the first mesh band a local fault makes its strongest lines: the comb of the
faulty tooth's passes (``k f_sf``; with ``± f_s`` for a sun fault, whose force turns with the
sun when the sun floats on its bearing), tens of dB above the floor. The low band adds every
bin from ``0.8 N f_c`` (the lowest knot of a calibrated sensor response) to the first mesh
band as band 0, with the planet-pass lines that calibration fits.

**A healthy tooth is not ruled out by the coordinate.** Severity is fitted in a logit
coordinate, whose Gaussian and profile intervals never reach 0 itself. The twin without the
fault (severity at the edge of its range, 1e-3 of it, other free parameters at their fitted
values) is scored by the likelihood-ratio rule: when its ``‖r‖²`` exceeds the best fit's by no
more than ``χ²₁(95 %)`` in units of the residual variance (neighbour-correlation and
lack-of-fit factors included), the data cannot reject a healthy tooth and the interval's lower
ends (severity and peak loss) move to the range's lower edge: 0, unless the user bounded it. A
healthy tooth is a point of the fitted model, not another model form, so the shapes' second
term (what the best fit leaves unexplained) does not apply. Holding the other parameters makes
the test conservative: the profile over them could only lower the healthy twin's loss.

**Band jackknife** (``jackknife=True``, the default). Each accepted shape's interval is also
the hull with the delete-one-band jackknife interval
(:func:`dtwin.identify.uncertainty.band_jackknife`): when the bands disagree about the
severity beyond their noise — a model-form error that the loss, at the noise level, need not
show — the interval grows with the disagreement, and the status says "widened by the band
jackknife". So "ok" means the fit passed all of its own checks: converged, loss at the noise
level (lack of fit), residuals white past the window's reach
(:mod:`dtwin.identify.uncertainty`, "Whiteness") and bands that agree. It costs one
least-squares step per band on the fit's Jacobian; ``jackknife=False`` (``--no-jackknife``) leaves it out, and with fewer than
three bands there is nothing to leave out.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from dtwin.errors import ParameterError, SettingsError
from dtwin.model.faults import MIN_SPREAD, peak_stiffness_loss
from dtwin.model.registry import lookup
from dtwin.spec.build import SEVERITY_KIND, is_calibrated

from .excitation_response import (
    SPLIT_CALIBRATED,
    SPLIT_STIFFNESS,
    model_form_tolerance,
    other_split,
    stiffness_split,
)
from .fit import fit
from .fit_result import FitResult
from .line_ratio import SEVERITY_GRID, SIGNIFICANT_DB, LineRatio, line_ratio, twin_powers
from .line_ratio import with_shape as _with_shape
from .low_band import LOW_BAND_LOCATIONS as LOW_BAND_LOCATIONS
from .low_band import LOW_BAND_START as LOW_BAND_START
from .low_band import with_low_band as with_low_band
from .low_band import with_low_band_problem as with_low_band_problem
from .problem import make_problem, spec_of
from .residuals import point_groups
from .solve import batched_loss, jacobian_at
from .uncertainty import CHI2_95, HALF_WIDTH_LIMIT, band_jackknife

__all__ = ["METHODS", "RAMP_GRID", "SeverityEstimate", "SeveritySeries", "bands_disagree",
           "estimate_severity", "fault_location", "severity_series"]

#: How a depth is read: ``"ratio"``, from the power of the fault's sidebands over the healthy
#: mesh lines in the first mesh band (:mod:`dtwin.identify.line_ratio`; the default for a
#: steady record with no other free parameter), or ``"spectrum"``, by a least-squares fit of
#: the spectrum's log levels (:func:`dtwin.identify.fit.fit`; the default otherwise).
METHODS = ("ratio", "spectrum")

#: Shapes of the loss tried with ``ramps="grid"``: edge widths (mesh cycles) from a sharp
#: loss over the tooth's contact (0.05, the default fault's: 10–90 % in 0.22 cycles) to one
#: that rises and falls over about a mesh cycle either side (0.3: 10–90 % in 1.3 cycles).
RAMP_GRID = (0.05, 0.15, 0.3)

#: Shapes of the loss tried with ``ramps="shapes"``, as ``(ramp, spread)`` (mesh cycles): the
#: sharp loss over the contact, a soft one, one that extends a mesh cycle beyond the contact
#: either side and fades over it, and a sharp one confined to the middle of the contact (a pit
#: or spall about the pitch point: :data:`dtwin.model.faults.MIN_SPREAD`).
SHAPE_GRID = ((0.05, 0.0), (0.3, 0.0), (0.3, 1.0), (0.05, MIN_SPREAD))
_LOCATIONS = ("sun", "planet", "ring")


def fault_location(names: Sequence[str]) -> str | None:
    """The location (``sun``, ``planet``, ``ring``) of the one tooth fault's severity among the
    registry `names`, or None when they hold none or more than one.

    This is the rule by which every command that fits a tooth fault's depth takes one path
    (:func:`estimate_severity`): ``dtwin identify --free …,sun_fault`` on one steady record,
    ``dtwin fleet`` with a tooth fault free, and ``dtwin discover`` when it names a local tooth
    fault fit the problem ``dtwin severity`` fits — the same twin, the same ends of a
    calibration's excitation/response split, the same bands — and so give the same depth."""
    found = [n[: -len("_fault")] for n in names if n.endswith("_fault")
             and n[: -len("_fault")] in _LOCATIONS]
    return found[0] if len(found) == 1 else None


def _name(location: str) -> str:
    if location not in _LOCATIONS:
        raise ParameterError(f"fault location must be one of {_LOCATIONS}, got {location!r}")
    return f"{location}_fault"


@dataclasses.dataclass(frozen=True)
class SeverityEstimate:
    """Severity (1) at `location` with its 95 % `interval`, whether it is `determined`, the
    method of the interval (``gaussian`` in the logit coordinate or ``profile``), and the fit;
    `peak_loss` (fraction; × 100 for %): the peak mesh-stiffness loss at the faulty tooth
    relative to the mean mesh stiffness (:func:`dtwin.model.faults.peak_stiffness_loss`), and
    `peak_interval`, its 95 % interval over any healthy waveform (module docstring); `ramp`,
    `spread`: the loss's edge width and its extent beyond the contact (mesh cycles) of the
    reported fit; `widened`: the factor the intervals were widened by for lack of fit (1:
    none); `shapes`: per fit, shape (``ramps=``) and split, its ramp, spread, ``excitation``
    (the split, where two were fitted), loss, severity, peak loss, whether the loss accepts it
    and its intervals (``jackknife_95`` with the band jackknife); `note`: where the twin's
    kind departs from the one the spec was calibrated with, what that means (module
    docstring, "The twin"); `low_band`: whether the fit held the low
    band (:func:`with_low_band`); `excitation`: of a calibrated spec's two excitation/response
    splits, the one the reported fit used (:data:`~dtwin.identify.excitation_response.SPLIT_CALIBRATED`,
    :data:`~dtwin.identify.excitation_response.SPLIT_STIFFNESS`; module docstring, "The calibration's
    split"), empty when one was fitted; `flank`: for a planet fault, the flank of the planet
    tooth the reported fit put it on (``both``, ``sun``, ``ring``; module docstring, "A planet fault's flank"), empty for a sun or ring fault."""

    location: str
    severity: float
    interval: tuple[float, float]
    determined: bool
    method: str
    fit: FitResult = dataclasses.field(repr=False)
    peak_loss: float = float("nan")
    peak_interval: tuple[float, float] = (float("nan"), float("nan"))
    ramp: float = float("nan")
    spread: float = 0.0
    widened: float = 1.0
    shapes: tuple[dict[str, Any], ...] = ()
    note: str = ""
    low_band: bool = False
    excitation: str = ""
    flank: str = ""
    reason: str = ""
    readings: tuple[dict[str, Any], ...] = ()

    @property
    def status(self) -> str:
        """``NOT DETERMINED`` (with the reason where the model does not fit the record at all:
        :data:`~dtwin.identify.uncertainty.MODEL_FORM_LIMIT`), ``widened ×k for lack of fit``,
        ``unconverged``, ``residuals not white (p = …)``, ``widened by
        the band jackknife`` (the bands disagree beyond their noise: a model-form error, and
        the interval covers it) or ``ok``."""
        if self.method.startswith("line ratio"):
            if not self.determined:
                return f"NOT DETERMINED: {self.reason}" if self.reason else "NOT DETERMINED"
            return f"ok ({self.reason})" if self.reason else "ok"
        st = self.fit.status(f"{self.location}_fault")
        if not self.determined:  # the model-form failure says so, with the loss over the noise
            return st if st.startswith("NOT DETERMINED:") else "NOT DETERMINED"
        if st == "ok" and "band jackknife" in self.method:
            return "widened by the band jackknife"
        return st

    def shapes_table(self) -> str:
        """The fits of the loss shapes (``ramps=``), excitation/response splits and planet-tooth
        flanks tried, a line each: the split and the flank (where several were fitted), edges
        and extent (mesh cycles), the fit's loss,
        severity and peak loss with its 95 % interval, and whether the record rejects it; empty
        when one fit was made."""
        if len(self.shapes) < 2:
            return ""
        splits = any("excitation" in r for r in self.shapes)
        flanks = any("flank" in r for r in self.shapes)
        head = (f"{'excitation and response':<34} " if splits else "") + \
            (f"{'flank':<6} " if flanks else "")
        out = [f"{head}{'loss shape':<24} ramp spread       loss  severity  peak loss, 95 %"]
        for r in self.shapes:
            pk = r.get("peak_interval_95", [np.nan, np.nan])
            verdict = "accepted" if r["accepted"] else "rejected by the record"
            col = (f"{r.get('excitation', ''):<34} " if splits else "") + \
                (f"{r.get('flank', ''):<6} " if flanks else "")
            out.append(f"{col}{_shape_name(r['ramp'], r['spread']):<24} {r['ramp']:4.2f} "
                       f"{r['spread']:+5.2f}  {r['loss']:9.2f}  {r['severity']:8.3f}  "
                       f"{100 * r['peak_stiffness_loss']:5.1f} % [{100 * pk[0]:.1f}, "
                       f"{100 * pk[1]:.1f}]  {verdict}")
        return "\n".join(out)

    def readings_table(self) -> str:
        """The sideband ratio's readings (``method="ratio"``), a line per band of each loss
        shape (and excitation/response split, where a calibrated spec has two): fault and
        healthy lines (bins), the record's ratio with its noise and jackknife standard errors,
        the twin's ratio over the severity grid, and the band's reading; empty for a spectrum
        fit."""
        if not self.readings:
            return ""
        out = []
        for r in self.readings:
            grid = " ".join(f"{g:g}" for g in r["grid"])
            split = f"excitation: {r['excitation']}; " if "excitation" in r else ""
            out.append(f"{split}loss shape: {_shape_name(r['ramp'], r['spread'])} (ramp "
                       f"{r['ramp']:.2f}, spread {r['spread']:+.2f}); twin at severities {grid}")
            quiet = [b["name"] for b in r["bands"][1:] if not b["fault_bins"]]
            for b in r["bands"]:
                if b["name"] in quiet:
                    continue
                twin = " ".join(f"{v:6.1f}" for v in b["twin_db"])
                read = ("–" if not np.isfinite(b["severity"]) else
                        f"{b['severity']:.3f} [{b['interval'][0]:.3f}, {b['interval'][1]:.3f}]")
                out.append(f"  {b['name']:<6} {b['fault_bins']:4d} fault / {b['healthy_bins']:3d} "
                           f"healthy bins  record {b['record_db']:6.1f} dB "
                           f"(±{b['record_se_db']:.1f} noise, ±{b['jackknife_db']:.1f} "
                           f"jackknife)  twin {twin}  → {read} {b['edge']}".rstrip())
            if quiet:
                out.append(f"  {', '.join(quiet)}: no fault line {SIGNIFICANT_DB:g} dB over the "
                           "noise (not read)")
        return "\n".join(out)

    def to_dict(self, with_fit: bool = True) -> dict[str, Any]:
        """The estimate as JSON-ready values; `with_fit`: with the fit's own dictionary under
        ``fit`` (without it where the fit is reported beside it)."""
        out = {"location": self.location, "severity": self.severity,
                "interval_95": list(self.interval), "determined": self.determined,
                "interval_method": self.method, "peak_stiffness_loss": self.peak_loss,
                "peak_stiffness_loss_interval_95": list(self.peak_interval),
                "ramp_mesh_cycles": self.ramp, "spread_mesh_cycles": self.spread,
                "widened_for_lack_of_fit": self.widened,
                "status": self.status, "shapes": [dict(x) for x in self.shapes],
                "twin_kind": self.fit.problem.twin.kind, "note": self.note,
                "low_band": self.low_band, "excitation": self.excitation,
                "flank": self.flank, "readings": [dict(r) for r in self.readings]}
        if with_fit:
            out["fit"] = self.fit.to_dict()
        return out

    def summary(self) -> str:
        """One line: severity and peak stiffness loss with their 95 % intervals and status."""
        lo, hi = self.interval
        plo, phi = self.peak_interval
        where = {"": "", "both": " (both flanks)"}.get(self.flank, f" ({self.flank} flank)")
        return (f"{self.location} fault{where} severity {self.severity:.3f} 95 % "
                f"[{lo:.3f}, {hi:.3f}]"
                f" ({self.method}); peak stiffness loss {100 * self.peak_loss:.1f} % of the "
                f"healthy mesh stiffness at that instant, 95 % [{100 * plo:.1f}, "
                f"{100 * phi:.1f}] % (any healthy waveform); {self.status}")


def _shape_name(ramp: float, spread: float) -> str:
    """A loss shape in words (:data:`SHAPE_GRID`)."""
    where = ("mid-contact (pit)" if spread < 0.0 else
             "beyond the contact" if spread > 0.0 else "whole contact")
    return f"{'sharp' if ramp <= 0.1 else 'soft'}, {where}"


def _fault_index(twin, location: str) -> int | None:
    """Position in ``twin.parts`` of the local fault at `location` (the one ``<location>_fault``
    addresses), or None: that parameter's registry address finds it."""
    return lookup(_name(location)).address.index(twin)


def _peak(twin, i: int, severity: float, reference: str = "instant") -> float:
    """Peak stiffness loss of the twin's fault `i` at `severity` (its own type and shape),
    relative to the healthy mesh's `reference` stiffness
    (:func:`dtwin.model.faults.peak_stiffness_loss`; module docstring, "Peak stiffness loss")."""
    f = eqx.tree_at(lambda f: f.severity, twin.parts[i].fault,
                    jnp.asarray(min(max(float(severity), 0.0), 1.0), jnp.float64))
    return float(peak_stiffness_loss(f, twin.lp, reference=reference))


def _split_kwargs(fit_kwargs: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(make_problem's keyword arguments, the rest: fit's own)."""
    import inspect

    mp = set(inspect.signature(make_problem).parameters) - {"records", "spec_or_twin", "free"}
    return ({k: v for k, v in fit_kwargs.items() if k in mp},
            {k: v for k, v in fit_kwargs.items() if k not in mp or k == "jac"})


def _shapes(ramps) -> tuple[tuple[float, float], ...]:
    """``ramps`` as ``((ramp, spread), …)``: ``"grid"`` (:data:`RAMP_GRID`, no spread),
    ``"shapes"`` (:data:`SHAPE_GRID`), or a sequence of ramps or ``(ramp, spread)`` pairs."""
    if isinstance(ramps, str):
        if ramps == "grid":
            return tuple((float(r), 0.0) for r in RAMP_GRID)
        if ramps == "shapes":
            return SHAPE_GRID
        raise SettingsError(f"ramps must be 'grid', 'shapes' or a sequence, got {ramps!r}")
    return tuple((float(r[0]), float(r[1])) if isinstance(r, (tuple, list)) else (float(r), 0.0)
                 for r in ramps)


def _twin_kind(spec_or_twin, kind: str | None) -> tuple[str | None, str]:
    """``(kind, note)``: the twin kind a severity fit builds from `spec_or_twin` (None for a
    twin, which is its own) and, where the default departs from the kind the spec was
    calibrated with, a note saying so (module docstring, "The twin")."""
    spec = None if kind is not None else spec_of(spec_or_twin)
    if spec is None:
        return kind, ""
    own = spec["model"]["kind"]
    if is_calibrated(spec) and own != SEVERITY_KIND:
        return SEVERITY_KIND, (
            f"fitted with the {SEVERITY_KIND} twin (the {own} twin this spec was calibrated "
            f"with holds the sun and planets still under a tooth fault and reads sun and planet "
            f"faults 4–10× small), the calibrated excitation, window and response taken as "
            f"they are; kind='{own}' (--model {own}) for the calibrated twin")
    return SEVERITY_KIND, ""


#: The flanks of a planet tooth a planet fault's severity is fitted on (``flanks=None`` where the
#: spec names none; module docstring, "A planet fault's flank"): both, the one meeting the sun,
#: the one meeting the ring (:class:`dtwin.model.faults.AbstractFault`'s ``flank``).
PLANET_FLANKS = ("both", "sun", "ring")


def _named_flank(spec_or_twin) -> bool:
    """Whether `spec_or_twin` says which flank its planet fault is on: a twin always does (its
    planet fault part's flank; the registry's default part, on both flanks, where it has none),
    a spec where a ``[[faults]]`` entry at the planet names ``flank``."""
    spec = spec_of(spec_or_twin)
    if spec is None:
        return True
    return any(f.get("location") == "planet" and f.get("flank") for f in spec["faults"])


def _flanks(spec_or_twin, location: str, flanks) -> tuple[str | None, ...]:
    """The planet-tooth flanks to fit (``(None,)``: the twin's fault as it is): `flanks` None
    gives :data:`PLANET_FLANKS` for a planet fault whose flank `spec_or_twin` does not name
    (:func:`_named_flank`), True gives them for any planet fault, a sequence gives those
    flanks, False none."""
    if flanks is None:
        flanks = location == "planet" and not _named_flank(spec_or_twin)
    if flanks is False:
        return (None,)
    if location != "planet":
        raise SettingsError(f"flanks are a planet tooth's; a {location} fault has none: leave "
                            "out flanks (--flanks) or fit a planet fault (location='planet', "
                            "--location planet)")
    chosen = PLANET_FLANKS if flanks is True else tuple(flanks)
    bad = [f for f in chosen if f not in PLANET_FLANKS]
    if bad or not chosen:
        raise SettingsError(f"flanks must be some of {PLANET_FLANKS}, got {list(chosen)}")
    return tuple(dict.fromkeys(chosen))


def _with_flank(problem, i: int, flank: str | None):
    """`problem` with its twin's fault ``parts[i]`` on `flank` (a static field: a new compiled
    fit per flank); None leaves it as it is."""
    if flank is None:
        return problem
    fault = problem.twin.parts[i].fault
    return eqx.tree_at(lambda p: p.twin.parts[i].fault, problem,
                       dataclasses.replace(fault, flank=flank))


def _fit_shapes(record, spec_or_twin, names, initial, ramps, fit_kwargs, low_band=None,
                splits=None, flanks=None):
    """``([(tags, FitResult)], note, low_band)``: one fit per loss shape (``ramps``; shape
    ``(ramp, spread)``, read back from each fit's twin), or one fit of the twin's own fault as it
    is (``ramps=None``), and the twin's note (:func:`_twin_kind`); with `low_band` the
    observation holds the low band too (:func:`with_low_band`; None: for a sun or ring fault on
    a steady spectrum record, :data:`LOW_BAND_LOCATIONS`; returned as used). With `splits`
    (None: where :func:`~dtwin.identify.excitation_response.stiffness_split` gives one) every shape is fitted
    again with the spec's other excitation/response split, and with `flanks` (:func:`_flanks`)
    on each planet-tooth flank. `tags` names what varies beyond the shape: ``"excitation"``
    (:data:`~dtwin.identify.excitation_response.SPLIT_CALIBRATED`, :data:`~dtwin.identify.excitation_response.SPLIT_STIFFNESS`)
    where two splits were fitted, ``"flank"`` where several flanks were."""
    location = names[0].removesuffix("_fault")
    flank_list = _flanks(spec_or_twin, location, flanks)
    pk, fk = _split_kwargs(dict(fit_kwargs))
    pk["kind"], note = _twin_kind(spec_or_twin, pk.get("kind"))
    other = other_split(spec_or_twin, names, splits)  # names[0] is the fault: None fits both
    specs = [(SPLIT_CALIBRATED, spec_or_twin), (SPLIT_STIFFNESS, other)] if other is not None \
        else [("", spec_or_twin)]
    out = []
    for split, sp_or_tw in specs:
        with warnings.catch_warnings():
            if note:  # said in the estimate's note, in other words
                warnings.filterwarnings("ignore", "this spec was calibrated with", UserWarning)
            problem, ops = make_problem(record, sp_or_tw, names, initial=initial, **pk)
        obs = problem.observations[0]
        if low_band is None:
            low_band = (obs.kind == "spectrum" and not obs.ramp and not obs.order_domain
                        and location in LOW_BAND_LOCATIONS)
        if low_band:
            problem = with_low_band_problem(problem, record, channel=pk.get("channel", 0))
        i = _fault_index(problem.twin, location)
        for flank in flank_list:
            tags = {"excitation": split} if split else {}
            if len(flank_list) > 1:
                tags["flank"] = flank
            on_flank = _with_flank(problem, i, flank)
            for shape in (None,) if ramps is None else _shapes(ramps):
                prob = on_flank if shape is None else _with_shape(on_flank, i, *shape)
                res = fit(record, sp_or_tw, names, problem=prob, **fk)
                res.operating_points = ops
                out.append((dict(tags), res))
    return out, note, bool(low_band)


def _jackknife_interval(res: FitResult, name: str) -> tuple[float, float]:
    """95 % interval of `name` from the delete-one-band jackknife of fit `res`
    (:func:`dtwin.identify.uncertainty.band_jackknife`; residuals and Jacobian at the optimum,
    as the fit left them, recomputed only when it kept none), mapped through the parameter's
    transform; (nan, nan) without enough bands."""
    prob = res.problem
    theta = jnp.asarray(res.theta)
    if res.residuals is not None and res.jacobian is not None:
        r, J = res.residuals, res.jacobian
    else:
        r, J = jacobian_at(theta, prob)
    n_prior = len(prob.pset.priors)
    groups = np.concatenate([point_groups(prob.observations), -1 - np.arange(n_prior)])
    half, _ = band_jackknife(np.asarray(theta), np.asarray(r), np.asarray(J), groups)
    i = res.names.index(name)
    if not np.isfinite(half[i]):
        return (float("nan"), float("nan"))
    th = np.asarray(theta, dtype=float)
    lo_t, hi_t = th.copy(), th.copy()
    lo_t[i] -= half[i]
    hi_t[i] += half[i]
    a = float(np.asarray(prob.pset.values(np.clip(lo_t, -50, 50)))[i])
    b = float(np.asarray(prob.pset.values(np.clip(hi_t, -50, 50)))[i])
    return (min(a, b), max(a, b))


def _healthy_accepted(res: FitResult, name: str, best_loss: float, tol: float) -> bool:
    """Whether the fit's twin with the fault at the low edge of its range (the other free
    parameters held at their values) loses no more than `tol` in ``‖r‖²`` against
    `best_loss` (module docstring)."""
    if res.problem is None or not np.isfinite(tol):
        return False
    vals = dict(res.values)
    vals[name] = float(res.problem.pset.lower[res.names.index(name)])  # pulled inside the
    # logit range by ParameterSet.theta
    theta0 = jnp.asarray(res.problem.pset.theta(vals))[None, :]
    loss0 = float(np.asarray(batched_loss(theta0, res.problem, "map"))[0])
    return bool(np.isfinite(loss0) and 2.0 * (loss0 - best_loss) <= tol)


def _estimate(location: str, shapes, jackknife: bool = False, note: str = "",
              low_band: bool = False) -> SeverityEstimate:
    """The estimate from the fits of one record over the loss shapes (module docstring);
    `note`: the twin's (:func:`_twin_kind`); `low_band`: whether the fits held the low band."""
    name = _name(location)
    losses = np.array([res.loss if np.isfinite(res.loss) else np.inf for _, res in shapes])
    b = int(np.argmin(losses))
    key_b, best = shapes[b]
    tags_b = key_b if isinstance(key_b, dict) else {}
    i = best.names.index(name)
    unc = best.uncertainty
    twin_b = best.problem.twin
    k = _fault_index(twin_b, location)
    sev = float(best.values[name])
    iv = (np.nan, np.nan) if unc is None else tuple(map(float, unc.interval[i]))
    # noise: χ²₁ in units of the residual variance (neighbours, lack-of-fit widening); model
    # form: what the best shape leaves unexplained beyond the noise (module docstring)
    tol = model_form_tolerance(unc, losses[b])
    rows, lo, hi, plo, phi = [], iv[0], iv[1], np.inf, -np.inf
    jk_wider = False
    for (key, res), loss in zip(shapes, losses, strict=True):
        accepted = bool(2.0 * (loss - losses[b]) <= tol)
        tw = res.problem.twin
        j = _fault_index(tw, location)
        s_j = float(res.values[name])
        row = {"ramp": float(tw.parts[j].fault.ramp), "spread": float(tw.parts[j].fault.spread),
               "loss": float(loss),
               "severity": s_j, "peak_stiffness_loss": _peak(tw, j, s_j), "accepted": accepted}
        if isinstance(key, dict):
            row.update(key)
        if res.uncertainty is not None:
            a, c = map(float, res.uncertainty.interval[res.names.index(name)])
            row["interval_95"] = [a, c]
            if jackknife and accepted:
                ja, jc = _jackknife_interval(res, name)
                row["jackknife_95"] = [ja, jc]
                if np.isfinite(ja) and (ja < a or jc > c):
                    a, c = min(a, ja), max(c, jc)
                    row["interval_95"] = [a, c]
                    jk_wider = True
            # the healthy waveform at the faulty tooth is not known: from its largest to its
            # smallest value (module docstring, "Peak stiffness loss")
            row["peak_interval_95"] = [_peak(tw, j, a, "max"), _peak(tw, j, c, "min")]
            if accepted:
                lo, hi = min(lo, a), max(hi, c)
                plo, phi = min(plo, row["peak_interval_95"][0]), max(phi, row["peak_interval_95"][1])
        rows.append(row)
    if not np.isfinite(plo):
        plo = phi = np.nan
    # a healthy tooth is a point of the fitted model (severity 0), not another model form:
    # the likelihood-ratio rule with the noise term alone (lack of fit included through s²)
    healthy_ok = unc is not None and _healthy_accepted(
        best, name, losses[b], CHI2_95 * unc.s2 * unc.kappa * unc.widened ** 2)
    if healthy_ok:  # the range's lower edge: 0 unless the user bounded it
        lo = float(best.problem.pset.lower[i])
        plo = _peak(twin_b, k, lo, "max")
    method = "profile" if unc is not None and name in unc.profiled else "gaussian"
    accepted = [r for r in rows if r["accepted"]]
    if len({(r["ramp"], r["spread"]) for r in accepted}) > 1:
        method += " + loss shapes"
    for tag, words in (("excitation", "excitation splits"), ("flank", "flanks")):
        if len({r.get(tag) for r in accepted}) > 1:  # what the fits' tags vary (_fit_shapes)
            method += f" + {words}"
    if jk_wider:
        method += " + band jackknife"
    if healthy_ok:
        method += " + healthy not rejected"
    det = unc is not None and name not in unc.not_determined and \
        0.5 * (hi - lo) <= HALF_WIDTH_LIMIT * max(abs(sev), 0.1)
    return SeverityEstimate(location, sev, (float(lo), float(hi)), bool(det), method, best,
                            peak_loss=_peak(twin_b, k, sev), peak_interval=(float(plo), float(phi)),
                            ramp=float(twin_b.parts[k].fault.ramp),
                            spread=float(twin_b.parts[k].fault.spread), widened=best.widened,
                            shapes=tuple(rows), note=note, low_band=low_band,
                            excitation=tags_b.get("excitation", ""),
                            flank=str(getattr(twin_b.parts[k].fault, "flank", ""))
                            if location == "planet" else "")


def _fitted_estimate(record, spec_or_twin, location, names, initial, ramps, fit_kwargs,
                     low_band, jackknife, splits=None, flanks=None, method=None,
                     healthy=None) -> SeverityEstimate:
    """The depth of one record by `method` (:data:`METHODS`; None: ``"ratio"`` for a steady
    record with the fault's severity the only free parameter and none of the spectrum fit's
    own options (`low_band`, `splits`, `flanks`) given, else ``"spectrum"``):
    :func:`_ratio_estimate`, or :func:`_fit_shapes` and :func:`_estimate` from its fits."""
    if method is not None and method not in METHODS:
        raise SettingsError(f"method must be one of {METHODS}, got {method!r}")
    if method == "ratio" and len(names) > 1:
        raise SettingsError("the sideband ratio reads a fault's depth alone: leave out the "
                            f"other free parameters ({', '.join(names[1:])}) or use "
                            "method='spectrum' (--method spectrum)")
    if method is None and any(x is not None for x in (low_band, splits, flanks)):
        method = "spectrum"  # asked for the spectrum fit's own options
    if method in (None, "ratio") and len(names) == 1:
        est = _ratio_estimate(record, spec_or_twin, location, names[0], initial, ramps,
                              fit_kwargs, healthy, required=method == "ratio")
        if est is not None:
            return est
    shapes, note, used = _fit_shapes(record, spec_or_twin, names, initial, ramps, fit_kwargs,
                                     low_band, splits, flanks)
    return _estimate(location, shapes, jackknife, note, used)


def bands_disagree(bands) -> tuple[Any, Any] | None:
    """The two bands of a sideband-ratio reading (:class:`~dtwin.identify.line_ratio.BandReading`)
    whose 95 % intervals exclude each other — the band whose interval starts highest and the
    one whose interval ends lowest — or None where every band holding fault lines over the
    noise admits one depth (module docstring, "The sideband ratio"). A band held at the grid's
    top (``"above the grid"``) reads at least its interval's lower end."""
    read = [b for b in bands if b.fault_bins > 0 and b.edge != "below detection"
            and np.isfinite(b.severity) and np.all(np.isfinite(b.interval))]
    if len(read) < 2:
        return None
    high = max(read, key=lambda b: b.interval[0])
    low = min(read, key=lambda b: math.inf if b.edge == "above the grid" else b.interval[1])
    top = math.inf if low.edge == "above the grid" else low.interval[1]
    return (high, low) if high.interval[0] > top else None


def _band_text(b) -> str:
    if b.edge == "above the grid":
        return f"{b.name} above {b.severity:.3g} (the grid's top)"
    return f"{b.name} {b.severity:.3g} [{b.interval[0]:.3g}, {b.interval[1]:.3g}]"


def _ratio_estimate(record, spec_or_twin, location: str, name: str, initial, ramps, fit_kwargs,
                    healthy=None, required: bool = False) -> SeverityEstimate | None:
    """The depth from the sideband ratio (module docstring, "The sideband ratio"): one reading
    per loss shape (``ramps``; None: the twin's fault as it is), the first shape's reported and
    the interval the hull over all; None where the record is no steady spectrum (a run-up, an
    order-domain fit) unless `required`, which then raises."""
    import time

    t0 = time.perf_counter()
    pk, _ = _split_kwargs(dict(fit_kwargs))
    pk["kind"], note = _twin_kind(spec_or_twin, pk.get("kind"))
    with warnings.catch_warnings():
        if note:
            warnings.filterwarnings("ignore", "this spec was calibrated with", UserWarning)
        problem, ops = make_problem(record, spec_or_twin, [name], initial=initial, **pk)
    obs = problem.observations[0]
    if obs.kind != "spectrum" or obs.ramp or obs.order_domain or len(problem.observations) > 1:
        if required:
            raise SettingsError("the sideband ratio needs one steady record's spectrum: use "
                                "method='spectrum' (--method spectrum) for a run-up, a "
                                "spectrogram or an order-domain fit")
        return None
    if note:
        note = (f"read with the {pk['kind']} twin (the {spec_of(spec_or_twin)['model']['kind']} "
                "twin this spec was calibrated with holds the sun and planets still under a "
                "tooth fault); the calibrated window and response cancel in the sideband ratio")
    i = _fault_index(problem.twin, location)
    readings: list[tuple[Any, LineRatio]] = []
    # the loss's shape is not known on a real machine: the twin's own fault is read, and the
    # interval spans the other shapes of SHAPE_GRID too (module docstring, "The sideband ratio")
    shapes = (None, *SHAPE_GRID[1:]) if ramps is None else _shapes(ramps)
    # the healthy twin (no fault: any shape) and every shape's grid in one batch
    f0 = problem.twin.parts[i].fault
    own = (float(f0.ramp), float(f0.spread))
    vals = [own if sh is None else (float(sh[0]), float(sh[1])) for sh in shapes]
    g = len(SEVERITY_GRID)
    p_tw = twin_powers(problem, 0, [0.0, *SEVERITY_GRID * len(vals)],
                       shapes=[vals[0], *(v for v in vals for _ in range(g))], part=i)
    for j, shape in enumerate(shapes):
        prob = problem if shape is None else _with_shape(problem, i, *shape)
        lr = line_ratio(prob, record, 0, channel=pk.get("channel", 0), healthy=healthy,
                        refine=j == 0, twin=(p_tw[0], p_tw[1 + j * g: 1 + (j + 1) * g]))
        readings.append((prob, lr))
    prob, lr = readings[0]
    twin = prob.twin
    sev = lr.severity
    band = lr.bands[0] if lr.bands else None
    edge = band.edge if band is not None else ""
    ok = [r for _, r in readings if np.isfinite(r.severity)]
    lo = min((r.interval[0] for r in ok), default=float("nan"))
    hi = max((r.interval[1] for r in ok), default=float("nan"))
    # the other end of the calibration's excitation/response split (module docstring, "The
    # healthy lines' excitation"): the first shape, its interval widened by the shapes' hull
    split = _split_reading(record, spec_or_twin, name, initial, pk, note, location, vals[0],
                           healthy, lr, lo, hi)
    split_wide = split_off = False
    if split is not None:
        s_prob, s_lr, s_iv = split
        split_wide = s_iv[0] < lo or s_iv[1] > hi
        lo, hi = min(lo, s_iv[0]), max(hi, s_iv[1])
        readings.append((s_prob, s_lr))
        # the two ends read the depth apart by more than the half-width limit
        split_off = bool(np.isfinite(sev) and np.isfinite(s_lr.severity) and edge == ""
                         and abs(s_lr.severity - sev) > HALF_WIDTH_LIMIT * max(abs(sev), 0.1))
    if not np.isfinite(sev):
        reason = "no band of the record holds the fault's lines and the healthy lines both"
    elif edge == "above the grid":
        reason = (f"the model does not fit this record: the twin's fault at severity "
                  f"{lr.grid[-1]:g} makes less sideband power than the record holds "
                  f"({band.record_db - band.twin_db[-1]:.1f} dB more in {band.name})")
    elif edge == "below detection":
        reason = f"no fault line stands {SIGNIFICANT_DB:g} dB over the noise"
    else:
        reason = ""
    apart = bands_disagree(lr.bands) if np.isfinite(sev) and edge == "" else None
    if apart is not None:
        reason = ("the bands disagree: a stiffness loss of one depth does not make this "
                  f"record's sidebands ({_band_text(apart[0])}, {_band_text(apart[1])}; a "
                  "profile deviation or a fault of another kind would)")
    determined = bool(np.isfinite(sev) and edge != "above the grid"
                      and (edge == "below detection"
                           or 0.5 * (hi - lo) <= HALF_WIDTH_LIMIT * max(abs(sev), 0.1))
                      and not split_off and apart is None)
    if split_off and not reason:
        reason = (f"the healthy lines' excitation is not known: the depth reads {sev:.3f} with "
                  f"the calibrated transmission error, {split[1].severity:.3f} with the "
                  "stiffness waveform's excitation alone, and a healthy record at one load "
                  f"cannot tell them apart (95 % over both: {lo:.3f}–{hi:.3f})")
    elif np.isfinite(sev) and not determined and not reason:
        what = "the loss's shapes, the healthy lines' excitation" if split_wide \
            else "the loss's shapes"
        reason = (f"{what} and the band's lines read {lo:.3f}–{hi:.3f}, wider than "
                  f"±{100 * HALF_WIDTH_LIMIT:.0f} % of {sev:.3f}")
    s_rep = sev if np.isfinite(sev) else float(problem.pset.x0[0])
    theta = np.asarray(problem.pset.theta([min(max(s_rep, 0.0), 1.0)]))
    res = FitResult(
        names=(name,), values={name: float(s_rep)}, theta=theta,
        initial={name: float(problem.pset.x0[0])}, uncertainty=None, loss=float("nan"),
        loss_history=[], start_losses=np.zeros(0), starts=np.zeros((0, 1)), refined=[],
        converged=bool(np.isfinite(sev)), at_bound=[name] if edge == "above the grid" else [],
        message="read from the sideband ratio (dtwin.identify.line_ratio)"
        + ("; refined on the twin" if lr.refined else ""),
        iterations=0, wall_time=time.perf_counter() - t0, operating_points=ops, problem=prob,
        read_intervals={name: (float(lo), float(hi))} if np.isfinite(lo) else {},
        read_reasons={} if determined else {name: reason})
    k = _fault_index(twin, location)
    method = "line ratio" + (" + loss shapes" if len(readings) > 1 else "")
    peak = _peak(twin, k, s_rep) if np.isfinite(sev) else float("nan")
    # each shape's severities in its own terms: the hull of their peak-loss intervals
    ends = [(_peak(p_.twin, k, r.interval[0], "max"), _peak(p_.twin, k, r.interval[1], "min"))
            for p_, r in (readings[:-1] if split is not None else readings)
            if np.isfinite(r.severity)]
    if split is not None:  # the split's interval, widened by the shapes' hull
        k_s = _fault_index(split[0].twin, location)
        ends.append((_peak(split[0].twin, k_s, split[2][0], "max"),
                     _peak(split[0].twin, k_s, split[2][1], "min")))
    piv = ((min(a for a, _ in ends), max(b for _, b in ends)) if ends
           else (float("nan"), float("nan")))
    rows = []
    for j, (p_, r) in enumerate(readings):
        f = p_.twin.parts[_fault_index(p_.twin, location)].fault
        row = {"ramp": float(f.ramp), "spread": float(f.spread), **r.to_dict()}
        if split is not None:
            row["excitation"] = SPLIT_STIFFNESS if j == len(readings) - 1 else SPLIT_CALIBRATED
        rows.append(row)
    return SeverityEstimate(
        location, float(s_rep), (float(lo), float(hi)), determined, method, res,
        peak_loss=peak, peak_interval=(float(piv[0]), float(piv[1])),
        ramp=float(twin.parts[k].fault.ramp), spread=float(twin.parts[k].fault.spread),
        note=note, flank=str(getattr(twin.parts[k].fault, "flank", ""))
        if location == "planet" else "", reason=reason, readings=tuple(rows),
        excitation=SPLIT_CALIBRATED if split is not None else "")


def _split_reading(record, spec_or_twin, name: str, initial, pk: dict, note: str,
                   location: str, shape: tuple[float, float], healthy, lr: LineRatio,
                   lo: float, hi: float):
    """The sideband ratio read on the other end of a calibrated spec's excitation/response
    split (:func:`~dtwin.identify.excitation_response.stiffness_split`; module docstring, "The
    healthy lines' excitation"), the loss `shape` of the reported reading `lr`:
    ``(problem, LineRatio, interval)``, the interval widened by the factors the loss shapes'
    hull `lo`, `hi` widens `lr`'s own; None for a spec without a split or a reading that
    cannot be made."""
    other = stiffness_split(spec_or_twin)
    if other is None:
        return None
    with warnings.catch_warnings():
        if note:
            warnings.filterwarnings("ignore", "this spec was calibrated with", UserWarning)
        problem, _ = make_problem(record, other, [name], initial=initial, **pk)
    i = _fault_index(problem.twin, location)
    problem = _with_shape(problem, i, *shape)
    g = len(SEVERITY_GRID)
    p_tw = twin_powers(problem, 0, [0.0, *SEVERITY_GRID], shapes=[shape] * (g + 1), part=i)
    s_lr = line_ratio(problem, record, 0, channel=pk.get("channel", 0), healthy=healthy,
                      refine=False, twin=(p_tw[0], p_tw[1:]))
    a, b = s_lr.interval
    if not (np.isfinite(a) and np.isfinite(b)):
        return None
    o_lo, o_hi = lr.interval
    f_lo = lo / o_lo if np.isfinite(lo) and o_lo > 0 else 1.0
    f_hi = hi / o_hi if np.isfinite(hi) and o_hi > 0 else 1.0
    return problem, s_lr, (a * min(f_lo, 1.0), min(b * max(f_hi, 1.0), 1.0))


def estimate_severity(
    record, spec_or_twin, location: str = "sun", *, free: Sequence[str] = (),
    initial_severity: float = 0.3, ramps: Sequence[float] | str | None = None,
    low_band: bool | None = None, jackknife: bool = True, splits: bool | None = None,
    flanks: bool | Sequence[str] | None = None, method: str | None = None, healthy=None,
    **fit_kwargs: Any,
) -> SeverityEstimate:
    """Severity of the fault at `location` from one record, and its peak stiffness loss
    (module docstring).

    **Arguments:** `record`; `spec_or_twin`; `location` (``sun``, ``planet``, ``ring``); `free`:
    further registry names fitted together; `initial_severity`; `ramps`: the loss shapes to try
    (edge widths in mesh cycles, ``"grid"`` for :data:`RAMP_GRID`, ``"shapes"`` for
    :data:`SHAPE_GRID`; None: the twin's fault as it is, one fit); `low_band`: fit the low band
    too (None: for a sun or ring fault on a steady record, :data:`LOW_BAND_LOCATIONS`);
    `jackknife`: widen the interval by the band jackknife where the bands disagree (module
    docstring; on by default); `splits`: fit a calibrated spec's other excitation/response split too (None:
    where it has one, :func:`~dtwin.identify.excitation_response.stiffness_split`; module docstring, "The
    calibration's split");
    `flanks`: for a planet fault, the planet-tooth flanks to fit (True: :data:`PLANET_FLANKS`;
    a sequence of them; False: the fault's own; None: all three unless the spec names the
    planet fault's flank; module docstring, "A planet fault's flank"); `method`: how the depth
    is read (:data:`METHODS`; None: ``"ratio"`` for a steady record with no other free
    parameter, else ``"spectrum"``; `low_band`, `jackknife`, `splits` and `flanks` are the
    spectrum fit's, and giving `low_band`, `splits` or `flanks` chooses it); `healthy`: a healthy record of the same machine at the same speed and
    rate, whose lines the ratio does not count as the fault's
    (:func:`dtwin.identify.line_ratio.line_ratio`); keyword arguments of
    :func:`dtwin.identify.fit.fit` (``kind``: default :data:`dtwin.spec.build.SEVERITY_KIND` for a
    spec, ``f_sun``, ``features``, ``starts``, ``progress`` …).
    """
    name = _name(location)
    names = [name] + [n for n in free if n != name]
    initial = dict(fit_kwargs.pop("initial", {}) or {})
    initial.setdefault(name, initial_severity)
    return _fitted_estimate(record, spec_or_twin, location, names, initial, ramps, fit_kwargs,
                            low_band, jackknife, splits, flanks, method, healthy)


@dataclasses.dataclass(frozen=True)
class SeveritySeries:
    """Trajectories over a series of records: `labels` (one per record), `names` (free
    parameters), `values` ``(records, params)`` (SI), `lower`/`upper` (95 %),
    `not_determined` (per record, names flagged), the fits, and per record the
    :class:`SeverityEstimate` (`estimates`: peak stiffness loss, its interval, the shape)."""

    labels: tuple[str, ...]
    names: tuple[str, ...]
    values: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    not_determined: tuple[tuple[str, ...], ...]
    fits: tuple[FitResult, ...] = dataclasses.field(repr=False)
    estimates: tuple[SeverityEstimate, ...] = dataclasses.field(default=(), repr=False)

    @property
    def peak_loss(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Peak stiffness loss per record (fraction) and its 95 % interval (lower, upper)."""
        e = self.estimates
        return (np.array([x.peak_loss for x in e]), np.array([x.peak_interval[0] for x in e]),
                np.array([x.peak_interval[1] for x in e]))

    def trajectory(self, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        i = self.names.index(name)
        return self.values[:, i], self.lower[:, i], self.upper[:, i]

    def to_dict(self) -> dict[str, Any]:
        return {"labels": list(self.labels), "names": list(self.names),
                "values": self.values.tolist(), "lower_95": self.lower.tolist(),
                "upper_95": self.upper.tolist(),
                "not_determined": [list(x) for x in self.not_determined],
                "estimates": [e.to_dict(with_fit=False) for e in self.estimates]}


def severity_series(
    records: Sequence, spec_or_twin, location: str = "sun", *, free: Sequence[str] = (),
    labels: Sequence[str] | None = None, initial_severity: float = 0.3, warm_start: bool = False,
    ramps: Sequence[float] | str | None = None, low_band: bool | None = None,
    jackknife: bool = True, splits: bool | None = None,
    flanks: bool | Sequence[str] | None = None, method: str | None = None, healthy=None,
    **fit_kwargs: Any,
) -> SeveritySeries:
    """Fit every record of a series (module docstring).

    **Arguments:** `records` (in time order); `spec_or_twin`; `location`; `free` (further
    parameters); `labels` (default ``record0`` …); `initial_severity`; `warm_start`: start each
    fit from the previous record's values (a slowly evolving machine); `ramps`, `low_band`,
    `jackknife`, `splits`, `flanks`, `method`, `healthy`: as for :func:`estimate_severity`;
    keyword arguments of
    :func:`dtwin.identify.fit.fit` (``kind`` as for :func:`estimate_severity`).
    """
    name = _name(location)
    names = [name] + [n for n in free if n != name]
    labels = tuple(labels) if labels is not None else tuple(f"record{i}" for i in range(len(records)))
    if len(labels) != len(records):
        raise SettingsError("labels need one entry per record")
    init = dict(fit_kwargs.pop("initial", {}) or {})
    init.setdefault(name, initial_severity)
    ests = []
    for rec in records:
        est = _fitted_estimate(rec, spec_or_twin, location, names, init, ramps,
                               dict(fit_kwargs), low_band, jackknife, splits, flanks, method,
                               healthy)
        ests.append(est)
        if warm_start:
            init = dict(est.fit.values)
    fits = [e.fit for e in ests]
    p = len(names)
    vals = np.array([[f.values[n] for n in names] for f in fits]).reshape(len(fits), p)
    lo = np.array([[f.interval(n)[0] if f.has_interval(n) else np.nan for n in names]
                   for f in fits])
    hi = np.array([[f.interval(n)[1] if f.has_interval(n) else np.nan for n in names]
                   for f in fits])
    lo, hi = lo.reshape(vals.shape), hi.reshape(vals.shape)
    lo[:, 0] = [e.interval[0] for e in ests]  # the severity: union over the accepted shapes
    hi[:, 0] = [e.interval[1] for e in ests]
    nd = tuple(tuple(f.not_determined) for f in fits)
    return SeveritySeries(labels, tuple(names), vals, lo, hi, nd, tuple(fits), tuple(ests))
