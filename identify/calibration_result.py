"""What a calibration found (:class:`CalibrationResult`, :class:`CalibratedParameter`), the
parameters' intervals and the calibrated spec written from the fitted values.

**Intervals.** Gauss–Newton at the optimum, with the residual variance estimated from the
residuals themselves (so lack of fit widens every interval). A parameter is *determined* when
the data shrink its prior standard deviation by at least half; *determined jointly* with others
when they do so only with the others held (its conditional standard deviation, ``1/sqrt`` of
its diagonal of the information, below half the prior's, its marginal one not), and the report
names those it trades with, by posterior correlation (a transmission-error harmonic's cosine
and sine: an amplitude spectrum fixes their amplitude, not their phase); *not determined*
otherwise. A knot of the response is determined when a measured line lies within its support
and its standard deviation is below 3 dB.
"""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Any, NamedTuple

import jax.numpy as jnp
import numpy as np

from dtwin._version import __version__
from dtwin.spec import Spec, load_spec, spec_to_dict
from dtwin.spec.writer import spec_to_toml

from .calibration_model import _SHARE_UNIT, _Data, _Layout, _residuals_and_jacobian, _shares
from .gap import GapResult

__all__ = ["CalibratedParameter", "CalibrationResult", "adoption"]


@dataclasses.dataclass(frozen=True)
class CalibratedParameter:
    """One calibrated quantity: value, unit, standard deviation and whether the data determine
    it (module docstring), with a short note."""

    name: str
    value: float
    unit: str
    sd: float
    prior_sd: float
    determined: bool
    note: str = ""
    #: when not `determined` alone but the data determine it with the others held (its
    #: conditional standard deviation below half the prior's): the parameters it trades with,
    #: as ``(name, correlation)``, the strongest first
    joint_with: tuple[tuple[str, float], ...] = ()

    @property
    def status(self) -> str:
        """``determined``, ``determined jointly with …`` or ``not determined``."""
        if self.determined:
            return "determined"
        if self.joint_with:
            return "determined jointly with " + ", ".join(
                f"{n} (correlation {r:+.2f})" for n, r in self.joint_with)
        return "not determined"

    def to_dict(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self), "status": self.status}


