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
