"""The calibration's excitation/response split, and which end of it a faulty record prefers.

A healthy record at one load measures each mesh harmonic as the product of the mesh's
excitation and the sensor's response at that frequency (:mod:`dtwin.identify.calibrate`). The
calibration's transmission-error harmonics and response knots split that product one way; a twin
whose response is some dB higher at the mesh band while its transmission error cancels as much
of the stiffness waveform's excitation fits the healthy record as well (or better, where the
twin's own sun and ring excitations do not match the machine's). A tooth fault is not cancelled:
its sidebands, the stiffness it removes (N/m) times the static mesh deflection, pass the
response as it is, so a response too high at the mesh band reads the fault too small by the
same factor. The faulty record can tell the splits apart, since the fault's own lines fix the
response against the stiffness the fault removes.

So a fault severity is fitted with both ends of the split: the calibrated spec as it is
(:data:`SPLIT_CALIBRATED`), and the same spec with the stiffness waveform's excitation alone
and a flat response (:data:`SPLIT_STIFFNESS`, :func:`stiffness_split`); window, damping and
load shares stay as calibrated. The fits are scored by one rule (:func:`model_form_tolerance`):
the split of least loss is reported (for a sun or ring fault fitted on the mesh bands, the loss
with the low band added, which the fits did not use: :func:`low_band_losses`; there a small
fault's comb stands tens of dB over the floor where its mesh sidebands stand a few, and the
mesh lines, which the calibrated split was chosen to fit, would otherwise decide), and a split
whose ``‖r‖²`` exceeds it by no more than the larger of ``χ²₁(95 %)`` in units of the residual
variance and what the best fit leaves unexplained beyond the noise cannot be rejected.
:func:`choose_split` applies it to two :class:`~dtwin.identify.fit_result.FitResult`;
:func:`fit_both_ends` and :func:`fit_batch_both_ends` fit both ends and choose (called by
:func:`dtwin.identify.fit.fit` and :func:`~dtwin.identify.fit_batch.fit_batch`, so by ``dtwin
identify`` and ``dtwin fleet``); :mod:`dtwin.identify.severity` applies the rule over its loss
shapes and flanks too.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import jax.numpy as jnp
import numpy as np

from dtwin.errors import DtwinError, FitError, SettingsError
from dtwin.model.registry import lookup
from dtwin.spec import Spec, load_spec, spec_to_dict

from .confounding import calibrated_excitation
from .low_band import LOW_BAND_LOCATIONS, with_low_band_problem
from .problem import calibrated_spec, make_problem
from .residuals import Features
from .solve import batched_loss
from .uncertainty import CHI2_95, HALF_WIDTH_LIMIT, Uncertainty, half_width_scale

if TYPE_CHECKING:
    from .fit_result import FitResult
    from .fit_settings import FitSettings

__all__ = ["LOW_BAND_FAULTS", "SPLIT_CALIBRATED", "SPLIT_STIFFNESS", "choose_split",
           "fault_names", "fit_batch_both_ends", "fit_both_ends", "low_band_losses",
           "model_form_tolerance", "other_split", "stiffness_split"]

#: What each end of a calibrated spec's excitation/response split is called in results.
SPLIT_CALIBRATED = "calibrated"
SPLIT_STIFFNESS = "stiffness waveform, flat response"
#: Fault severities whose split is scored with the low band too: those of
#: :data:`dtwin.identify.low_band.LOW_BAND_LOCATIONS` (the sun's and the ring's comb lies where
#: the records put it).
LOW_BAND_FAULTS = tuple(f"{loc}_fault" for loc in LOW_BAND_LOCATIONS)


def stiffness_split(spec_or_twin) -> Spec | None:
    """The other end of a calibrated spec's excitation/response split (module docstring): the
    same spec with its mesh excitation back at the stiffness waveform's own (every ``[mesh]
    excitation_*`` transmission-error harmonic 0 m) and a flat sensor response at the calibrated
    knots' mean level (dB); window, damping and load shares as calibrated. None for a twin, an
    uncalibrated spec, or a calibrated spec that has neither (a calibration that kept the spec's
    values). The spec handed in is not modified."""
    spec = calibrated_spec(spec_or_twin)
    if spec is None:
        return None
    data = spec_to_dict(spec)
    data.pop("source", None)
    mesh, sensor = data["mesh"], data["sensor"]
    te = bool(calibrated_excitation(spec))
    frf = sensor.get("frf_db")
    shaped = frf is not None and len(frf) > 1 and float(np.ptp(np.asarray(frf, float))) > 0.0
    if not (te or shaped):
        return None
    for k, v in mesh.items():
        if k.startswith("excitation_") and v is not None:
            mesh[k] = [0.0] * len(v)
    if shaped:
        sensor["frf_db"] = [float(np.mean(frf))] * len(frf)
    return load_spec(data)


def fault_names(names: Sequence[str]) -> tuple[str, ...]:
    """The names among `names` that are a tooth fault's severity (registry ``faults.*``)."""
    return tuple(n for n in names if lookup(n).spec_path.startswith("faults."))