@dataclasses.dataclass
class CalibrationResult:
    """What :func:`calibrate` found.

    - `spec_data`: the calibrated spec as a mapping (write it with :meth:`write_spec`).
    - `parameters`: every calibrated quantity (:class:`CalibratedParameter`).
    - `f_sun` (Hz): the speed estimated from the records.
    - `gap_before`: held-out gap of the uncalibrated twin (a fitted gain only), dB per band.
    - `gap_heldout`: cross-validated gap of the calibrated model (fit on one half, scored on
      the other), dB per band.
    - `gap_confirmed`: gap of the calibrated twin simulated in full, no refit, dB per band.
    - `freqs` (Hz), `a_meas`, `a_before`, `a_after`: amplitude spectra (rows: record × half)
      of the records, the uncalibrated and the confirmed calibrated twin, in the record's unit.
    - `noise_rms`: the measured noise floor as an rms (record unit).
    - `records`: names of the records.
    - `fit_steps`: Levenberg–Marquardt steps of the final fit; `fit_converged`: False when it
      stopped at `CalibrationSettings.max_steps` with its loss still falling.
    - `linearisations`: the linearisation the calibrated values come from (1: the response
      at the spec's values; more when the full simulation departed from it and the fit was
      linearised again at its values, `CalibrationSettings.relinearize`).
    - `departure_db`: the confirmed gap minus the linearised response's gap at the calibrated
      values (dB, all data); `departs`: whether it stayed above
      `CalibrationSettings.relinearize_db` (the calibrated values lie where the response is
      not first order, and the held-out gap, which scores the linearised response, is
      optimistic: read the confirmed one).
    - `calibrated_confirmed_db`: the confirmed gap of the calibrated values (dB, all data),
      whether adopted or not; `heldout_full_db`: where the calibrated twin departs from the
      linearised response, its held-out gap simulated in full (dB; None when not measured).
    - `kept_spec`: the calibrated values did not bring the twin closer to the records than the
      spec as written (not `improves`), so `spec_data` keeps the spec's own values with only
      the response level fitted (one flat gain), as the "before" model; `parameters` and
      `gap_heldout` still describe the calibration that was not adopted, `gap_confirmed` and
      `a_after` the spec that was kept, simulated in full.
    """

    spec_data: dict[str, Any]
    parameters: list[CalibratedParameter]
    f_sun: float
    gap_before: GapResult
    gap_heldout: GapResult
    gap_confirmed: GapResult
    freqs: np.ndarray
    a_meas: np.ndarray
    a_before: np.ndarray
    a_after: np.ndarray
    noise_rms: float
    records: list[str]
    fit_steps: int = 0
    fit_converged: bool = True
    linearisations: int = 1
    departure_db: float = 0.0
    departs: bool = False
    kept_spec: bool = False
    calibrated_confirmed_db: float | None = None
    heldout_full_db: float | None = None

    @property
    def improves(self) -> bool:
        """Whether the calibrated values are adopted: the calibrated twin is closer to the
        records than the spec as written (:func:`adoption`, which says why not). When it is
        not, the healthy records hold something the calibrated parameters cannot represent (an
        effect for discovery), or the calibrated values lie where the twin is not first order
        in them, and the calibrated spec should not replace the user's."""
        return not self.rejection

    @property
    def rejection(self) -> str:
        """Why the calibrated values were not adopted ("" when they were: :func:`adoption`)."""
        return adoption(self.gap_before.total, self.gap_heldout.total,
                        self.calibrated_confirmed_db, self.heldout_full_db)

    @property
    def contact_margin(self) -> float | None:
        """The calibrated twin's least mesh deflection over its records, over the mean
        (``[calibration] contact_margin``; None where not measured): below 0 its teeth part
        every mesh cycle, which a healthy gearbox under load does not (docs/calibration.md,
        "Teeth that part")."""
        v = self.spec_data.get("calibration", {}).get("contact_margin")
        return None if v is None else float(v)

    @property
    def teeth_part(self) -> bool:
        """Whether the calibrated twin's teeth part (:attr:`contact_margin` below 0)."""
        return self.contact_margin is not None and self.contact_margin < 0

    @property
    def not_determined(self) -> list[str]:
        """Parameters the records determine neither alone nor jointly with the others."""
        return [p.name for p in self.parameters if not (p.determined or p.joint_with)]

    @property
    def jointly_determined(self) -> list[str]:
        """Parameters the records determine only jointly with others (their `joint_with`)."""
        return [p.name for p in self.parameters if not p.determined and p.joint_with]

    def spec(self) -> Spec:
        """The calibrated spec, validated."""
        return _spec_from_data(self.spec_data)

    def write_spec(self, path: str | os.PathLike) -> None:
        """Write the calibrated spec as TOML at `path` (a new file)."""
        with open(path, "x", encoding="utf-8") as f:
            f.write(spec_to_toml(self.spec_data, header=_HEADER))

    def table(self) -> str:
        rows = [f"speed {self.f_sun:.4f} Hz (from the records); noise floor rms "
                f"{self.noise_rms:.3g}",
                f"gap (dB): before {self.gap_before.total:.2f}, held-out "
                f"{self.gap_heldout.total:.2f}, confirmed {self.gap_confirmed.total:.2f}"
                + ("" if self.improves else f" (NOT adopted: {self.rejection}"
                   + ("; the spec's values kept, with its fitted level)" if self.kept_spec
                      else ")")),
                f"final fit: {self.fit_status}",
                *([f"the calibrated twin's teeth part every mesh cycle (least mesh deflection "
                   f"{self.contact_margin:.2f} of its mean): see docs/calibration.md, 'Teeth "
                   "that part'"] if self.teeth_part else []),
                f"{'parameter':<24} {'value':>12} {'sd':>10} {'unit':<6} status"]
        for p in self.parameters:
            status = p.status
            if p.note:
                status += f" ({p.note})"
            # six significant figures: a frequency knot of 2494.8 Hz is not 2495
            rows.append(f"{p.name:<24} {p.value:>12.6g} {p.sd:>10.2g} {p.unit:<6} {status}")
        return "\n".join(rows)

    @property
    def fit_status(self) -> str:
        """The final fit's stop, in words."""
        about = ("" if self.linearisations == 1 else
                 f", linearised at the fitted values (linearisation {self.linearisations})")
        if self.fit_converged:
            return f"converged in {self.fit_steps} Levenberg–Marquardt steps{about}"
        return (f"stopped at the step limit ({self.fit_steps} Levenberg–Marquardt steps) with "
                f"its loss still falling: raise CalibrationSettings.max_steps{about}")

    def to_dict(self) -> dict[str, Any]:
        return dict(
            f_sun=self.f_sun, records=self.records, noise_rms=self.noise_rms,
            fit_steps=self.fit_steps, fit_converged=self.fit_converged,
            linearisations=self.linearisations, departure_db=self.departure_db,
            departs=self.departs,
            gap_before=self.gap_before.to_dict(), gap_heldout=self.gap_heldout.to_dict(),
            gap_confirmed=self.gap_confirmed.to_dict(),
            parameters=[p.to_dict() for p in self.parameters],
            not_determined=self.not_determined, jointly_determined=self.jointly_determined,
            improves=self.improves, kept_spec=self.kept_spec,
            calibrated_confirmed_db=self.calibrated_confirmed_db,
            heldout_full_db=self.heldout_full_db, rejection=self.rejection,
            contact_margin=self.contact_margin, teeth_part=self.teeth_part,
        )


