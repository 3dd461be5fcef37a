"""The persistent-compilation-cache switch (`dtwin._config`, DTWIN_JAX_CACHE)."""

import os
import sys

from dtwin import _config


def test_cache_switch_words_are_not_folder_names(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    default = os.path.join(str(tmp_path), "dtwin", "jax")
    for word in ("off", "0", "none", "false", ""):
        monkeypatch.setenv("DTWIN_JAX_CACHE", word)
        assert _config.cache_dir() is None, word
    for word in ("on", "1", "true", "ON"):
        monkeypatch.setenv("DTWIN_JAX_CACHE", word)
        assert _config.cache_dir() == default, word
    monkeypatch.setenv("DTWIN_JAX_CACHE", "/some/folder")
    assert _config.cache_dir() == "/some/folder"
    monkeypatch.delenv("DTWIN_JAX_CACHE")
    assert _config.cache_dir() == default


_CACHE_DIR = "import dtwin, jax; print(jax.config.jax_compilation_cache_dir)"


def _cache_dir_in_new_process(**env: str | None) -> str:
    import subprocess

    environ = {k: v for k, v in os.environ.items()
               if k not in ("DTWIN_JAX_CACHE", "XDG_CACHE_HOME")}
    environ.update({k: v for k, v in env.items() if v is not None})
    return subprocess.run([sys.executable, "-c", _CACHE_DIR], env=environ, capture_output=True,
                          text=True, timeout=120, check=True).stdout.strip()


def test_cache_defaults_to_the_users_cache_folder_and_obeys_the_switch(tmp_path):
    """`import dtwin` points JAX's persistent cache at the XDG cache folder (not at the virtual
    environment, which a new clone or `make clean` throws away), at ``~/.cache`` without
    ``XDG_CACHE_HOME``, at the folder ``DTWIN_JAX_CACHE`` names, and nowhere when it is off."""
    xdg = tmp_path / "xdg"
    assert _cache_dir_in_new_process(XDG_CACHE_HOME=str(xdg)) == str(xdg / "dtwin" / "jax")
    assert (xdg / "dtwin" / "jax").is_dir()
    home = tmp_path / "home"
    assert _cache_dir_in_new_process(HOME=str(home)) == str(home / ".cache" / "dtwin" / "jax")
    mine = tmp_path / "mine"
    assert _cache_dir_in_new_process(DTWIN_JAX_CACHE=str(mine),
                                     XDG_CACHE_HOME=str(xdg)) == str(mine)
    for off in ("off", "0"):
        assert _cache_dir_in_new_process(DTWIN_JAX_CACHE=off, XDG_CACHE_HOME=str(xdg)) == "None"


_FIT_TWICE = """
import sys, time
import dtwin
from dtwin.model.faults import MissingTooth
from dtwin.identify.fit import fit
from dtwin.simulation.simulate import DAQ, simulate
from dtwin.spec import preset

spec = preset("paper-sim")
truth = dtwin.build_twin(spec, kind="torsional", faults=(MissingTooth(0.4, location="sun"),))
rec = simulate(truth, duration=0.4, f_sun=30.0, daq=DAQ(snr_db=20.0), discard=0.02).to_record()
res = fit(rec, spec, ["sun_fault"], initial={"sun_fault": 0.3}, f_sun=30.0, max_steps=3,
          uncertainty=False)
print(repr(res.values["sun_fault"]), len(res.loss_history))
"""


def test_equinox_checks_return_nan_unless_the_user_says_otherwise():
    """`import dtwin` sets ``EQX_ON_ERROR=nan`` before equinox is imported, and keeps a value
    the user set."""
    import subprocess

    code = "import dtwin, equinox, os; print(os.environ['EQX_ON_ERROR'])"
    environ = {k: v for k, v in os.environ.items() if k != "EQX_ON_ERROR"}
    for given, seen in ((None, "nan"), ("raise", "raise")):
        env = environ if given is None else {**environ, "EQX_ON_ERROR": given}
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                             text=True, timeout=120, check=True).stdout.strip()
        assert out == seen, (given, out)


def test_simulation_and_fit_are_written_to_the_compilation_cache(tmp_path):
    """By default (dtwin._config sets ``EQX_ON_ERROR=nan``: equinox's default checks call back
    to the host) a fit compiles the ODE solve and the solver loop once per machine, not once
    per process: both programs reach the persistent cache (the fit's own loss history is kept
    in the solver's state, not sent by a callback, which would keep it out), and a second
    process reads them back and gets the same fit."""
    import subprocess

    cache = tmp_path / "cache"
    env = {k: v for k, v in os.environ.items() if k != "EQX_ON_ERROR"}
    env.update({"DTWIN_JAX_CACHE": str(cache), "JAX_ENABLE_X64": "1"})
    outs = [subprocess.run([sys.executable, "-c", _FIT_TWICE], env=env, capture_output=True,
                           text=True, timeout=600, check=True).stdout.split()
            for _ in range(2)]
    names = {p.name.split("-")[0] for p in cache.iterdir()}
    assert {"jit__solve", "jit_refine_starts"} <= names, sorted(names)
    assert outs[0] == outs[1]
    assert int(outs[0][1]) >= 2  # the loss history holds the solver's evaluations
