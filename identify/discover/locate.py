"""Locate: the lines where the current model and the record disagree.

The residual lines over 0 … Nyquist
(:func:`dtwin.identify.lines.residual_lines`) labelled with their fault combs and a modulation
at a located frequency (:func:`_labelled`), and the current model's held-out gaps
(:func:`locate`).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from dtwin.signal.spectrum import amplitude_spectrum

from ..gap import GapResult, segment_spectra
from ..lines import (
    find_combs,
    find_modulation,
    label_combs,
    modulation_lines,
    residual_lines,
)

if TYPE_CHECKING:
    from .search import Search


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


@dataclasses.dataclass(frozen=True)
class Current:
    """The current model against the record (:func:`locate`)."""

    #: the model's complex fold spectra (F, K) and each fold's log gain to the record
    Z0: np.ndarray
    lg0: np.ndarray
    #: held-out gaps: the search's (its decisions) and as reported
    gap_now: GapResult
    held_now: GapResult
    #: the gain-matched whole-record model spectrum
    m_full: np.ndarray
    #: the labelled residual lines, the combs and the located modulation among them
    lines: list
    combs: list
    modulation: object


def locate(search: Search, m_sig, added_fx) -> Current:
    """The current model's fold spectra and log gains, held-out gap, gain-matched whole-record
    spectrum and labelled residual lines (`added_fx`: see :func:`_labelled`)."""
    settings = search.settings
    _, Z0 = segment_spectra(m_sig, search.fs, settings.n_folds)
    lg0 = search.fold_gains(Z0)
    # held-out gap of the current model: gains fitted on the other fold
    a0 = np.exp(lg0[::-1])[:, None] * np.abs(Z0)
    gap_now, held_now = search.search_gap(a0), search.reported_gap(a0)
    _, m_full = amplitude_spectrum(m_sig * float(np.exp(np.mean(lg0))), search.fs, "hann")
    m_full = np.asarray(m_full)
    lines = residual_lines(search.freqs_full, search.a_full, m_full, search.kin,
                           threshold_db=settings.threshold_db, excess_db=settings.excess_db,
                           tolerance_bins=settings.tolerance_bins, f_max=search.f_max)
    lines, combs, modulation = _labelled(lines, search.kin, search.tol_full, search.f_max,
                                         added_fx)
    return Current(Z0, lg0, gap_now, held_now, m_full, lines, combs, modulation)