def other_split(spec_or_twin, names: Sequence[str], splits: bool | None) -> Spec | None:
    """The spec to fit beside `spec_or_twin` (:func:`stiffness_split`), or None: `splits` None
    gives it where a fault severity is among `names` and the spec has a split, True wherever the
    spec has one (a clear error where it has none), False never."""
    if splits is False:
        return None
    if splits is None and not fault_names(names):
        return None
    other = stiffness_split(spec_or_twin)
    if splits and other is None:
        raise SettingsError("splits=True (--splits) needs a calibrated spec with a calibrated "
                            "mesh excitation or sensor response (dtwin calibrate); this one has "
                            "none: leave the option out")
    return other


def model_form_tolerance(unc: Uncertainty | None, loss: float) -> float:
    """How far (in ``‖r‖²``) a fit of another model form may lie above the best fit, of loss
    `loss` (½‖r‖²) and uncertainty `unc`, and not be rejected: the larger of ``χ²₁(95 %)`` in
    units of the residual variance (neighbour-correlation and lack-of-fit factors included) and
    what the best fit leaves unexplained beyond the noise, ``‖r‖² − E``
    (:func:`dtwin.identify.uncertainty.expected_noise_rss`). Infinite without `unc`."""
    if unc is None:
        return float("inf")
    rss = 2.0 * float(loss)
    lof = float(unc.lack_of_fit)
    excess = rss - rss / lof if np.isfinite(lof) and lof > 0 else 0.0
    return max(CHI2_95 * unc.s2 * unc.kappa * unc.widened ** 2, excess)


def choose_split(fits: Sequence[tuple[str, FitResult]],
                 scores: Sequence[float] | None = None) -> FitResult:
    """The fit of least loss among `fits` (``(split, FitResult)``, the same parameters, one
    record set), or of least `scores` where given (:func:`low_band_losses`), with
    ``excitation`` set to its split and ``splits`` to a row per fit (split, loss, score, values,
    95 % intervals, accepted). Where another split is accepted (its loss or score within
    :func:`model_form_tolerance` of the best fit's) every interval is the union over the
    accepted splits, and a parameter whose union half-width exceeds ``HALF_WIDTH_LIMIT`` of its
    scale is flagged not determined, naming what each split read."""
    fit_losses = np.array([r.loss if np.isfinite(r.loss) else np.inf for _, r in fits])
    losses = fit_losses if scores is None else \
        np.array([v if np.isfinite(v) else np.inf for v in scores])
    b = int(np.argmin(losses))
    name_b, best = fits[b]
    tol = model_form_tolerance(best.uncertainty, fit_losses[b])
    rows: list[dict[str, Any]] = []
    for (split, res), loss, fit_loss in zip(fits, losses, fit_losses, strict=True):
        row: dict[str, Any] = {"excitation": split, "loss": float(fit_loss),
                               "values": dict(res.values),
                               "accepted": bool(2.0 * (loss - losses[b]) <= tol)}
        if scores is not None:
            row["low_band_loss"] = float(loss)
        if res.uncertainty is not None:
            row["intervals_95"] = {n: list(map(float, res.uncertainty.interval[i]))
                                   for i, n in enumerate(res.names)}
        rows.append(row)
    unc = best.uncertainty
    accepted = [(s, r) for (s, r), row in zip(fits, rows, strict=True) if row["accepted"]]
    if unc is not None and len(accepted) > 1:
        interval = np.array(unc.interval, dtype=float, copy=True)
        flags = dict(unc.not_determined)
        for i, n in enumerate(best.names):
            for _, r in accepted:
                if r.uncertainty is not None:
                    a, c = r.uncertainty.interval[r.names.index(n)]
                    interval[i] = (min(interval[i, 0], a), max(interval[i, 1], c))
            half = 0.5 * (interval[i, 1] - interval[i, 0])
            pset = best.problem.pset if best.problem is not None else None
            ref = abs(float(best.values[n])) if pset is None else half_width_scale(
                float(best.values[n]), pset.transforms[i], pset.lower[i], pset.upper[i])
            if n not in flags and not half <= HALF_WIDTH_LIMIT * ref:
                read = ", ".join(f"{r.values[n]:.4g} ({s})" for s, r in accepted)
                flags[n] = (f"the calibration's excitation/response splits the record cannot "
                            f"tell apart read it {read}; 95 % interval over both "
                            f"[{interval[i, 0]:.4g}, {interval[i, 1]:.4g}]")
        best.uncertainty = dataclasses.replace(unc, interval=interval, not_determined=flags)
    best.excitation = name_b
    best.splits = rows
    best.wall_time = float(sum(r.wall_time for _, r in fits))
    return best


