"""Bad records (issue 53): a convert onto its own input, cut WAV/TDMS files, a WAV header whose
bit depth its data lacks, absurd sample values. Each is refused with one message naming the
file and what is wrong; no input file is changed (sha256 before and after)."""

from __future__ import annotations

import hashlib
import os
import struct

import numpy as np
import pytest
from scipy.io import wavfile

from dtwin.cli import main
from dtwin.errors import RecordError
from dtwin.io.readers import read_record

FS = 8000


def _sha(path) -> str:
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def _run(argv, capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as e:
        main(argv)
    out, err = capsys.readouterr()
    return e.value.code, out, err


@pytest.fixture()
def wav(tmp_path):
    """A 2-channel 16-bit WAV of 4000 frames (16000 data bytes after a 44-byte header)."""
    x = (10000 * np.sin(2 * np.pi * 500 * np.arange(4000) / FS)).astype(np.int16)
    path = tmp_path / "rec.wav"
    wavfile.write(path, FS, np.stack([x, -x], axis=1))
    assert path.stat().st_size == 44 + 16000
    return path


def test_convert_onto_its_own_input_is_refused(tmp_path, wav, capsys):
    src = tmp_path / "rec.dtwin.h5"
    main(["record", "convert", str(wav), str(src)])
    capsys.readouterr()
    before = _sha(src)
    (tmp_path / "sub").mkdir()
    link = tmp_path / "link.dtwin.h5"
    link.symlink_to(src)
    os.link(src, tmp_path / "hard.dtwin.h5")
    for target in (src, tmp_path / "sub" / ".." / "rec.dtwin.h5", link,
                   tmp_path / "hard.dtwin.h5"):
        for force in ([], ["--force"]):
            code, _, err = _run(["record", "convert", str(src), str(target), *force], capsys)
            assert code == 2
            assert err.startswith("error: TARGET:") and "input file" in err, err
            assert err.count("\n") == 1
            assert _sha(src) == before


def test_truncated_wav(tmp_path, wav):
    cut = tmp_path / "cut.wav"
    cut.write_bytes(wav.read_bytes()[:44 + 6000])  # 1500 of 4000 frames, on a frame boundary
    with pytest.raises(RecordError, match="truncated") as e:
        read_record(cut)
    msg = str(e.value)
    assert str(cut) in msg and "16000 bytes" in msg and "6000" in msg


def test_wav_header_bit_depth_its_data_lacks(tmp_path, wav):
    data = bytearray(wav.read_bytes())
    tag, nch, rate, bps, align, bits = struct.unpack("<HHIIHH", data[20:36])
    assert (nch, align, bits) == (2, 4, 16)
    data[34:36] = struct.pack("<H", 24)  # 24 bits stated, 16-bit frames of 4 bytes stored
    bad = tmp_path / "bits.wav"
    bad.write_bytes(bytes(data))
    with pytest.raises(RecordError, match="24 bits") as e:
        read_record(bad)
    assert str(bad) in str(e.value) and "6-byte frames" in str(e.value)
    # a data chunk stating a size that is not whole frames: 16001 bytes of 4-byte frames
    data = bytearray(wav.read_bytes()) + b"\0"
    data[40:44] = struct.pack("<I", 16001)
    data[4:8] = struct.pack("<I", len(data) - 8)
    odd = tmp_path / "odd.wav"
    odd.write_bytes(bytes(data))
    with pytest.raises(RecordError, match="whole number of 4-byte frames"):
        read_record(odd)


def test_truncated_tdms(tmp_path):
    from nptdms import ChannelObject, TdmsWriter

    x = np.sin(np.arange(5000) * 0.1)
    path = tmp_path / "rec.tdms"
    with TdmsWriter(path) as w:
        w.write_segment([ChannelObject("g", "acc", x, properties={"wf_increment": 1 / FS}),
                         ChannelObject("g", "mic", 2 * x, properties={"wf_increment": 1 / FS})])
    assert read_record(path).n_samples == 5000
    whole = path.read_bytes()
    for keep in (0.99, 0.6):  # the second channel cut short; the first as well
        cut = tmp_path / f"cut{keep}.tdms"
        cut.write_bytes(whole[:int(keep * len(whole))])
        with pytest.raises(RecordError, match="truncated") as e:
            read_record(cut)
        assert str(cut) in str(e.value)
    # one channel cut at a whole sample: would read as a shorter record
    one = tmp_path / "one.tdms"
    with TdmsWriter(one) as w:
        w.write_segment([ChannelObject("g", "acc", x, properties={"wf_increment": 1 / FS})])
    cut = tmp_path / "one_cut.tdms"
    cut.write_bytes(one.read_bytes()[:-8 * 1000])
    with pytest.raises(RecordError, match="truncated"):
        read_record(cut)


def test_tdms_cut_in_its_lead_in_or_metadata(tmp_path, capsys):
    """A TDMS file cut inside its first segment's 28-byte lead-in, or inside the metadata that
    follows it: truncated (npTDMS reads such a file as one without channels), said in one
    `error:` line; npTDMS's own console handler prints nothing while the file is read."""
    import logging

    from nptdms import ChannelObject, TdmsWriter

    x = np.sin(np.arange(5000) * 0.1)
    path = tmp_path / "rec.tdms"
    with TdmsWriter(path) as w:
        w.write_segment([ChannelObject("g", "acc", x, properties={"wf_increment": 1 / FS})])
    whole = path.read_bytes()
    assert whole[:4] == b"TDSm"
    raw_offset = struct.unpack("<Q", whole[20:28])[0]  # metadata bytes after the lead-in
    heard: list[str] = []

    class Ear(logging.Handler):  # stands for npTDMS's console handler
        def emit(self, record):
            heard.append(record.getMessage())

    ear = Ear(logging.WARNING)
    loggers = [logging.getLogger(n) for n in ("nptdms.reader", "nptdms.tdms_segment")]
    for log in loggers:
        log.addHandler(ear)
    try:
        for keep in (5, 20, 28, 28 + raw_offset // 2):
            cut = tmp_path / f"cut{keep}.tdms"
            cut.write_bytes(whole[:keep])
            before = _sha(cut)
            code, out, err = _run(["record", "info", str(cut)], capsys)
            assert code == 2 and out == "", (keep, out)
            assert err.count("\n") == 1 and err.startswith(f"error: {cut}: "), (keep, err)
            assert "truncated" in err and "copy the file again" in err, (keep, err)
            assert _sha(cut) == before
    finally:
        for log in loggers:
            log.removeHandler(ear)
    assert heard == []
    for log in loggers:  # the handlers npTDMS had are back
        assert ear not in log.handlers
    junk = tmp_path / "junk.tdms"
    junk.write_bytes(b"abcd")
    with pytest.raises(RecordError, match="not a TDMS file"):
        read_record(junk)


def test_convert_onto_its_own_input_by_relative_spelling(tmp_path, wav, monkeypatch, capsys):
    """x, ./x and sub/../x from the working folder name the same file: refused, unchanged."""
    monkeypatch.chdir(tmp_path)
    main(["record", "convert", "rec.wav", "x.dtwin.h5"])
    capsys.readouterr()
    before = _sha("x.dtwin.h5")
    (tmp_path / "sub").mkdir()
    for src, target in (("x.dtwin.h5", "./x.dtwin.h5"), ("./x.dtwin.h5", "x.dtwin.h5"),
                        ("x.dtwin.h5", "sub/../x.dtwin.h5")):
        code, _, err = _run(["record", "convert", src, target, "--force"], capsys)
        assert code == 2 and err.startswith("error: TARGET:") and "input file" in err, err
        assert _sha("x.dtwin.h5") == before


def test_strict_info_flags_absurd_values(tmp_path, capsys):
    t = np.arange(20000) / 10000
    x = np.sin(2 * np.pi * 50 * t)
    median = float(np.median(np.abs(x)))
    cases = {"1e302": 1e302, "bound": 1.001e12 * median}
    for name, v in cases.items():
        y = x.copy()
        y[5000] = v
        path = tmp_path / f"{name}.csv"
        np.savetxt(path, np.stack([t, y], 1), delimiter=",", header="time,acc", comments="")
        before = _sha(path)
        code, out, _ = _run(["record", "info", str(path), "--strict"], capsys)
        assert code == 2 and _sha(path) == before
        assert "absurd sample" in out  # the problem's text (the folder's name holds "absurd" too)
    # a large but possible sample (1e6 × the median, 120 dB): not flagged
    y = x.copy()
    y[5000] = 1e6 * median
    path = tmp_path / "large.csv"
    np.savetxt(path, np.stack([t, y], 1), delimiter=",", header="time,acc", comments="")
    main(["record", "info", str(path), "--strict"])
    out = capsys.readouterr().out
    assert "absurd sample" not in out and "no problems found" in out
