"""Record checks against constructed defects with known answers.

Each test builds a record with one defect whose size is known in closed form (the index of a
NaN, the number of samples held at a rail, the rate 2.5·f_mesh, the duration 10/f_carrier) and
checks that :func:`check_record` reports exactly that, and nothing for a clean record.
"""

from __future__ import annotations

import numpy as np
import pytest

from dtwin.errors import RecordError
from dtwin.io.readers import read_record
from dtwin.io.record import Record
from dtwin.io.validate import (
    MIN_CARRIER_PERIODS,
    MIN_RATE_PER_MESH,
    check_record,
    validate_record,
)

FS = 5000.0
# the paper's bench: f_sun = 29.7 Hz, Zs = 21, Zr = 84 (f_carrier = f_sun Zs/(Zs+Zr))
F_CARRIER = 29.7 * 21 / (21 + 84)
F_MESH = F_CARRIER * 84


def _clean(n=int(4 * FS), seed=0):
    """The bench's 4 s record: a mesh tone with carrier sidebands and noise (never clipped)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    x = (1 + 0.3 * np.cos(2 * np.pi * F_CARRIER * t)) * np.sin(2 * np.pi * F_MESH * t)
    x += 0.05 * rng.standard_normal(n)
    return Record(data=np.stack([x, 0.5 * x]), sample_rate=FS, channels=("acc", "mic"),
                  units=("g", "Pa"))


def _kinds(problems):
    return sorted(p.kind for p in problems)


def test_clean_bench_record_has_no_problems():
    """The paper's bench record (5000 Hz, 4 s) is fit for f_mesh ≈ 499 Hz and f_c ≈ 5.94 Hz."""
    rec = _clean()
    assert check_record(rec, f_mesh=F_MESH, f_carrier=F_CARRIER) == []
    assert validate_record(rec, f_mesh=F_MESH, f_carrier=F_CARRIER) is rec


def test_nan_and_inf_reported_with_first_index():
    rec = _clean()
    rec.data[0, 1234] = np.nan
    rec.data[0, 2000] = np.inf
    (p,) = check_record(rec)
    assert p.kind == "nan" and p.channel == "acc" and p.sample == 1234 and p.value == 2
    assert "1234" in p.message


def test_empty_and_constant_channels():
    empty = Record(data=np.zeros((1, 0)), sample_rate=FS, channels=("a",), units=("g",))
    assert _kinds(check_record(empty)) == ["empty"]
    rec = _clean()
    rec.data[1] = 0.25
    (p,) = check_record(rec)
    assert p.kind == "constant" and p.channel == "mic" and p.value == 0.25


def test_clipping_counts_the_samples_at_the_rails():
    """A sine of amplitude 1.5 through a ±1 ADC: the fraction of samples with |sin| ≥ 1/1.5
    is 1 − (2/π) asin(1/1.5) in the limit of many periods."""
    n = int(2 * FS)
    t = np.arange(n) / FS
    x = np.clip(1.5 * np.sin(2 * np.pi * 50.0 * t), -1.0, 1.0)
    rec = Record(data=x, sample_rate=FS, channels=("acc",), units=("V",))
    (p,) = check_record(rec)
    limit = 1.0 - 2.0 / np.pi * np.arcsin(1.0 / 1.5)
    sampled = np.mean(np.abs(1.5 * np.sin(2 * np.pi * 50.0 * t)) >= 1.0)  # from the unclipped
    assert p.kind == "clipping"
    assert p.value == pytest.approx(sampled, rel=1e-12)
    assert p.value == pytest.approx(limit, abs=0.01)  # 100 samples per period
    # runs shorter than clip_run are not clipping: isolated repeated extremes of a clean record
    assert check_record(_clean()) == []


