"""``dtwin spec``: check gearbox spec files and show their schema.

    dtwin spec check FILE [--json]
    dtwin spec schema

``check`` loads the spec with :func:`dtwin.spec.load_spec`, which collects every problem at
once; each is printed with the field's dotted path (``gears.module: …``). Exit code 0 when the
spec is valid, 2 when it has problems (or cannot be read). ``--json`` prints
``{"file", "ok", "problems": [{"path", "message"}], "warnings", "spec"}`` on stdout, where
``spec`` is the validated spec with defaults filled (null when invalid). ``schema`` prints the
documented schema (Markdown) of every section and field.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import typer

from ..errors import SpecError, UnreadableFileError
from .app import app

spec_app = typer.Typer(help="Gearbox spec files (TOML; what is wrong, the fields): check, schema.")
app.add_typer(spec_app, name="spec")


def check_spec_file(path: Path) -> dict[str, Any]:
    """Load and validate a spec file; **returns** the JSON-ready report of ``dtwin spec check``."""
    from .. import spec as spec_mod

    report: dict[str, Any] = {"file": str(path), "ok": False, "problems": [], "warnings": [],
                              "spec": None}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            spec = spec_mod.load_spec(path)
        except SpecError as e:
            report["problems"] = [{"path": p, "message": m} for p, m in e.problems]
        except UnreadableFileError as e:
            report["problems"] = [{"path": "", "message": str(e)}]
        except UnicodeDecodeError as e:  # tomllib on a binary file, before spec.py converts it
            report["problems"] = [{"path": "", "message": f"{path} is not a UTF-8 text (TOML) "
                                   f"file ({e.reason} at byte {e.start}); save it as UTF-8"}]
        else:
            report["ok"] = True
            report["spec"] = spec_mod.spec_to_dict(spec)
    report["warnings"] = [str(w.message) for w in caught]
    return report


@spec_app.command("check")
def check(
    file: Path = typer.Argument(..., help="Gearbox spec file (TOML)."),
    json_out: bool = typer.Option(False, "--json", help="Print the report as JSON on stdout."),
) -> None:
    """Check a spec file: every problem at once, with the field's path. Exit 2 on problems."""
    report = check_spec_file(file)
    if json_out:
        from ..io.output import to_jsonable

        typer.echo(json.dumps(to_jsonable(report), indent=2))
    else:
        _print_report(report)
    if not report["ok"]:
        import sys

        fields = sorted({p["path"] or "(file)" for p in report["problems"]})
        print(f"error: {file}: {len(report['problems'])} problem(s) in the spec "
              f"({', '.join(fields)}){'' if json_out else ', listed above'}; fix them and "
              "check again", file=sys.stderr)
        raise SystemExit(2)


@spec_app.command("schema")
def schema() -> None:
    """Print the spec schema: sections, fields, units, defaults and allowed ranges (Markdown)."""
    from ..spec import schema_markdown

    typer.echo(schema_markdown())


def _print_report(report: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    console = Console()
    for w in report["warnings"]:
        console.print(f"[yellow]warning:[/yellow] {escape(w)}")
    if report["ok"]:
        console.print(f"[green]{escape(report['file'])}: valid spec[/green]")
        return
    table = Table(title=f"{report['file']}: {len(report['problems'])} problem(s)")
    table.add_column("field")
    table.add_column("problem")
    for p in report["problems"]:
        table.add_row(escape(p["path"] or "(file)"), escape(p["message"]))
    console.print(table)
