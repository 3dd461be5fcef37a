"""Run one benchmark script against an earlier commit's library and the current one, side by side.

A figure of speed or memory means little on a shared machine unless the code it is compared with
ran in the same session: this script checks out ``--base`` (any git revision) into a worktree,
then runs the *same* script (the current tree's file, with the same arguments) once with the
base's ``dtwin`` / ``dtwin.identify`` and once with the current ones, alternating base and
current ``--repeat`` times. Every run reports wall time, CPU time (user + system of the process
and the processes it waited for), peak resident memory and the load average before and after
(``/proc/loadavg``); a script that prints JSON (``--json`` is passed when the script accepts it)
gets its numeric figures compared key by key, with the ratio current / base.

How the base's code is loaded: the worktree goes first on ``PYTHONPATH`` with a
``sitecustomize`` that removes the editable install's import finder from ``sys.meta_path``, and
``dtwin/identify`` in the worktree links to its top-level ``identify/`` (the package-dir mapping
of ``pyproject.toml``); processes the script starts (``run_all.py`` starts one per script)
inherit the environment, so they load the base too. Base runs start in the worktree (a
``python -m dtwin`` puts the working directory first on ``sys.path``), current runs in the
repository root; relative paths in the script's arguments resolve there. The persistent compilation cache is off for
both (``DTWIN_JAX_CACHE=off``) unless ``--cache`` is given, so compile times compare.

Usage::

    python benchmarks/compare.py --base 69a1100 benchmarks/bench_fit.py --quick
    python benchmarks/compare.py --base 5f9f60d --repeat 2 --out cmp.json benchmarks/run_all.py

Prints one table; ``--out FILE`` writes every run (figures, times, load, stdout tail) as JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from _timing import wait_measured  # noqa: E402

_SITECUSTOMIZE = '''\
import sys
# benchmarks/compare.py: load dtwin from the base worktree, not from the editable install
sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in repr(f).lower()]
'''


def _git(*args: str, cwd: Path = ROOT) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True,
                          text=True).stdout.strip()


def base_tree(rev: str, where: Path | None = None) -> tuple[Path, str]:
    """A worktree of `rev` (created once per commit, reused): ``(path, full sha)``."""
    sha = _git("rev-parse", "--verify", f"{rev}^{{commit}}")
    root = where or Path(tempfile.gettempdir()) / "dtwin-compare"
    tree = root / sha[:12]
    if not (tree / "dtwin" / "__init__.py").exists():
        root.mkdir(parents=True, exist_ok=True)
        _git("worktree", "add", "--detach", "--force", str(tree), sha)
    link = tree / "dtwin" / "identify"
    if (tree / "identify").is_dir() and not link.exists():
        link.symlink_to(Path("..") / "identify")
    boot = root / "boot"
    boot.mkdir(parents=True, exist_ok=True)
    (boot / "sitecustomize.py").write_text(_SITECUSTOMIZE)
    return tree, sha


def _loadavg() -> list[float]:
    with open("/proc/loadavg") as f:
        return [float(v) for v in f.read().split()[:3]]


def _accepts_json(script: Path) -> bool:
    try:
        return "--json" in script.read_text()
    except OSError:
        return False


def _last_json(text: str):
    """The last JSON value printed on stdout (a line or a block starting with ``[`` or ``{``)."""
    lines = text.splitlines()
    for i in range(len(lines) - 1, -1, -1):
        if lines[i].lstrip().startswith(("[", "{")):
            try:
                return json.loads("\n".join(lines[i:]))
            except json.JSONDecodeError:
                continue
    return None


def flatten(obj, prefix: str = "") -> dict[str, float]:
    """Numeric leaves of nested dicts/lists as ``{"a.b.0.c": value}`` (lists of records keyed by
    their ``kind``/``name`` when they have one)."""
    out: dict[str, float] = {}
    if isinstance(obj, bool):
        return out
    if isinstance(obj, int | float):
        out[prefix.rstrip(".")] = float(obj)
    elif isinstance(obj, dict):
        for k, v in obj.items():
            out.update(flatten(v, f"{prefix}{k}."))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            tag = str(i)
            if isinstance(v, dict):
                tag = str(v.get("kind") or v.get("name") or v.get("record") or i)
            out.update(flatten(v, f"{prefix}{tag}."))
    return out


def run_once(script: Path, args: list[str], tree: Path | None, boot: Path | None,
             cache: bool, timeout: float) -> dict:
    """One run of `script` with the library of `tree` (None: the current checkout)."""
    env = dict(os.environ)
    if not cache:
        env["DTWIN_JAX_CACHE"] = "off"
    if tree is not None:
        env["PYTHONPATH"] = os.pathsep.join(
            [str(boot), str(tree)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    load0 = _loadavg()
    t0 = time.perf_counter()
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        # the base runs inside its worktree: a `python -m dtwin` the script starts puts the
        # working directory first on sys.path, so it must be the base's
        proc = subprocess.Popen([sys.executable, str(script), *args], cwd=tree or ROOT, env=env,
                                stdout=out, stderr=err, text=True)
        m = wait_measured(proc, t0, timeout)
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read(), err.read()
    return {
        "code": "base" if tree is not None else "current",
        "returncode": m["returncode"],
        "wall_s": m["wall_s"],
        "cpu_s": m["cpu_s"],
        "peak_rss_mb": m["peak_rss_mb"],
        "load_before": load0,
        "load_after": _loadavg(),
        "figures": flatten(_last_json(stdout)),
        "stdout_tail": stdout[-4000:],
        "stderr_tail": stderr[-2000:],
    }


def _fmt(v: float | None) -> str:
    if v is None:
        return "—"
    a = abs(v)
    if a != 0 and (a < 1e-3 or a >= 1e6):
        return f"{v:.3e}"
    return f"{v:.4g}"


def table(runs: list[dict]) -> str:
    """Median of each figure per side, and the ratio current / base."""
    import statistics

    rows = ["wall_s", "cpu_s", "peak_rss_mb"]
    keys = sorted({k for r in runs for k in r["figures"]})
    lines = [f"{'figure':<60} {'base':>12} {'current':>12} {'cur/base':>9}"]

    def med(side, key, top):
        vals = [(r[key] if top else r["figures"].get(key)) for r in runs if r["code"] == side]
        vals = [v for v in vals if v is not None]
        return statistics.median(vals) if vals else None

    for key, top in [(k, True) for k in rows] + [(k, False) for k in keys]:
        b, c = med("base", key, top), med("current", key, top)
        ratio = f"{c / b:.2f}" if b and c is not None else ""
        lines.append(f"{key[:60]:<60} {_fmt(b):>12} {_fmt(c):>12} {ratio:>9}")
    for r in runs:
        lines.append(f"  {r['code']:<8} rc {r['returncode']}  wall {r['wall_s']:.1f} s  "
                     f"cpu {r['cpu_s']:.1f} s  rss {r['peak_rss_mb']:.0f} MB  load "
                     f"{' '.join(f'{x:.2f}' for x in r['load_before'])} -> "
                     f"{' '.join(f'{x:.2f}' for x in r['load_after'])}")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--base", required=True, help="git revision whose library is the baseline")
    p.add_argument("--repeat", type=int, default=1, help="pairs of runs (alternating order)")
    p.add_argument("--cache", action="store_true", help="keep the persistent compilation cache")
    p.add_argument("--timeout", type=float, default=3600.0, help="seconds per run")
    p.add_argument("--out", type=Path, help="write every run as JSON here")
    p.add_argument("--no-json", action="store_true", help="do not pass --json to the script")
    p.add_argument("script", type=Path)
    p.add_argument("args", nargs=argparse.REMAINDER)
    a = p.parse_args(argv)
    if a.repeat < 1:
        p.error("--repeat must be at least 1")
    script = a.script.resolve()
    if not script.is_file():
        p.error(f"no script {a.script}")
    args = list(a.args)
    if not a.no_json and "--json" not in args and _accepts_json(script):
        args.append("--json")
    tree, sha = base_tree(a.base)
    boot = tree.parent / "boot"
    head = _git("rev-parse", "HEAD")
    dirty = bool(_git("status", "--porcelain", "--untracked-files=no"))
    print(f"base {sha[:12]} ({tree}); current {head[:12]}{' + uncommitted changes' if dirty else ''}",
          file=sys.stderr)
    runs = []
    for i in range(a.repeat):
        order = (tree, None) if i % 2 == 0 else (None, tree)
        for t in order:
            r = run_once(script, args, t, boot, a.cache, a.timeout)
            print(f"{r['code']}: rc {r['returncode']}, {r['wall_s']:.1f} s wall, "
                  f"{r['cpu_s']:.1f} s CPU, load {r['load_before'][0]:.2f}", file=sys.stderr)
            runs.append(r)
    print(table(runs))
    if a.out:
        a.out.write_text(json.dumps({"base": sha, "current": head, "dirty": dirty,
                                     "script": str(a.script), "args": args, "runs": runs},
                                    indent=1))
    return 0 if all(r["returncode"] == 0 for r in runs) else 1


if __name__ == "__main__":
    raise SystemExit(main())
