"""dtwin.model.kinematics: one type of the characteristic frequencies (used by spectrum labels,
residual lines, effects and the operating point), one bounds type, one label formatter; and
the one level formula (dtwin.identify.gap.levels) of the gap and discovery's fits.

Frequencies are compared with the closed forms (ring fixed, sun input; McFadden & Smith 1985,
Zhu, Li & Hu 2022 Eqs. (1)–(4)): fc = fs Zs/(Zs + Zr), fm = fc Zr = (fs − fc) Zs,
f_sun_fault = fm N/Zs, f_planet_fault = fm/Zp, f_ring_fault = fm N/Zr = N fc."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import dtwin.identify.lines as lines
import dtwin.signal.spectrum as spectrum
from dtwin.identify.gap import levels
from dtwin.identify.operating_point import gear_orders
from dtwin.model.gears import characteristic_frequencies
from dtwin.model.kinematics import Kinematics, OrderBounds, combination_text
from dtwin.spec import preset
from dtwin.spec.build import build_twin

GEARS = [(21, 30, 81, 3, 30.0), (21, 31, 84, 3, 29.7), (13, 17, 47, 4, 12.5)]


@pytest.mark.parametrize("zs,zp,zr,n,fs", GEARS)
def test_frequencies_match_the_closed_forms(zs, zp, zr, n, fs):
    k = Kinematics.from_gears(zs, zp, zr, n, fs, pole_pairs=4)
    fc = fs * zs / (zs + zr)
    fm = fc * zr
    assert k.f_carrier == pytest.approx(fc, rel=1e-15)
    assert k.f_mesh == pytest.approx(fm, rel=1e-15)
    assert k.f_mesh == pytest.approx((fs - fc) * zs, rel=1e-13)
    assert k.f_sun_fault == pytest.approx(fm * n / zs, rel=1e-15)
    assert k.f_sun_fault_per_planet == pytest.approx(fs - fc, rel=1e-13)
    assert k.f_planet_fault == pytest.approx(fm / zp, rel=1e-15)
    assert k.f_ring_fault == pytest.approx(n * fc, rel=1e-13)
    assert k.f_electrical == 4 * fs
    both = Kinematics.from_gears(zs, zp, zr, n, fs, planet_fault="both_flanks")
    assert both.f_planet_fault == pytest.approx(2 * fm / zp, rel=1e-15)
    o = k.orders()
    assert o["mesh"] == pytest.approx(zs * zr / (zs + zr), rel=1e-15)
    assert o["carrier"] == pytest.approx(zs / (zs + zr), rel=1e-15)


def test_paper_simulation_gearbox_numbers():
    """21/30/81, N = 3 at 30 Hz: fc = 6.1765 Hz, fm = 500.29 Hz (Zhu, Li & Hu 2022)."""
    k = Kinematics.from_spec(preset("paper-sim"))
    assert k.f_carrier == pytest.approx(6.176470588235294, rel=1e-12)
    assert k.f_mesh == pytest.approx(500.2941176470588, rel=1e-12)
    # the sideband rule (m Zr + n) mod N = 0: fm ± 3fc pass, fm − 7fc is forbidden
    assert k.allowed_by_sideband_rule(1, 3) and k.allowed_by_sideband_rule(1, -3)
    assert not k.allowed_by_sideband_rule(1, -7)


def test_one_type_everywhere():
    """Spectrum labels, residual lines, gears and the operating point use the one type."""
    assert spectrum.FrequencyBasis is Kinematics and lines.Kinematics is Kinematics
    assert spectrum.LabelBounds is OrderBounds and lines.LineBounds is OrderBounds
    spec = preset("paper-sim")
    gs = spec.gear_set()
    k = Kinematics.from_gear_set(gs, 30.0)
    assert characteristic_frequencies(gs, 30.0) == k.as_dict()
    twin = build_twin(spec, kind="torsional")
    o = gear_orders(twin)
    k1 = Kinematics.from_gears(21, 30, 81, 3, 1.0)
    assert o == {"mesh": k1.f_mesh, "carrier": k1.f_carrier, "sun_fault": k1.f_sun_fault,
                 "planet_fault": k1.f_planet_fault}
    # a basis built from frequencies only (as the spectrum CLI does): faults left out unused
    b = spectrum.FrequencyBasis(k.f_mesh, k.f_carrier, None, None, 3)
    labs = spectrum.label_frequency(k.f_mesh - 7 * k.f_carrier, b, 0.01)
    assert labs[0].text == "fm − 7fc" and all(lab.b == lab.c == 0 for lab in labs)


def test_combination_text_is_the_shortest_form():
    assert combination_text((("fm", 1), ("fc", -7))) == "fm − 7fc"
    assert combination_text((("2fm", 1), ("fs/3", 1), ("fc", -1))) == "2fm + fs/3 − fc"
    assert combination_text((("fm", 1), ("fc", 2), ("fc", -2))) == "fm"  # like terms merged
    assert combination_text((("fm", 0), ("fc", -1))) == "−fc"
    assert combination_text(()) == "DC"
    # spectrum labels, residual-line descriptions and effect signatures write alike
    from dtwin.identify.discover.effects.base import carrier_grid

    k = Kinematics.from_spec(preset("paper-sim"))
    f = k.f_mesh - 7 * k.f_carrier
    lab = spectrum.label_frequency(f, spectrum.FrequencyBasis(k.f_mesh, k.f_carrier,
                                                              k.f_sun_fault, k.f_planet_fault, 3),
                                   1e-6)
    desc = lines.describe(f, k, 1e-6)
    sig = [s for s in carrier_grid(k, 2000.0) if abs(s.frequency - f) < 1e-9]
    assert lab[0].text == desc[0].text == sig[0].label == "fm − 7fc"


def test_one_level_formula_numpy_and_jax():
    """20 log10(A + F) (dB), the same values for numpy input and under jit."""
    a = np.array([0.0, 1e-3, 0.5, 2.0])
    f = np.array([1e-3, 1e-3, 1e-2, 1.0])
    ref = 20 * np.log10(a + f)
    np.testing.assert_allclose(levels(a, f), ref, rtol=1e-14)
    np.testing.assert_allclose(np.asarray(jax.jit(levels)(jnp.asarray(a), jnp.asarray(f))), ref,
                               rtol=1e-13)
