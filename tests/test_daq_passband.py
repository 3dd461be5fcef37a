"""The DAQ's anti-aliasing pass band (issue "Right on every machine", item 4): the twin's filter
passes flat to the spec's ``[sensor] passband`` and stops what would fold onto it; the gaps are
scored up to the same edge."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from dtwin.simulation.simulate import DEFAULT_PASSBAND, STOPBAND_DB, daq_filter
from dtwin.spec import load_spec, preset, spec_to_dict
from dtwin.spec.build import daq_from_spec


@pytest.mark.parametrize("oversample", [2, 4, 5, 8])
@pytest.mark.parametrize("passband", [DEFAULT_PASSBAND, 1 / 2.56])
def test_flat_to_the_passband_and_stopped_where_decimation_folds_onto_it(oversample, passband):
    """Gain (freqz of the taps, output rate 1): within 0.01 dB of 1 from 0 to the pass band's
    edge; at least STOPBAND_DB down from (1 − passband), whose aliases land on the
    pass band; unit DC gain; odd, symmetric taps (zero phase)."""
    taps = daq_filter(oversample, passband)
    f_pass = np.linspace(0.0, passband, 200)
    f_stop = np.linspace(1.0 - passband, oversample / 2, 400)
    _, hp = scipy.signal.freqz(taps, worN=f_pass, fs=oversample)
    _, hs = scipy.signal.freqz(taps, worN=f_stop, fs=oversample)
    assert np.max(np.abs(20 * np.log10(np.abs(hp)))) < 0.01
    assert np.max(20 * np.log10(np.abs(hs) + 1e-300)) < -STOPBAND_DB
    assert taps.size % 2 == 1 and np.allclose(taps, taps[::-1]) and taps.sum() == pytest.approx(1)


def test_the_spec_states_the_passband_and_the_twin_follows_it():
    d = spec_to_dict(preset("paper-sim"))
    d.pop("source", None)
    assert daq_from_spec(load_spec(d)).passband == DEFAULT_PASSBAND
    d["sensor"]["passband"] = 0.39
    assert daq_from_spec(load_spec(d)).passband == 0.39
    d["sensor"]["passband"] = 0.6
    from dtwin.errors import SpecError

    with pytest.raises(SpecError, match="passband"):
        load_spec(d)
    with pytest.raises(ValueError, match="passband"):
        daq_filter(4, 0.55)
