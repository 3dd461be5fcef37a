"""The discrepancy search loop (:func:`discover`; the method in the package docstring)."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from dtwin import _maps
from dtwin.build import build_twin, daq_from_spec, twin_kind
from dtwin.errors import DtwinError
from dtwin.io.record import Record
from dtwin.spec import Spec, load_spec
from dtwin.spectrum import amplitude_spectrum, as_signal, noise_floor
from dtwin.units import quantity as unit_quantity

from ..effects import registered_effects
from ..effects.base import EffectContext
from ..gap import FLOOR_BINS, gap, named_bands, segment_spectra
from ..lines import (
    Kinematics,
    band_bounds,
    chance_match_probability,
    find_combs,
    find_modulation,
    label_combs,
    modulation_lines,
    residual_lines,
)
from ..operating_point import resolve_speed
from ..shortfall import SHORTFALL_SHARE, shortfall_share
from .candidates import _adapted, _bins_of, _dilate, coverage, signature_labels
from .in_range import in_range_trials, refit_in_range
from .model import extended_model
from .results import CandidateResult, DiscoveryResult, Step
from .settings import DiscoverySettings
from .statistics import (
    amplitude_profile,
    candidate_inputs,
    chi2_quantile,
    fit_joint,
    heldout_statistic,
    is_identified,
    normal_quantile,
    null_statistics,
    p_value,
    residual_variance,
    screen_score,
    theta_of,
)


def _log_gain(Y, Z0, floor, thr_db, n_lines: int = 20) -> float:
    """Log of the gain that scales the model's amplitude `Z0` to the measured `Y`: the median
    log ratio over the bins where both stand `thr_db` over the floor, started from the model's
    `n_lines` strongest lines and iterated (three passes). Starting from every bin where the
    measurement has a line would let lines the model lacks (a fault's comb, where the model
    holds only numerical leakage) set the gain: on the independent sun-fault record that
    put the model 54 dB too high."""
    a0 = np.abs(Z0)
    if not np.any(a0 > 0):
        return 0.0
    thr = floor * 10 ** (thr_db / 20.0)
    pk = np.flatnonzero((a0[1:-1] >= a0[:-2]) & (a0[1:-1] >= a0[2:]) & (a0[1:-1] > 0)) + 1
    if pk.size == 0:
        return 0.0
    pk = pk[np.argsort(a0[pk])[::-1][:n_lines]]
    g = float(np.median(np.log(np.maximum(Y[pk], 1e-300) / a0[pk])))
    for _ in range(3):
        sel = (Y > thr) & (np.exp(g) * a0 > thr)
        if not sel.any():
            break
        g = float(np.median(np.log(Y[sel] / a0[sel])))
    return g


def _set_score(cr: CandidateResult, scores: dict, i: int, covering: list) -> None:
    """Copy candidate `i`'s screening score and rank into `cr` (nothing without screening)."""
    if i not in scores:
        return
    cr.score, cr.score_df, cr.score_log10p = scores[i]
    cr.score_rank = 1 + [j for _, j, _ in covering].index(i)


def _on_added(r, families, tol):
    """The label of line `r` on the family of a located modulation already added (`families`:
    ``(f_x, step, frequencies, labels)``), or "" when it lies on none or a describing
    combination lies closer to it than the family's line."""
    for f_x, step, ff, labels in families:
        i = int(np.argmin(np.abs(ff - r.frequency)))
        d = abs(ff[i] - r.frequency)
        if d <= tol and all(abs(x.frequency - r.frequency) > d for x in r.descriptions):
            return f"{labels[i]} (fx = {f_x:.2f} Hz, the fluctuation added in step {step})"
    return ""


