"""The persistent-compilation-cache switch (`dtwin._config`, DTWIN_JAX_CACHE)."""

import os
import sys

from dtwin import _config


def test_cache_switch_words_are_not_folder_names(monkeypatch):
    in_venv = sys.prefix != sys.base_prefix
    default = os.path.join(sys.prefix, "jax-cache") if in_venv else None
    for word in ("off", "0", "none", "false", ""):
        monkeypatch.setenv("DTWIN_JAX_CACHE", word)
        assert _config._cache_dir() is None, word
    for word in ("on", "1", "true", "ON"):
        monkeypatch.setenv("DTWIN_JAX_CACHE", word)
        got = _config._cache_dir()
        assert got is not None and os.path.basename(got) == "jax-cache", (word, got)
        if in_venv:
            assert got == default
    monkeypatch.setenv("DTWIN_JAX_CACHE", "/some/folder")
    assert _config._cache_dir() == "/some/folder"
    monkeypatch.delenv("DTWIN_JAX_CACHE")
    assert _config._cache_dir() == default


_FIT_TWICE = """
import sys, time
import dtwin
from dtwin.faults import MissingTooth
from dtwin.identify.fit import fit
from dtwin.simulate import DAQ, simulate
from dtwin.spec import preset

spec = preset("paper-sim")
truth = dtwin.build_twin(spec, kind="torsional", faults=(MissingTooth(0.4, location="sun"),))
rec = simulate(truth, duration=0.4, f_sun=30.0, daq=DAQ(snr_db=20.0), discard=0.02).to_record()
res = fit(rec, spec, ["sun_fault"], initial={"sun_fault": 0.3}, f_sun=30.0, max_steps=3,
          uncertainty=False)
print(repr(res.values["sun_fault"]), len(res.loss_history))
"""


def test_simulation_and_fit_are_written_to_the_compilation_cache(tmp_path):
    """With ``EQX_ON_ERROR=nan`` (dtwin._config: equinox's default checks call back to the
    host), a fit compiles the ODE solve and the solver loop once per machine, not once per
    process: both programs reach the persistent cache (the fit's own loss history is kept in
    the solver's state, not sent by a callback, which would keep it out), and a second process
    reads them back and gets the same fit."""
    import subprocess

    cache = tmp_path / "cache"
    env = {**os.environ, "DTWIN_JAX_CACHE": str(cache), "JAX_ENABLE_X64": "1",
           "EQX_ON_ERROR": "nan"}
    outs = [subprocess.run([sys.executable, "-c", _FIT_TWICE], env=env, capture_output=True,
                           text=True, timeout=600, check=True).stdout.split()
            for _ in range(2)]
    names = {p.name.split("-")[0] for p in cache.iterdir()}
    assert {"jit__solve", "jit__refine"} <= names, sorted(names)
    assert outs[0] == outs[1]
    assert int(outs[0][1]) >= 2  # the loss history holds the solver's evaluations
