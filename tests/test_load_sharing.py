"""A spec's `imperfections.load_sharing` (relative load share of each planet): the clearances
that `dtwin.model.parts.imperfections.load_share_offsets` solves for give those shares in a running
twin (mean mesh forces of a simulation, with the time-varying stiffness and one-sided contact
the static design leaves out), agree with the closed form of the torsional twin, and bad values
are refused with the field named."""

from __future__ import annotations

import copy

import jax.numpy as jnp
import numpy as np
import pytest

from dtwin.errors import SpecError
from dtwin.model.parts.base import AbstractPart
from dtwin.model.parts.imperfections import MeshOffsets
from dtwin.simulation.simulate import simulate
from dtwin.spec import load_spec, preset
from dtwin.spec.build import build_twin, daq_from_spec

SHARES = [1.2, 0.9, 0.9]


class MeshForceProbe(AbstractPart):
    """Each planet's sun- and ring-mesh contact force (N) as named outputs."""

    def forces(self, twin, t, q, qdot, aux, mesh):
        out = {f"f_sp_{i}": mesh.force_sp[i] for i in range(twin.n_planets)}
        out |= {f"f_rp_{i}": mesh.force_rp[i] for i in range(twin.n_planets)}
        return None, jnp.zeros(0), out


def _spec(shares):
    data = copy.deepcopy(preset("paper-sim").data)
    data["imperfections"]["load_sharing"] = shares
    return load_spec(data)


def _offsets(twin):
    (part,) = [p for p in twin.parts if isinstance(p, MeshOffsets)]
    return np.asarray(part.e_sp), np.asarray(part.e_rp)


@pytest.mark.parametrize("kind", ["torsional", "translational"])
def test_stated_shares_hold_in_a_running_twin(kind):
    """Mean contact forces over 0.2 s of a simulation at the spec's load: each planet's share
    of the sun- and ring-mesh load within 1 % of the stated share (planet 0 carries 1.2)."""
    spec = _spec(SHARES)
    twin = build_twin(spec, kind=kind, extra_parts=(MeshForceProbe(),))
    res = simulate(twin, duration=0.2, f_sun=float(spec["operating"]["f_sun"]),
                   daq=daq_from_spec(spec, snr_db=None), discard=0.1)
    for mesh in ("sp", "rp"):
        f = np.array([np.mean(res.outputs[f"f_{mesh}_{i}"]) for i in range(3)])
        assert f / f.mean() == pytest.approx(SHARES, abs=0.01), (kind, mesh)
    e_sp, e_rp = _offsets(twin)
    assert np.array_equal(e_sp, e_rp) and e_sp[0] < 0 < e_sp[1]  # the loaded planet sits closer


def test_torsional_offsets_match_the_closed_form():
    """Sun held on its centre: a planet's two meshes in series (1/k = 1/k_sp + 1/k_rp) carry
    F_i = k (D − 2 e_i), so e_i = (1 − s_i) F̄ / (2 k) with F̄ the equal-sharing mesh force."""
    spec = _spec(SHARES)
    twin = build_twin(spec, kind="torsional")
    lp = twin.lp
    k = 1.0 / (1.0 / float(lp.k_sun_planet) + 1.0 / float(lp.k_ring_planet))
    healthy = build_twin(_spec(None), kind="torsional", extra_parts=(MeshForceProbe(),))
    res = simulate(healthy, duration=0.1, f_sun=float(spec["operating"]["f_sun"]),
                   daq=daq_from_spec(spec, snr_db=None), discard=0.05)
    f_bar = np.mean([np.mean(res.outputs[f"f_sp_{i}"]) for i in range(3)])
    e, _ = _offsets(twin)
    expect = (1.0 - np.asarray(SHARES)) * f_bar / (2.0 * k)
    assert e == pytest.approx(expect - expect.mean() + e.mean(), rel=0.01, abs=1e-11)


def test_shares_are_relative_and_bad_values_are_refused():
    """Shares are read relative to their mean ([2.4, 1.8, 1.8] is [1.2, 0.9, 0.9]); zero,
    negative or a wrong count name the field."""
    a = _offsets(build_twin(_spec(SHARES), kind="torsional"))[0]
    b = _offsets(build_twin(_spec([2.4, 1.8, 1.8]), kind="torsional"))[0]
    assert a == pytest.approx(b, rel=1e-9)
    for bad in ([1.5, 1.5, 0.0], [1.0, 1.0]):
        with pytest.raises(SpecError, match="load_sharing"):
            build_twin(_spec(bad), kind="torsional")