def _labelled(lines, kin, tol, f_max, added_fx=()):
    """Residual lines with their comb and located-modulation labels
    (:func:`dtwin.identify.lines.find_combs`, :func:`~dtwin.identify.lines.find_modulation`):
    ``(lines, combs, modulation)``. `added_fx`: ``(f_x, step)`` of the located modulations
    already added; a measured line left on their family (the twin's level there falls short) is
    labelled as theirs rather than "no kinematic match" or a combination farther from it, and
    is no trial for a new modulation. A modulation located off the combinations that described
    its line (:attr:`dtwin.identify.lines.Modulation.off`) takes its family's lines from the
    combs and their descriptions."""
    families = []
    for f_x, step in added_fx:
        fam = modulation_lines(kin, f_x, f_max)
        families.append((f_x, step, np.array([f for f, _ in fam]), [t for _, t in fam]))
    added = {r.frequency: lab for r in lines if r.side == "measured"
             for lab in [_on_added(r, families, tol)] if lab}
    combs = find_combs(lines, kin, tol, f_max)
    mod = find_modulation([r for r in label_combs(lines, combs) if r.frequency not in added],
                          kin, tol, f_max, combs=combs)
    if mod is not None and mod.off:
        held = {f for f, _ in mod.members}
        combs = find_combs([r for r in lines if r.frequency not in held], kin, tol, f_max)
        lines = [dataclasses.replace(r, descriptions=())
                 if r.side == "measured" and r.frequency in held else r for r in lines]
    lines = label_combs(lines, combs)
    if mod is not None:
        lab = {f: f"{text} (fx = {mod.f_x:.2f} Hz)" for f, text in mod.members}
        lines = [dataclasses.replace(r, comb=lab[r.frequency])
                 if r.side == "measured" and not r.comb and r.frequency in lab else r
                 for r in lines]
    lines = [dataclasses.replace(r, comb=added[r.frequency], descriptions=())
             if r.side == "measured" and r.frequency in added
             and (not r.comb or r.descriptions) else r for r in lines]
    return lines, combs, mod


def _refit_set(covering, candidates, max_refit: int):
    """The candidates a step refits: the first `max_refit` of `covering` (ranked), and, when
    there are two or more and all of them are look-alikes of one group (members that make the
    same lines in different ways, :mod:`dtwin.identify.effects`), also the first candidate of
    another group: a step compares explanations of two kinds, not only two members of one."""
    ranked = list(covering[:max_refit])
    groups = {candidates[i].group for _, i, _ in ranked}
    if len(ranked) >= 2 and len(groups) == 1:
        other = next((t for t in covering[max_refit:] if candidates[t[1]].group not in groups),
                     None)
        if other is not None:
            ranked.append(other)
    return ranked


