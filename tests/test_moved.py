"""Old import paths of moved modules (``dtwin._moved``): an old path, and anything below it,
imports as the very module object of the new path; every entry's target exists and no file is
left at an old path; docs/changelog.md lists every move."""

import importlib
import sys
from pathlib import Path

import pytest

import dtwin
from dtwin import _moved

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture
def fake_moves(monkeypatch):
    """Two made-up moves onto existing modules: a module and a package."""
    monkeypatch.setitem(_moved.MOVED, "dtwin.old_gears_for_test", "dtwin.model.gears")
    monkeypatch.setitem(_moved.MOVED, "dtwin.old_parts_for_test", "dtwin.model.motor")
    yield
    for name in list(sys.modules):
        if "_for_test" in name:
            del sys.modules[name]


def test_an_old_path_is_the_same_module(fake_moves):
    import dtwin.model.gears

    old = importlib.import_module("dtwin.old_gears_for_test")
    assert old is dtwin.model.gears
    assert old.__spec__.name == "dtwin.model.gears"  # its own spec, not the alias's
    from dtwin.old_gears_for_test import GearSet
    assert GearSet is dtwin.model.gears.GearSet


def test_a_submodule_below_an_old_package_path_is_the_same_module(fake_moves):
    import dtwin.model.motor.pmsm

    old = importlib.import_module("dtwin.old_parts_for_test.pmsm")
    assert old is dtwin.model.motor.pmsm
    from dtwin.old_parts_for_test.pmsm import PMSM
    assert PMSM is dtwin.PMSM


def test_an_unknown_path_still_fails():
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("dtwin.no_such_module_anywhere")


def _file_of(name: str) -> Path:
    parts = name.split(".")
    base = ROOT / "identify" if parts[:2] == ["dtwin", "identify"] else ROOT / "dtwin"
    rest = parts[2:] if parts[:2] == ["dtwin", "identify"] else parts[1:]
    return base.joinpath(*rest)


@pytest.mark.parametrize("old,new", sorted(_moved.MOVED.items()))
def test_every_move_leads_to_a_module_and_leaves_no_file_behind(old, new):
    assert importlib.import_module(old) is importlib.import_module(new)
    f = _file_of(old)
    assert not f.with_suffix(".py").exists() and not (f / "__init__.py").exists(), \
        f"{old} is still a file: the move left a copy"


def test_the_changelog_lists_every_move():
    text = (ROOT / "docs" / "changelog.md").read_text(encoding="utf-8")
    missing = [old for old, new in _moved.MOVED.items()
               if f"`{old}` | `{new}`" not in text]
    assert missing == [], "docs/changelog.md lacks these moves: " + ", ".join(missing)


def test_dtwin_installs_the_finder_once():
    _moved.install()
    assert sum(isinstance(f, _moved._MovedFinder) for f in sys.meta_path) == 1
    assert dtwin.__name__ == "dtwin"