_HEADER = ("Calibrated by dtwin calibrate: fitted from healthy records (see [calibration]).\n"
           "The user's spec is unchanged; this file adds the fitted window shape, mesh\n"
           "excitation, mesh damping and sensor frequency response.")


def _spec_from_data(data: dict[str, Any]) -> Spec:
    import tempfile

    with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False, encoding="utf-8") as f:
        f.write(spec_to_toml(data))
        path = f.name
    try:
        return load_spec(path)
    finally:
        os.unlink(path)


class _Stamp(NamedTuple):
    """What every calibrated spec records of its calibration: the records' speed (Hz), rate
    (Hz), the quantity their unit names (None: the spec's stays), their names, the twin kind
    (None: the spec's)."""

    f_sun: float
    fs: float
    measured: str | None
    names: tuple[str, ...]
    kind: str | None


def _stamped(data: dict[str, Any], stamp: _Stamp) -> dict[str, Any]:
    """`data` (a spec mapping) with the records' speed, rate and quantity, the twin kind and
    the ``[calibration]`` table (`_Stamp`)."""
    sensor = data["sensor"]
    sensor["sample_rate"] = float(stamp.fs)  # the calibrated records' (knots reach 0.45 of it)
    if stamp.measured:  # what the records measure, as the calibration simulated it
        sensor["quantity"] = stamp.measured
    data["operating"]["f_sun"] = float(stamp.f_sun)
    if stamp.kind:
        data["model"]["kind"] = stamp.kind
    data["calibration"] = {"records": ", ".join(stamp.names),
                           "created_by": f"dtwin {__version__}"}
    return data


def _kept_data(spec: Spec, gain_db: float, knots, stamp: _Stamp, why: str) -> dict[str, Any]:
    """The spec as written, as a calibrated spec: its own values, a flat sensor response at
    the fitted level `gain_db` (dB at every knot), the records' speed, rate and quantity, and
    the ``[calibration]`` table saying that the calibrated values were not adopted, and `why`
    (:func:`adoption`)."""
    data = spec_to_dict(spec)
    data.pop("source", None)
    data["sensor"]["frf_hz"] = [float(v) for v in knots]
    data["sensor"]["frf_db"] = [float(gain_db)] * len(knots)
    data = _stamped(data, stamp)
    data["calibration"]["kept_spec"] = (f"the calibrated values were not adopted ({why}): the "
                                        "spec's own values, with its fitted response level")
    return data


