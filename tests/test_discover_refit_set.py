"""Which candidates a discovery step refits (``identify/discover/propose.py``): the best
``max_refit`` by score, and the best of another look-alike group when those are all of one.

The bundled ``bench_sun_fault`` record is the case that needs it: a sun fault's comb
``k f_sf ± f_s`` lies on carrier orders there (``f_sf = 12 f_c``, ``f_s = 5 f_c``), so two
carrier-sideband look-alikes outscore it, and a step that refit only them kept one of them
first (tests/test_bundled_workflow.py runs that record)."""

from __future__ import annotations

from types import SimpleNamespace

from dtwin.identify.discover.propose import _refit_set


def _covering(*groups):
    """``(coverage, index, matched)`` rows in rank order, and candidates of those groups."""
    cands = [SimpleNamespace(name=f"c{i}", group=g) for i, g in enumerate(groups)]
    return [(0.5, i, []) for i in range(len(groups))], cands


def test_two_groups_in_the_slots_refit_as_ranked():
    cov, cands = _covering("carrier_sidebands", "sun_rotation", "carrier_sidebands")
    assert [i for _, i, _ in _refit_set(cov, cands, 2)] == [0, 1]


def test_one_group_in_the_slots_adds_the_best_of_another():
    cov, cands = _covering("carrier_sidebands", "carrier_sidebands", "carrier_sidebands",
                           "sun_rotation", "planet_fault")
    assert [i for _, i, _ in _refit_set(cov, cands, 2)] == [0, 1, 3]


def test_nothing_of_another_group_leaves_the_slots_as_they_are():
    cov, cands = _covering("carrier_sidebands", "carrier_sidebands", "carrier_sidebands")
    assert [i for _, i, _ in _refit_set(cov, cands, 2)] == [0, 1]


def test_one_slot_is_never_widened():
    cov, cands = _covering("carrier_sidebands", "sun_rotation")
    assert [i for _, i, _ in _refit_set(cov, cands, 1)] == [0]
    assert _refit_set(cov[:0], cands, 2) == []