def low_band_losses(fits: Sequence[tuple[Any, FitResult]], records, names: Sequence[str],
                    problem_kwargs: dict[str, Any]) -> list[float] | None:
    """Each fit's loss (½‖r‖²) over its own points and the low band of `records` (the fault's
    comb below the first mesh band, :func:`dtwin.identify.low_band.with_low_band`), at its fitted
    values: `fits` are ``(spec, FitResult)`` of one record set. The low band is where a small
    sun or ring fault makes its strongest lines and where the fit did not look, so it scores the
    splits on data the fits did not use. A fit on the DFT grid is scored with its own problem
    and the low band added; one in the order domain with a DFT-grid problem of the same record
    at the fitted values and operating point. None where it does not apply (the fits are then
    scored by their own losses): no sun or ring fault among `names` (:data:`LOW_BAND_FAULTS`), a
    run-up, a fit without uncertainty, or a score that could not be computed."""
    if not any(n in LOW_BAND_FAULTS for n in names):
        return None
    recs = list(records) if isinstance(records, (list, tuple)) else [records]
    channel = problem_kwargs.get("channel", 0)
    keep = {k: v for k, v in problem_kwargs.items()
            if k not in ("features", "weights", "f_sun", "initial", "runup")}
    out = []
    for spec, res in fits:
        prob = res.problem
        if prob is None or res.uncertainty is None or \
                any(o.kind != "spectrum" or o.ramp for o in prob.observations):
            return None
        theta = np.asarray(res.theta)
        if any(o.order_domain for o in prob.observations):
            f_sun = [op.get("f_sun") for op in res.operating_points]
            if len(f_sun) != len(recs) or any(f is None for f in f_sun):
                return None
            try:
                prob, _ = make_problem(recs, spec, list(res.names), initial=dict(res.values),
                                       f_sun=f_sun, features=Features(), **keep)
            except DtwinError:  # scored by the fits' own losses then
                return None
            theta = np.zeros_like(theta)
        if len(prob.observations) != len(recs):
            return None
        prob = with_low_band_problem(prob, recs, channel=channel)
        out.append(float(np.asarray(batched_loss(jnp.asarray(theta)[None], prob, "map"))[0]))
    return out if all(np.isfinite(out)) else None


def fit_both_ends(fit_one, records, specs: tuple[Any, Spec], free, names: Sequence[str],
                  settings: FitSettings, problem_kwargs: dict[str, Any]) -> FitResult:
    """`records` fitted with each of `specs` (the spec as given, :data:`SPLIT_CALIBRATED`, and
    its :func:`stiffness_split`, :data:`SPLIT_STIFFNESS`) by ``fit_one(records, spec, free,
    settings, **problem_kwargs)`` (:func:`dtwin.identify.fit.fit_one`), and the split chosen
    (:func:`choose_split`, scored with the low band where it applies: :func:`low_band_losses`).
    With ``settings.throw`` a result not converged or at a bound raises `FitError`."""
    each = dataclasses.replace(settings, splits=False, throw=False)
    pair = [(spec, fit_one(records, spec, free, each, **problem_kwargs)) for spec in specs]
    res = choose_split([(SPLIT_CALIBRATED, pair[0][1]), (SPLIT_STIFFNESS, pair[1][1])],
                       low_band_losses(pair, records, names, problem_kwargs))
    if settings.throw and (not res.converged or res.at_bound):
        raise FitError(res.message)
    return res


def fit_batch_both_ends(fit_batch, records: Sequence, specs: tuple[Any, Spec], free,
                        names: Sequence[str], settings: FitSettings,
                        problem_kwargs: dict[str, Any]) -> list[FitResult]:
    """:func:`fit_both_ends` for a batch: ``fit_batch(records, spec, free, settings,
    **problem_kwargs)`` (:func:`dtwin.identify.fit_batch.fit_batch`) with each of `specs`, a
    batch each, and the split chosen per record."""
    each = dataclasses.replace(settings, splits=False)
    a_fits = fit_batch(records, specs[0], free, each, **problem_kwargs)
    b_fits = fit_batch(records, specs[1], free, each, **problem_kwargs)
    return [choose_split([(SPLIT_CALIBRATED, a), (SPLIT_STIFFNESS, b)],
                         low_band_losses([(specs[0], a), (specs[1], b)], rec, names,
                                         problem_kwargs))
            for rec, a, b in zip(records, a_fits, b_fits, strict=True)]