def _intervals(theta, G, data: _Data, layout: _Layout, knots, Wl, B, twin, i_exc,
               settings) -> list[CalibratedParameter]:
    r, Jr = _residuals_and_jacobian(jnp.asarray(theta), data)
    r, Jr = np.asarray(r), np.asarray(Jr)
    m_data = int(np.asarray(data.S).sum())
    p = len(theta)
    n_prior = p
    rss = float(np.sum(r[:-n_prior] ** 2))
    s2 = max(rss / max(m_data - p - len(knots), 1), 1e-12)
    # data rows scaled by the residual variance; prior rows keep their unit variance
    Jd, Jp = Jr[:-n_prior], Jr[-n_prior:]
    info = Jd.T @ Jd / s2 + Jp.T @ Jp
    cov = np.linalg.pinv(info)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    prior = np.asarray(data.prior_sd)
    names = ([f"window_c{k + 1}" for k in range(layout.n_window)]
             + [f"excitation_ring_{cs}_{i + 1}" for cs in ("cos", "sin")
                for i in range(layout.n_harm)]
             + [f"load_share_{i}" for i in range(1, layout.n_share + 1)] + ["zeta_mesh"])
    joint = _joint(cov, info, prior, names)
    out = []
    c = np.asarray(layout.c_init)
    for k in range(layout.n_window):
        val = c[k + 1] + layout.window_scale * theta[k]
        out.append(CalibratedParameter(
            names[k], float(val), "1", float(layout.window_scale * sd[k]),
            float(layout.window_scale * prior[k]), bool(sd[k] < 0.5 * prior[k]),
            joint_with=joint[k]))
    exc = twin.parts[i_exc]
    h = layout.n_harm
    for j, base in enumerate((exc.ring_cos, exc.ring_sin)):
        for i in range(h):
            k = layout.n_window + j * h + i
            val = float(base[i]) + layout.te_scale * theta[k]
            out.append(CalibratedParameter(
                names[k], val, "m", float(layout.te_scale * sd[k]),
                float(layout.te_scale * prior[k]), bool(sd[k] < 0.5 * prior[k]),
                "with the response at this harmonic: one sensor sees their product",
                joint[k]))
    shares = np.asarray(_shares(jnp.asarray(theta), layout)) if layout.n_share else ()
    for i in range(layout.n_share):
        k = layout.i_share + i
        out.append(CalibratedParameter(
            names[k], float(shares[i + 1]), "1", float(_SHARE_UNIT * sd[k]),
            float(_SHARE_UNIT * prior[k]), bool(sd[k] < 0.5 * prior[k]),
            "load share relative to planet 0", joint[k]))
    k = layout.i_zeta
    z0 = float(twin.lp.zeta_ring_planet)
    out.append(CalibratedParameter("zeta_mesh", z0 * math.exp(theta[k]), "1",
                                   z0 * math.exp(theta[k]) * float(sd[k]),
                                   z0 * float(prior[k]), bool(sd[k] < 0.5 * prior[k]),
                                   "sd of the log value times the value", joint[k]))
    # response knots: covariance of the closed-form solve at the optimum
    W = np.asarray(data.W)
    BtWB = np.einsum("rb,bi,bj->ij", W, B, B)
    k_n = len(knots)
    P = np.eye(k_n) / settings.frf_prior_db**2
    if k_n >= 3:
        L = np.diff(np.eye(k_n), n=2, axis=0)
        P = P + L.T @ L / settings.smooth_db**2
    covG = np.linalg.pinv(BtWB / s2 + P)
    support = (W.sum(axis=0) @ (B > 0.05)) > 0
    for j, f in enumerate(knots):
        sdj = float(np.sqrt(max(covG[j, j], 0.0)))
        out.append(CalibratedParameter(
            f"frf_db_{j}", float(G[j]), "dB", sdj, settings.frf_prior_db,
            bool(support[j] and sdj < 3.0), f"response at {f:.6g} Hz"
            + ("" if support[j] else "; no measured line near this knot")))
    return out