@pytest.mark.parametrize("factor", [2.0, 2.49, 2.5, 3.0])
def test_sample_rate_rule(factor):
    rec = _clean(n=20000)
    f_mesh = FS / factor
    problems = check_record(rec, f_mesh=f_mesh)
    if factor < MIN_RATE_PER_MESH:
        (p,) = problems
        assert p.kind == "sample_rate" and p.value == pytest.approx(2.5 * f_mesh)
        assert f"{int(np.ceil(2.5 * f_mesh))} Hz" in p.message
    else:
        assert problems == []


def test_sidebands_below_nyquist():
    """f_mesh = 1900 Hz passes 2.5·f_mesh = 4750 Hz but f_mesh + 5·f_c must stay below 2500 Hz:
    with f_c = 200 Hz the needed rate is 2·(1900 + 1000) = 5800 Hz."""
    rec = _clean(n=20000)
    (p,) = check_record(rec, f_mesh=1900.0, f_carrier=200.0, n_sidebands=5)
    assert p.kind == "sample_rate" and p.value == pytest.approx(5800.0)


def test_duration_rule_k_carrier_periods():
    need = MIN_CARRIER_PERIODS / F_CARRIER
    short = _clean(n=int(np.floor(need * FS)) - 1)
    (p,) = check_record(short, f_carrier=F_CARRIER)
    assert p.kind == "too_short" and p.value == pytest.approx(need)
    assert check_record(_clean(n=int(np.ceil(need * FS)) + 1), f_carrier=F_CARRIER) == []


def test_time_column_disagreeing_with_given_rate(tmp_path):
    t = np.arange(500) / 2000.0
    path = tmp_path / "r.csv"
    np.savetxt(path, np.column_stack([t, np.sin(2 * np.pi * 100 * t)]), delimiter=",",
               header="time,acc", comments="")
    assert check_record(read_record(path)) == []
    rec = read_record(path, sample_rate=2500.0)
    (p,) = check_record(rec)
    assert p.kind == "time_column" and p.value == pytest.approx(2000.0)
    with pytest.raises(RecordError, match="2000 Hz") as err:
        validate_record(rec)
    assert err.value.problems == [p]


def test_unknown_channel_and_all_problems_at_once():
    rec = _clean(n=1000)
    rec.data[0, 10] = np.nan
    with pytest.raises(RecordError) as err:
        validate_record(rec, channels=["acc", "acx"], f_mesh=3000.0, f_carrier=F_CARRIER)
    kinds = sorted(p.kind for p in err.value.problems)
    assert kinds == ["nan", "sample_rate", "too_short", "unknown_channel"]
    text = str(err.value)
    for p in err.value.problems:
        assert p.message in text


def test_usable_record_refuses_what_no_analysis_can_use_and_warns_otherwise():
    """The one check every command runs: constant or NaN channels and bad time columns are
    refused, a short record only warned about (refused for fits), unused channels ignored."""
    from dtwin.errors import RecordError
    from dtwin.io.record import Record
    from dtwin.io.validate import usable_record

    fs = 5000.0
    t = np.arange(int(0.01 * fs)) / fs  # 10 ms: shorter than MIN_CARRIER_PERIODS carrier periods
    tone = np.sin(2 * np.pi * 500.0 * t)
    rec = Record(np.stack([tone, np.ones_like(t)]), fs, ("acc", "dead"), ("g", "g"))
    with pytest.raises(RecordError, match="constant"):
        usable_record(rec)  # every channel: the dead one is refused
    (p,) = usable_record(rec, channels=["acc"], f_mesh=500.0, f_carrier=5.94)
    assert p.kind == "too_short" and p.value == pytest.approx(MIN_CARRIER_PERIODS / 5.94)
    assert "0.01 s" in p.message and f"{MIN_CARRIER_PERIODS / 5.94:.3f} s" in p.message
    with pytest.raises(RecordError, match="for a fit"):
        usable_record(rec, channels=["acc"], f_mesh=500.0, f_carrier=5.94, fit=True)
    bad = Record(np.stack([np.where(t > 0.005, np.nan, tone)]), fs, ("acc",), ("g",))
    with pytest.raises(RecordError, match="NaN"):
        usable_record(bad, channels=["acc"])