def discover(
    record,
    spec,
    *,
    sample_rate: float | None = None,
    f_sun: float | None = None,
    base_twin=None,
    kind: str | None = None,
    candidates: Sequence | None = None,
    settings: DiscoverySettings = DiscoverySettings(),
    log=None,
) -> DiscoveryResult:
    """Find what the twin is missing, name it, add it, refit, and repeat (docs/discovery.md).

    **Arguments:**

    - `record`: a :class:`dtwin.io.Record` (first channel) or a 1-D signal with `sample_rate`.
    - `f_sun`: the input speed (Hz), if known; otherwise the record's tachometer, metadata or
      lines give it (:func:`dtwin.identify.operating_point.resolve_speed`).
    - `spec`: the gearbox spec (`dtwin.spec.Spec`, path or mapping): kinematics, DAQ and the
      base twin (``build_twin(spec, kind=kind)``) unless `base_twin` is given (e.g. the twin
      fitted by :func:`dtwin.identify.fit.fit`).
    - `candidates`: effects to try (default: :func:`dtwin.identify.effects.registered_effects`).
    - `settings`: :class:`DiscoverySettings`.
    - `log`: a callable receiving progress lines (default: silent).

    **Returns:** :class:`DiscoveryResult`.
    """
    t_start = time.perf_counter()
    say = log or (lambda s: None)
    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    x, fs = as_signal(record, sample_rate)
    n = (len(x) // (2 * settings.n_folds)) * 2 * settings.n_folds
    x = x[:n] - np.mean(x[:n])
    candidates = list(candidates) if candidates is not None else registered_effects()

    # 1. speed (given, tachometer, metadata or the record's lines), kinematics
    kin0 = Kinematics.from_spec(spec)
    freqs_full, a_full = amplitude_spectrum(x, fs, "hann")
    # a record that holds no mesh line of this gearbox has nothing to compare: refuse at once
    op = resolve_speed(record if isinstance(record, Record)
                       else Record(x[None, :], fs, ("signal",), ("",)), spec, f_sun,
                       fallback=False)
    f_est = op.f_sun
    # the spec's speed unless the estimate moves the top of the band by more than half the
    # line tolerance (a calibrated spec carries its baseline's speed: 30.0011 Hz against
    # 30.0002 Hz on the independent load-fluctuation record, 0.07 Hz at 4 fm — more than the
    # 0.06 Hz tolerance of a 4 s record)
    rel = abs(f_est / kin0.f_sun - 1)
    df_full = float(freqs_full[1] - freqs_full[0])
    f_sun = (kin0.f_sun if op.method == "spectrum" and rel < 2e-4
             and rel * fs / 2 < 0.5 * settings.tolerance_bins * df_full else f_est)
    kin = Kinematics.from_spec(spec, f_sun)
    f_max = fs / 2
    say(f"speed {f_sun:.4f} Hz ({op.source}: {f_est:.4f}); fm {kin.f_mesh:.2f} Hz")

    # 2. the extended model
    if base_twin is None:
        base_twin = build_twin(spec, kind=twin_kind(spec, kind, default=spec["model"]["kind"]),
                               f_sun=f_sun)
    # what the record measures: its channel's unit where it says (mm/s → velocity), else the spec's
    measured = unit_quantity(record.units[0]) if isinstance(record, Record) else None
    daq = daq_from_spec(spec, sample_rate=fs, snr_db=None,
                        quantity=measured or spec["sensor"]["quantity"])
    # candidates specialised to the machine (spec, base twin) first, then to the record (the
    # base twin's residual lines); a second model only when the record changed the set
    ctx = EffectContext(spec, base_twin, kin, threshold_db=settings.threshold_db,
                        tolerance_bins=settings.tolerance_bins)
    originals = candidates
    candidates = _adapted(originals, ctx)
    model = extended_model(base_twin, candidates, kin, daq, n, f_sun, settings.solver(),
                           settings.response)
    m_sig = model.base_signal()
    _, Zb = segment_spectra(m_sig, fs, settings.n_folds)
    _, Yb = segment_spectra(x, fs, settings.n_folds)
    lgb = [_log_gain(np.abs(Yb[f]), Zb[f], noise_floor(np.abs(Yb[f]), FLOOR_BINS),
                     settings.threshold_db) for f in range(settings.n_folds)]
    _, m_b = amplitude_spectrum(m_sig * float(np.exp(np.mean(lgb))), fs, "hann")
    floor_b = noise_floor(np.asarray(a_full), FLOOR_BINS)
    lines_b = residual_lines(freqs_full, np.asarray(a_full), np.asarray(m_b), kin,
                             threshold_db=settings.threshold_db, excess_db=settings.excess_db,
                             tolerance_bins=settings.tolerance_bins, f_max=f_max)
    lines_b, _, mod_b = _labelled(lines_b, kin, settings.tolerance_bins * (freqs_full[1] - freqs_full[0]),
                              f_max)
    ctx = dataclasses.replace(ctx, freqs=freqs_full, measured=np.asarray(a_full),
                              model=np.asarray(m_b), floor=floor_b, lines=tuple(lines_b),
                              modulation=mod_b)
    with_data = _adapted(originals, ctx)
    if with_data != candidates:
        say("candidates specialised to the record: "
            + ", ".join(repr(e) for e in with_data if e not in candidates))
        candidates = with_data
        model = extended_model(base_twin, candidates, kin, daq, n, f_sun, settings.solver(),
                               settings.response)
        m_sig = model.base_signal()
    theta_units = np.zeros(model.size)

    # spectra
    freqs, Yc = segment_spectra(x, fs, settings.n_folds)
    Y = np.abs(Yc)
    floor = noise_floor(Y, FLOOR_BINS)
    df = freqs[1] - freqs[0]
    nb = len(freqs)
    # the gap over the DAQ's pass band, as calibration's (dtwin.identify.gap): the lines above
    # it are still found and labelled ("alias of 5fm"), not scored
    bands = named_bands(kin, float(spec["sensor"]["passband"]) * fs)
    tol_full = settings.tolerance_bins * (freqs_full[1] - freqs_full[0])
    chance = chance_match_probability(kin, tol_full, f_max, band_bounds(kin, f_max))
    combs, modulation = [], None
    # the level of the parameter intervals and of the identification decision
    z = normal_quantile(settings.confidence)
    chi2 = chi2_quantile(settings.confidence)
    seg_len = n // settings.n_folds
    # lines the calibration left unexplained on the healthy records (dtwin.identify.shortfall)
    shortfall_orders = list(spec["calibration"].get("shortfall_orders") or [])

    def fold_gains(Z0):
        return np.array([_log_gain(Y[f], Z0[f], floor[f], settings.threshold_db)
                         for f in range(settings.n_folds)])

    def search_gap(a_model_folds):
        """The search's held-out gap: bins `threshold_db` over the floor (its decisions)."""
        return gap(freqs, Y, a_model_folds, bands, floor, settings.threshold_db)

    def reported_gap(a_model_folds):
        """The held-out gap as reported (`gap_threshold_db`; None: family-wise, as calibration's)."""
        return gap(freqs, Y, a_model_folds, bands, floor, settings.gap_threshold_db)

    def heldout_spectra(Z):
        """Fold spectra of a model signal with each fold's gain fitted on the other fold."""
        return np.exp(swap(fold_gains(Z)))[:, None] * np.abs(Z)

    def swap(v):
        return v[::-1]

    steps: list[Step] = []
    n_bins = 0
    models, residual_sets = [], []
    added: set[str] = set()
    added_fx: list[tuple[float, int]] = []  # (f_x, step) of the located modulations added
    stop = "budget"
    last_cands: list[CandidateResult] = []
    initial_gap = None
    respecialised: list[int] = []

    def current(m_sig):
        """The current model's fold spectra and log gains, held-out gap, gain-matched
        whole-record spectrum and labelled residual lines."""
        _, Z0 = segment_spectra(m_sig, fs, settings.n_folds)
        lg0 = fold_gains(Z0)
        # held-out gap of the current model: gains fitted on the other fold
        a0 = np.exp(swap(lg0))[:, None] * np.abs(Z0)
        gap_now, held_now = search_gap(a0), reported_gap(a0)
        _, m_full = amplitude_spectrum(m_sig * float(np.exp(np.mean(lg0))), fs, "hann")
        m_full = np.asarray(m_full)
        lines = residual_lines(freqs_full, np.asarray(a_full), m_full, kin,
                               threshold_db=settings.threshold_db, excess_db=settings.excess_db,
                               tolerance_bins=settings.tolerance_bins, f_max=f_max)
        return (Z0, lg0, gap_now, held_now, m_full) + _labelled(lines, kin, tol_full, f_max,
                                                                added_fx)

    for step_no in range(1, settings.max_steps + 2):
        Z0, lg0, gap_now, held_now, m_full, lines, combs, modulation = current(m_sig)
        if steps and settings.respecialise and step_no <= settings.max_steps:
            # 2b. the candidates specialised again from the current model's residual: where
            # that offers one the earlier residual withdrew and it covers the residual lines
            # (a housing resonance that lifts the comb of the fault just added), the model is
            # rebuilt about the current twin (the added effects at their fitted values), so
            # every response is linearised there
            # the effects added since `model` was built (those before are in its base twin)
            twin_now = model.twin(theta_units, [i for i, e in enumerate(candidates)
                                                if e.name in added])
            ctx_now = dataclasses.replace(ctx, base_twin=twin_now, model=m_full,
                                          lines=tuple(lines), modulation=modulation)
            again = [e for e in _adapted(originals, ctx_now) if e.name not in added]
            # only a new candidate that covers the current residual is worth a rebuild: one
            # that does not would be neither scored nor refit in this step
            new = [e for e in again if e.name not in {c.name for c in candidates}
                   and coverage(e, kin, lines, tol_full, f_max)[0] >= settings.min_coverage]
            if new:
                offered = ", ".join(getattr(e, "summary", e.name) for e in new)
                try:  # a model that cannot be built or simulated leaves the current one
                    rebuilt = extended_model(twin_now, again, kin, daq, n, f_sun,
                                             settings.solver(), settings.response)
                    sig_new = rebuilt.base_signal()
                except (DtwinError, FloatingPointError, ValueError) as err:
                    say(f"step {step_no}: the current residual offers {offered}, but the model "
                        f"about the current twin failed ({type(err).__name__}: {err}); the "
                        "candidates stay as they were")
                else:
                    say(f"step {step_no}: the current residual offers {offered}; candidates "
                        "specialised again and linearised about the current model")
                    candidates, model, m_sig = again, rebuilt, sig_new
                    theta_units = np.zeros(model.size)
                    Z0, lg0, gap_now, held_now, m_full, lines, combs, modulation = current(m_sig)
                    respecialised.append(step_no)
        if initial_gap is None:
            initial_gap = held_now
        models.append(m_full)
        residual_sets.append(lines)
        if step_no > settings.max_steps:
            break
        say(f"step {step_no}: held-out gap {held_now.total:.2f} dB (the search's, over "
            f"{settings.threshold_db:g} dB: {gap_now.total:.2f} dB), "
            f"{sum(r.side == 'measured' for r in lines)} residual lines")
        # 3. candidates covering the residual lines, ranked by coverage
        covering = []
        cov_all: dict[str, float] = {}
        for i, e in enumerate(candidates):
            if e.name in added:
                continue
            cov, matched = coverage(e, kin, lines, tol_full, f_max)
            cov_all[e.name] = cov
            if cov >= settings.min_coverage:
                covering.append((cov, i, matched))
        covering.sort(key=lambda t: -t[0])
        if not covering:
            stop = "no candidate covers the residual lines"
            last_cands = []
            break
        model_line = _dilate(np.abs(Z0) * np.exp(lg0)[:, None]
                             > floor * 10 ** (settings.threshold_db / 20.0))
        spectra: dict[int, np.ndarray] = {}

        def response_spectra(i, spectra=spectra, model=model):
            if i not in spectra:
                _, Jc = segment_spectra(model.response(i).T, fs, settings.n_folds)  # (p, F, K)
                spectra[i] = np.moveaxis(Jc, 0, -1)  # (F, K, p)
            return spectra[i]

        def signature_bins(e, model_line=model_line):
            sig_lines = [s.frequency for s in e.signature(kin, f_max)]
            sig = np.broadcast_to(_bins_of(sig_lines, df, nb), Y.shape)
            if not getattr(e, "modifies_model_lines", False):
                sig = sig & ~model_line
            return sig

        scores: dict[int, tuple[float, int, float]] = {}
        if settings.screen == "score":
            # 3b. score every covering candidate at zero amplitude (one response column per
            # parameter, no refit), on one bin set shared by all: their signature bins and the
            # model's lines; refit the best max_refit (and another group's best: _refit_set)
            model.ensure_responses([i for _, i, _ in covering])
            common = model_line.copy()
            for _, i, _ in covering:
                common = common | signature_bins(candidates[i])
            for _, i, _ in covering:
                scores[i] = screen_score(Z0, response_spectra(i), Y, floor, lg0, common)
            covering.sort(key=lambda t: (scores[t[1]][2], -t[0]))
            K_tried = len(covering)
        ranked = _refit_set(covering, candidates, settings.max_refit)
        refit_idx = {i for _, i, _ in ranked}
        screened_out = [t for t in covering if t[1] not in refit_idx]
        if len(ranked) > settings.max_refit:
            say(f"  the best {settings.max_refit} are look-alikes of group "
                f"{candidates[ranked[0][1]].group}: {candidates[ranked[-1][1]].name} "
                f"(group {candidates[ranked[-1][1]].group}) refit as well")
        if settings.screen == "coverage":
            K_tried = len(ranked)
        for k, (cov, i, _) in enumerate(covering):
            if i in scores:
                say(f"  score {candidates[i].name}: {scores[i][0]:.1f} ({scores[i][1]} df, "
                    f"log10 p {scores[i][2]:.1f}), rank {k + 1}, coverage {cov:.2f}")
        level = settings.alpha / K_tried
        # the smallest attainable p-value 1/(B+1) must lie below the level alpha/K
        n_boot = max(settings.n_boot, int(np.ceil(K_tried / settings.alpha)))
        model.ensure_responses([i for _, i, _ in ranked])
        # one padded bin count for every candidate refit in the step, never below the previous
        # step's: one compilation of the fits and the bootstrap serves them all
        n_bins = max([n_bins] + [int((signature_bins(candidates[i]) | model_line).any(axis=0)
                                     .sum()) for _, i, _ in ranked])
        results: list[CandidateResult] = []
        for cov, i, matched in ranked:
            _maps.relieve()  # a safe point between candidates' programs (dtwin._maps)
            e = candidates[i]
            cr = CandidateResult(e.name, e.group, cov, matched,
                                 main_name=getattr(e, "main_name", ""),
                                 main_unit=getattr(e, "main_unit", ""))
            _set_score(cr, scores, i, covering)
            share, on = shortfall_share(matched, shortfall_orders, f_sun, df)
            if share >= SHORTFALL_SHARE:  # the healthy machine shows the same lines
                cr.rejected = (f"calibration shortfall: {100 * share:.0f} % of its lines' excess "
                               f"lies on lines the calibrated twin left unexplained on the "
                               f"healthy calibration record(s) ({', '.join(f'{f:.2f}' for f in on[:6])}"
                               f" Hz{', …' if len(on) > 6 else ''}): not a finding")
                cr.significant = cr.identified = False
                say(f"  {e.name} set aside: {cr.rejected}")
                results.append(cr)
                continue
            try:  # one candidate never ends the run: a failure sets it aside
                say(f"  refit {e.name} (coverage {cov:.2f})")
                Jc = response_spectra(i)  # (F, K, p)
                sig = signature_bins(e)
                ps = model.parameters[i]
                p = Jc.shape[-1]
                inp, sel, K = candidate_inputs(Z0, Jc, Y, floor, sig, model_line,
                                               [q.nonnegative for q in ps], lg0, n_bins)
                nonneg = np.asarray(inp.nonneg)
                active = np.asarray(inp.active)
                T, fold_params = heldout_statistic(inp)
                T = float(T)
                fold_params = np.asarray(fold_params)
                # held-out gap with the linearised model, parameters from the other fold
                a_lin = np.zeros_like(Y)
                for f in range(settings.n_folds):
                    pf = fold_params[1 - f]
                    th = theta_of(pf, nonneg, active)[:p]
                    a_f = np.exp(pf[-1]) * np.abs(Z0[f] + Jc[f] @ th)
                    a_lin[f] = a_f
                cr.gap_after = search_gap(a_lin).total
                cr.statistic = T
                # bootstrap null
                # the draws stop once the decision p > level is certain; each candidate has
                # its own stream of draws (the same whichever candidates are refit before it)
                rng_c = np.random.default_rng([settings.seed, step_no, i])
                t_null = null_statistics(inp, rng_c, n_boot, Z0, floor, sel, seg_len,
                                         stop=(T, level))
                cr.p_value = p_value(T, t_null, rng_c)
                cr.significant = cr.p_value <= level and cr.gap_after < gap_now.total
                # joint fit and intervals
                val, loss, jac, r = fit_joint(inp, fold_params)
                n_par = p + settings.n_folds
                P = inp.J.shape[-1]  # the padded parameter count
                keep = np.r_[np.arange(p), P + np.arange(settings.n_folds)]
                Jk = jac[:, keep]
                s2 = residual_variance(inp, r, n_par)
                try:
                    cov_u = s2 * np.linalg.inv(Jk.T @ Jk)
                except np.linalg.LinAlgError:
                    cov_u = np.full((n_par, n_par), np.inf)
                u = val[:p]
                dth = np.where(nonneg[:p] > 0, np.exp(np.clip(u, -700, 700)), 1.0)  # dθ/du
                th_units = theta_of(val, nonneg, active)[:p]
                scales = model.scales[model.slice(i)]
                cr.theta = th_units * scales
                cr.sigma = np.sqrt(np.abs(np.diag(cov_u)[:p])) * dth * scales
                gmain = np.asarray(jax.grad(e.main)(jnp.asarray(cr.theta)))
                cov_th = cov_u[:p, :p] * np.outer(dth * scales, dth * scales)
                cr.main = float(e.main(jnp.asarray(cr.theta)))
                cr.main_sigma = float(np.sqrt(max(gmain @ cov_th @ gmain, 0.0)))
                # identified: the profile interval of the overall amplitude excludes zero (more
                # reliable than the delta method for a norm near zero, and scale-free)
                c_lo, c_hi, evidence = amplitude_profile(inp, val, s2, chi2)
                cr.main_interval = (c_lo * cr.main, c_hi * cr.main)
                cr.evidence = evidence
                cr.identified = is_identified(c_lo, evidence, cr.main, settings.confidence)
                cr.log_gains = val[P:]
                say(f"    T {T:.1f} p {cr.p_value:.4f} (level {level:.4f}) gap {cr.gap_after:.2f} dB "
                    f"main {cr.main:.3g} [{cr.main_interval[0]:.3g}, {cr.main_interval[1]:.3g}] "
                    f"identified {cr.identified}")
                out = [f"{q.name} = {v:.4g} {q.unit} lies outside its physical range "
                       f"[{q.bounds[0]:g}, {q.bounds[1]:g}]"
                       for q, v in zip(ps, cr.theta, strict=True)
                       if not q.bounds[0] <= v <= q.bounds[1]]
                if out:  # the linearised model extrapolated: refit inside the range in full
                    cr.out_of_range = "; ".join(out)
                    say(f"    {cr.out_of_range}: refit inside its range if it is kept")
            except (DtwinError, FloatingPointError, np.linalg.LinAlgError, ValueError) as err:
                cr.rejected = f"refit failed: {type(err).__name__}: {err}"
            if cr.rejected:
                cr.significant = cr.identified = False
                say(f"    set aside: {cr.rejected}")
            results.append(cr)
        tried = {c.name: c for c in results}
        for cov, i, matched in screened_out:
            e = candidates[i]
            cr = CandidateResult(e.name, e.group, cov, matched,
                                 main_name=getattr(e, "main_name", ""),
                                 main_unit=getattr(e, "main_unit", ""))
            _set_score(cr, scores, i, covering)
            cr.screened = (f"screened out, score {cr.score:.3g} ({cr.score_df} df), "
                           f"rank {cr.score_rank}")
            results.append(cr)
        last_cands = results
        ok = [c for c in results if c.significant and c.identified]
        if not ok:
            stop = "no candidate significant and identified"
            break
        # confirm with the full (nonlinear) model at the joint fit: the candidate of the best
        # linearised gap is kept only when the simulated twin's held-out gap falls too; else
        # the next one is confirmed
        best = None
        for cand in sorted(ok, key=lambda c: c.gap_after):
            i_c = next(i for i, e in enumerate(candidates) if e.name == cand.name)
            trials = [cand.theta] if cand.out_of_range is None else \
                in_range_trials(cand.theta, [q.bounds for q in model.parameters[i_c]])
            tried_c = []
            for th in trials:
                theta_c = theta_units.copy()
                theta_c[model.slice(i_c)] = th / model.scales[model.slice(i_c)]
                sig_c = model.signal(theta_c)
                _, Z1 = segment_spectra(sig_c, fs, settings.n_folds)
                a1 = heldout_spectra(Z1)
                tried_c.append((search_gap(a1).total, th, theta_c, sig_c, a1))
            g_best, th, theta_c, sig_c, a1 = min(tried_c, key=lambda t: t[0])
            gap_c = search_gap(a1)
            if cand.out_of_range is not None:
                refit_in_range(cand, th, candidates[i_c], [t[0] for t in tried_c], say)
            if gap_c.total < gap_now.total:
                best, i_best, theta_units, m_sig, gap_conf = cand, i_c, theta_c, sig_c, gap_c
                held_after = reported_gap(a1)
                break
            cand.significant = False
            cand.rejected = (f"not kept: simulated in full, the held-out gap went "
                             f"{gap_now.total:.2f} → {gap_c.total:.2f} dB (linearised "
                             f"{cand.gap_after:.2f} dB)")
            say(f"  {cand.name} {cand.rejected}")
        if best is None:
            stop = "no candidate reduced the held-out gap once simulated in full"
            break
        members = [e.name for e in candidates if e.group == best.group and e.name != best.name]
        # a member not refit is told apart only when its signature covers (almost) none of
        # the residual lines; one that covers them but was not refit may fit as well
        ties = [nm for nm in members
                if (nm not in tried and cov_all.get(nm, 0.0) >= settings.min_coverage)
                or (nm in tried and (not np.isfinite(tried[nm].gap_after)
                                     or tried[nm].gap_after - best.gap_after < settings.tie_db))]
        named = best.name if not ties else best.group
        gap_lin = best.gap_after
        e_best = candidates[i_best]
        params = [dict(name=q.name, unit=q.unit, value=float(v), sigma=float(s),
                       interval=[float(v - z * s), float(v + z * s)])
                  for q, v, s in zip(model.parameters[i_best], best.theta, best.sigma, strict=True)]
        main = dict(name=e_best.main_name, unit=e_best.main_unit, value=best.main,
                    sigma=best.main_sigma,
                    interval=list(best.main_interval),
                    interval_kind=(f"profile of the overall amplitude, {100 * settings.confidence:g} %"
                                   if best.out_of_range is None else
                                   f"none: {best.out_of_range}"),
                    delta_method_sigma=best.main_sigma,
                    typical_range=list(e_best.typical_range), typical_note=e_best.typical_note)
        gap_after = dataclasses.replace(gap_now, total=gap_lin,
                                        bands=dict(gap_now.bands, all=gap_lin))
        steps.append(Step(step_no, best.name, best.group, named, ties, best.matched, params, main,
                          best.p_value, level, gap_now, gap_after, gap_conf, results,
                          signature_labels(e_best, kin, best.matched, tol_full, f_max),
                          getattr(e_best, "summary", e_best.description), held_now,
                          held_after))
        added.add(best.name)
        if getattr(e_best, "f_x", None) is not None:
            added_fx.append((float(e_best.f_x), step_no))
        say(f"  added {best.name} (named {named}); held-out gap {held_now.total:.2f} → "
            f"{held_after.total:.2f} dB; the search's {gap_now.total:.2f} → {gap_lin:.2f} dB "
            f"(confirmed {gap_conf.total:.2f})")
    final_lines = residual_sets[-1]
    unexplained = [r for r in final_lines if r.side == "measured"]
    extra = [r for r in final_lines if r.side == "model"]
    _, Zf = segment_spectra(m_sig, fs, settings.n_folds)
    final_gap = reported_gap(heldout_spectra(Zf))
    return DiscoveryResult(kin, f_sun, fs, settings, steps, initial_gap, final_gap, unexplained,
                           extra, chance, stop, last_cands, freqs_full, np.asarray(a_full), models,
                           residual_sets, time.perf_counter() - t_start, combs, modulation,
                           respecialised)