def _joint(cov, info, prior, names, n_max: int = 3) -> list[tuple[tuple[str, float], ...]]:
    """For each parameter the data do not determine alone (marginal sd ≥ half the prior's) but
    do with the others held (conditional sd ``1/sqrt(info_kk)`` below half the prior's): the
    `n_max` parameters most correlated with it in the posterior, with their correlations.
    Empty for the others."""
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    cond = 1.0 / np.sqrt(np.clip(np.diag(info), 1e-300, None))
    corr = cov / np.maximum(np.outer(sd, sd), 1e-300)
    out = []
    for k in range(len(names)):
        if sd[k] < 0.5 * prior[k] or not cond[k] < 0.5 * prior[k]:
            out.append(())
            continue
        others = [j for j in np.argsort(-np.abs(corr[k])) if j != k][:n_max]
        out.append(tuple((names[j], round(float(corr[k, j]), 2)) for j in others))
    return out


def _calibrated_data(spec: Spec, theta, G, knots, layout: _Layout, twin, i_exc,
                     stamp: _Stamp) -> dict[str, Any]:
    data = spec_to_dict(spec)
    data.pop("source", None)
    c = np.asarray(layout.c_init).copy()
    c[1:] += layout.window_scale * np.asarray(theta[: layout.n_window])
    sensor = data["sensor"]
    sensor["window_harmonics"] = [float(v) for v in c]
    sensor["frf_hz"] = [float(v) for v in knots]
    sensor["frf_db"] = [float(v) for v in G]
    h = layout.n_harm
    te = np.asarray(theta[layout.n_window: layout.n_window + 2 * h]) * layout.te_scale
    exc = twin.parts[i_exc]
    mesh = data["mesh"]
    mesh["excitation_ring_cos"] = [float(v) for v in np.asarray(exc.ring_cos) + te[:h]]
    mesh["excitation_ring_sin"] = [float(v) for v in np.asarray(exc.ring_sin) + te[h:]]
    mesh["excitation_sun_cos"] = [float(v) for v in np.asarray(exc.sun_cos)]
    mesh["excitation_sun_sin"] = [float(v) for v in np.asarray(exc.sun_sin)]
    if layout.n_share:
        data["imperfections"]["load_sharing"] = [
            float(v) for v in np.asarray(_shares(jnp.asarray(theta), layout))]
    z = float(twin.lp.zeta_ring_planet) * math.exp(float(theta[layout.i_zeta]))
    z = min(max(z, 1e-6), 0.499)
    damping = data["damping"]
    damping["zeta_mesh"] = z
    damping.pop("zeta_sun_planet", None)
    damping.pop("zeta_ring_planet", None)
    return _stamped(data, stamp)


def adoption(before: float, heldout: float, confirmed: float | None,
             heldout_full: float | None = None) -> str:
    """Whether calibrated values are adopted, from the gaps (dB) of the spec as written
    (`before`: one fitted level, held out), of the calibration held out (`heldout`: the
    linearised response fitted on one half and scored on the other), of the calibrated twin
    simulated in full (`confirmed`, all data; None when not measured) and, where that twin
    departs from the linearised response, of the twin held out (`heldout_full`: each half's
    values simulated in full and scored on the other half; None when not measured). Adopted
    when:

    1. the held-out gap is below the spec's (cross-validation);
    2. the confirmed gap is below it too: the twin simulated in full bears the linearised
       response out;
    3. where measured, the held-out gap of the twin simulated in full is below it: where the
       twin departs from the linearised response, the held-out gap of 1. scores a response the
       twin does not follow, and only the twin's own cross-validation says whether the values
       generalise.

    **Returns:** "" when adopted, otherwise the reason, in words."""
    if not heldout < before:
        return (f"no closer to the held-out halves than the spec as written, {heldout:.2f} "
                f"against {before:.2f} dB")
    if confirmed is not None and not confirmed < before:
        return (f"no closer to the records than the spec as written once simulated in full, "
                f"{confirmed:.2f} against {before:.2f} dB")
    if heldout_full is not None and not heldout_full < before:
        return (f"simulated in full, no closer to the held-out halves than the spec as "
                f"written, {heldout_full:.2f} against {before:.2f} dB")
    return ""
