"""The package's structure (issues 18, 52): no import circles among modules, counting the
imports inside functions too; no ``_private`` name of a module imported from another package;
the parts do not import the twin, format modules do not import their dispatcher, the top-level
package exposes the twin and not the Section 6 study, docstrings cite papers, standards or
docs/, never a file outside the repository. Read from the source text (``ast``), so nothing is
imported twice. Imports under ``if TYPE_CHECKING:`` are for annotations and are never run, so
they are not counted."""

import ast
import re
from pathlib import Path

import pytest

import dtwin

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ((ROOT / "dtwin", "dtwin"), (ROOT / "identify", "dtwin.identify"))


def _modules() -> dict[str, tuple[Path, bool]]:
    mods = {}
    for base, pkg in PACKAGES:
        for f in base.rglob("*.py"):
            parts = list(f.relative_to(base).with_suffix("").parts)
            is_pkg = parts[-1] == "__init__"
            if is_pkg:
                parts = parts[:-1]
            mods[".".join([pkg, *parts])] = (f, is_pkg)
    return mods


def _tree(f: Path) -> ast.Module:
    """The module's syntax tree without its ``if TYPE_CHECKING:`` blocks (annotations only)."""
    tree = ast.parse(f.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING":
            node.body = []
    return tree


def _from_module(name: str, n: ast.ImportFrom, is_pkg: bool) -> str:
    if not n.level:
        return n.module or ""
    base = name.split(".") if is_pkg else name.split(".")[:-1]
    base = base[: len(base) - (n.level - 1)]
    return ".".join(base + ([n.module] if n.module else []))


def _imports(name: str, tree: ast.Module, is_pkg: bool, mods, *, module_level: bool
             ) -> set[str]:
    nodes = tree.body if module_level else list(ast.walk(tree))
    out = set()
    for n in nodes:
        if isinstance(n, ast.ImportFrom):
            m = _from_module(name, n, is_pkg)
            for a in n.names:
                full = f"{m}.{a.name}"
                out.add(full if full in mods else m)
        elif isinstance(n, ast.Import):
            out.update(a.name for a in n.names)
    return {d for d in out if d in mods and d != name}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    index, low, stack, on, found, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in list(graph):
        if v not in index:
            visit(v)
    return found


def test_no_import_circles_at_module_level():
    mods = _modules()
    graph = {n: _imports(n, _tree(f), p, mods, module_level=True) for n, (f, p) in mods.items()}
    assert _cycles(graph) == []


def test_no_import_circles_through_imports_inside_functions():
    """A function-local import hides a circle from the module-level graph but not from the
    design: it is counted like any other."""
    mods = _modules()
    graph = {n: _imports(n, _tree(f), p, mods, module_level=False) for n, (f, p) in mods.items()}
    assert _cycles(graph) == []


def _package(name: str, mods) -> str:
    return name if mods[name][1] else name.rpartition(".")[0]


def test_no_private_name_is_imported_from_another_package():
    """``from dtwin.simulation.simulate import _daq`` in ``dtwin.identify``: a name its module keeps to
    itself, used where that module cannot see it. Within a package such names are shared by
    design; across packages a name is public or not imported. A private *module*
    (``dtwin._heap``, ``dtwin._maps``) is the project's own machinery and may be imported
    anywhere."""
    mods = _modules()
    found = []
    for name, (f, is_pkg) in mods.items():
        for n in ast.walk(_tree(f)):
            if not isinstance(n, ast.ImportFrom):
                continue
            m = _from_module(name, n, is_pkg)
            if m not in mods:
                continue
            for a in n.names:
                if a.name.startswith("_") and not a.name.startswith("__") and \
                        f"{m}.{a.name}" not in mods and _package(m, mods) != _package(name, mods):
                    found.append(f"{name} imports {m}.{a.name}")
    assert found == []


@pytest.mark.parametrize("module,forbidden", [
    # parts share Coords/MeshState with the twin through dtwin.model.coords, never the twin itself
    *[(f"dtwin.model.{d}.{f.stem}", "dtwin.model.twin") for d in ("parts", "motor")
      for f in sorted((ROOT / "dtwin" / "model" / d).glob("*.py")) if f.stem != "__init__"],
    # format modules use dtwin.io.values/files, never the dispatcher or the result folders
    *[(f"dtwin.io.{f.stem}", "dtwin.io.readers") for f in (ROOT / "dtwin" / "io").glob("fmt_*.py")],
    *[(f"dtwin.io.{f.stem}", "dtwin.io.output") for f in (ROOT / "dtwin" / "io").glob("fmt_*.py")],
])
def test_no_upward_import(module, forbidden):
    """Not even inside a function (the annotations-only TYPE_CHECKING block aside)."""
    mods = _modules()
    f, is_pkg = mods[module]
    deps = _imports(module, _tree(f), is_pkg, mods, module_level=False)
    assert forbidden not in deps, f"{module} imports {forbidden}"


def test_top_level_exposes_the_twin_not_the_section6_study():
    for name in ("compare_drives", "sensitivity_sweep", "fault_rms", "comparison_twins",
                 "DriveComparison", "SensitivitySweep", "fault_rms_and_slope"):
        assert not hasattr(dtwin, name), name
    from dtwin.report.drive_comparison import compare_drives

    assert callable(compare_drives)
    for name in ("Twin", "build_twin", "simulate", "preset", "characteristic_frequencies"):
        assert hasattr(dtwin, name), name


def test_docstrings_cite_no_file_outside_the_repository():
    """Facts once cited as ``reference.md §N`` (a file not in the repository) are in
    docs/references.md; no source file names it."""
    bad = []
    for base, _ in PACKAGES:
        for f in base.rglob("*.py"):
            if re.search(r"reference\.md", f.read_text(encoding="utf-8")):
                bad.append(str(f.relative_to(ROOT)))
    assert bad == []
    assert (ROOT / "docs" / "references.md").exists()


def test_identify_raises_dtwin_errors_for_bad_settings():
    """Invalid settings of a fleet run, a fit's features or a search are `SettingsError`: a
    `DtwinError` (reported per record by fleet tasks, one line by the CLI) and a `ValueError`."""
    from dtwin.errors import DtwinError, SettingsError
    from dtwin.identify.discover import normal_quantile
    from dtwin.identify.fleet import FleetSettings
    from dtwin.identify.residuals import Features
    from dtwin.identify.trends import parse_threshold

    for make in (lambda: FleetSettings(batch_size=0), lambda: FleetSettings(kind="rigid"),
                 lambda: Features(grid="bins"), lambda: normal_quantile(1.5),
                 lambda: parse_threshold("sun_fault 3")):
        with pytest.raises(SettingsError) as e:
            make()
        assert isinstance(e.value, DtwinError) and isinstance(e.value, ValueError)


# ---- docs/structure.md's rooms, checked against the code (issue 52) --------------------------

STRUCTURE = ROOT / "docs" / "structure.md"


def _doc_rooms() -> dict[str, list[str]]:
    """Room → its entries (module or package paths), from the room table of docs/structure.md:
    the table under the ``<!-- rooms`` marker, modules in backquotes in its third column."""
    text = STRUCTURE.read_text(encoding="utf-8")
    table = text.split("<!-- rooms", 1)[1].split("\n\n", 1)[0]
    rooms = {}
    for line in table.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 3 or cells[0] in ("room", "") or set(cells[0]) <= {"-"}:
            continue
        assert cells[0] not in rooms, f"room {cells[0]} listed twice"
        rooms[cells[0]] = re.findall(r"`([\w.]+)`", cells[2])
    return rooms


def _doc_arrows() -> dict[str, set[str]]:
    """Room → the rooms it may import, from the list under the ``<!-- arrows`` marker."""
    text = STRUCTURE.read_text(encoding="utf-8")
    block = text.split("<!-- arrows", 1)[1].split("-->", 1)[1].strip().split("\n\n", 1)[0]
    arrows = {}
    for line in block.splitlines():
        m = re.fullmatch(r"- (\w+) → (.*)", line.strip())
        assert m, f"not an arrow: {line!r}"
        assert m.group(1) not in arrows, f"arrows of {m.group(1)} listed twice"
        arrows[m.group(1)] = {r.strip() for r in m.group(2).split(",")}
    return arrows


def _covers(entry: str, module: str) -> bool:
    # `dtwin` stands for dtwin/__init__.py alone; any other package covers what is below it
    return module == entry or (entry != "dtwin" and module.startswith(entry + "."))


def _room_of(rooms: dict[str, list[str]]) -> dict[str, str]:
    """Each module → its room (the longest entry covering it). Fails for a module in no room or
    in two rooms at once (the same entry listed twice)."""
    mods = _modules()
    entries = [(e, r) for r, es in rooms.items() for e in es]
    dup = sorted({e for e, _ in entries if sum(e == x for x, _ in entries) > 1})
    assert dup == [], f"listed in more than one room: {dup}"
    unknown = sorted(e for e, _ in entries if e not in mods)
    assert unknown == [], f"docs/structure.md names modules that do not exist: {unknown}"
    out, homeless = {}, []
    for m in mods:
        hits = [(len(e), r) for e, r in entries if _covers(e, m)]
        if not hits:
            homeless.append(m)
            continue
        out[m] = max(hits)[1]
    assert homeless == [], f"modules in no room of docs/structure.md: {sorted(homeless)}"
    return out


def test_every_module_sits_in_one_room_of_the_docs():
    rooms = _doc_rooms()
    assert {"core", "model", "signal", "spec", "io", "report", "cli"} <= set(rooms)
    room_of = _room_of(rooms)
    assert room_of["dtwin.model.twin"] == "model"
    assert room_of["dtwin"] == "top"


def test_the_docs_arrows_name_rooms_and_have_no_cycle():
    rooms, arrows = _doc_rooms(), _doc_arrows()
    named = set(arrows) | {r for rs in arrows.values() for r in rs}
    assert named <= set(rooms), f"arrows name rooms not in the table: {named - set(rooms)}"
    assert _cycles({r: set(rs) for r, rs in arrows.items()}) == []
    assert all(r not in rs for r, rs in arrows.items()), "a room's arrow to itself"


def test_imports_between_rooms_follow_the_docs_arrows():
    """Counting imports inside functions (the annotations-only TYPE_CHECKING block aside)."""
    rooms, arrows = _doc_rooms(), _doc_arrows()
    room_of = _room_of(rooms)
    mods = _modules()
    bad = []
    for name, (f, is_pkg) in sorted(mods.items()):
        a = room_of[name]
        for dep in sorted(_imports(name, _tree(f), is_pkg, mods, module_level=False)):
            b = room_of[dep]
            if b != a and b not in arrows.get(a, set()):
                bad.append(f"{name} ({a}) imports {dep} ({b})")
    assert bad == [], "imports docs/structure.md does not allow:\n" + "\n".join(bad)


# The command line imports every command module to build `dtwin --help`, so its modules (and the
# demo, a script of those commands) import the library inside the command functions: the
# start-up time of one command does not pay for all (dtwin/cli/app.py). Anywhere else a
# first-party import inside a function needs its reason, a comment on its line or the line
# above (a heavy optional dependency loaded when its output is asked for).
_DEFERRING = ("dtwin.cli", "dtwin.identify.demo")


def test_first_party_imports_inside_functions_say_why():
    found = []
    for name, (f, is_pkg) in _modules().items():
        if name.startswith(_DEFERRING):
            continue
        lines = f.read_text(encoding="utf-8").splitlines()
        for fn in ast.walk(_tree(f)):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for n in ast.walk(fn):
                if isinstance(n, ast.ImportFrom):
                    target = _from_module(name, n, is_pkg)
                elif isinstance(n, ast.Import):
                    target = n.names[0].name
                else:
                    continue
                if not target.startswith("dtwin"):
                    continue
                here = " ".join(lines[max(n.lineno - 2, 0):n.lineno])  # its line, the one above
                if "#" not in here:
                    found.append(f"{f.relative_to(ROOT)}:{n.lineno} {lines[n.lineno - 1].strip()}")
    assert sorted(set(found)) == [], "imports inside functions without a reason"
