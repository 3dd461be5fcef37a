"""The family benchmark: what a user runs, on every gearbox of ``../shared/independent/``.

For each machine (the original gearbox in ``../shared/independent/`` and every folder of
``../shared/independent/machines/``), in one process, through the command line's own entry
(:func:`dtwin.cli.main`, each command with ``--json``, exactly as a user types it):

1. ``dtwin calibrate baseline-1.csv --spec gearbox.toml --out …``;
2. ``dtwin discover REC --spec calibrated.toml`` on every other record;
3. ``dtwin severity REC --spec calibrated.toml --location L`` on every tooth-fault record
   (and on baseline-2 at the sun: a healthy record must read ≤ 0.02 with 0 inside its interval).

``truth.json`` is read only to score. Each row says: machine, record, the groups named, the
held-out gap before → after (dB; for a calibration also the confirmed gap), for a fault its
peak stiffness loss fitted / true with the 95 % interval and the status, right or wrong, and
the wall time of the step. A summary per
machine and over the family follows. Written as ``family.json`` and ``family.md`` into
``--out`` (default ``benchmarks/out/family``).

Scoring (issue "Right on every machine" and "One fault depth"):

- the calibration on baseline-1: held-out gap ≤ 3 dB, and the confirmed gap (the calibrated
  spec's twin simulated in full on baseline-1) ≤ 3 dB too, with its teeth in contact (its
  ``contact_margin`` ≥ 0: a healthy gearbox under load does not part them);
- a healthy record (baseline-2): nothing added and reported gap ≤ 3 dB;
- an effect record: its group (:data:`GROUP`) is the first named and nothing else is added; a
  tone: nothing named;
- a tooth fault's severity: peak loss within 25 % of the truth and the 95 % interval covering
  it; a healthy baseline ≤ 0.02 with 0 inside; a profile fault (no stiffness loss in its
  truth) must not be reported as a determined stiffness loss.

Usage::

    python benchmarks/family.py [--machines original mcfadden-19-38-95 …] [--records …]
        [--steps calibrate discover severity] [--reuse] [--quick] [--out DIR]

``--reuse`` takes a calibrated spec already in ``--out`` instead of calibrating again;
``--quick`` runs discover with one step and fewer bootstrap draws (``--max-steps 1 --n-boot
200``) and without its depth fit (``--no-depth``: the severity step fits the same problem),
the reduced form the CI test uses. Otherwise a discover row also shows the depth (peak
stiffness loss) of a tooth fault it named, which must equal the severity row's.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: the independent records: ``../shared/independent`` beside the checkout, or ``$DTWIN_INDEPENDENT``
IND = Path(os.environ.get("DTWIN_INDEPENDENT", HERE.parents[1] / "shared" / "independent"))

#: the look-alike group a hidden effect belongs to (docs/discovery.md); None: nothing to name
GROUP = {
    "sun local tooth fault": "sun_rotation",
    "sun eccentricity": "sun_rotation",
    "planet local tooth fault": "planet_fault",
    "ring local tooth fault": "carrier_sidebands",
    "planet position errors": "carrier_sidebands",
    "sinusoidal load fluctuation": "located_modulation",
    "tone unrelated to the gearbox": None,
    "sun tooth profile deviation": "sun_rotation",
    "ring tooth profile deviation": "carrier_sidebands",
}
#: tooth faults and the location ``dtwin severity`` is run at
FAULT_LOCATION = {"sun local tooth fault": "sun", "planet local tooth fault": "planet",
                  "ring local tooth fault": "ring", "sun tooth profile deviation": "sun",
                  "ring tooth profile deviation": "ring"}
HEALTHY_MAX = 0.02
REL_TOL = 0.25
GAP_OK_DB = 3.0


def machines() -> dict[str, Path]:
    """Machine name → folder holding ``gearbox.toml``, ``truth.json`` and the records."""
    out = {"original": IND} if (IND / "truth.json").exists() else {}
    mdir = IND / "machines"
    if mdir.is_dir():
        out.update({p.name: p for p in sorted(mdir.iterdir()) if (p / "truth.json").exists()})
    return out


def effect_kind(effect: dict) -> str:
    """The truth's effect text without its parenthesised detail (a key of :data:`GROUP`)."""
    return effect["effect"].split(" (")[0].strip()


def run_cli(args: list[str]) -> tuple[int, dict | None, str, float]:
    """``dtwin ARGS --json`` in this process: exit code, the JSON printed, stderr, wall s."""
    from dtwin.cli import main

    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    code = 0
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main([*args, "--json"])
        except SystemExit as e:
            code = int(e.code or 0) if not isinstance(e.code, str) else 2
    wall = time.perf_counter() - t0
    if code in (130, 143):  # the command was interrupted: so is the benchmark
        raise KeyboardInterrupt(err.getvalue().strip())
    text = out.getvalue().strip()
    data = None
    if text:
        try:
            data = json.loads(text[text.find("{"):])
        except ValueError:
            data = None
    return code, data, err.getvalue(), wall


def _gap(d: dict | None, key: str) -> float:
    try:
        return float(d[key]["total"])
    except (KeyError, TypeError, ValueError):
        return float("nan")


def score_discover(truth_effects: list[dict], res: dict | None) -> dict:
    """Named groups, gaps and whether the right group (only) was named."""
    if res is None:
        return dict(named=[], groups=[], gap_before=float("nan"), gap_after=float("nan"),
                    right=False, why="no result")
    groups = [s["group"] for s in res.get("steps", [])]
    named = [s["named"] for s in res.get("steps", [])]
    before, after = _gap(res, "initial_gap"), _gap(res, "final_gap")
    if not truth_effects:  # healthy
        right = not groups and after <= GAP_OK_DB
        why = "" if right else (f"added {named}" if groups else f"gap {after:.2f} dB > 3 dB")
    else:
        want = GROUP.get(effect_kind(truth_effects[0]), "?")
        if want is None:
            right, why = not groups, ("" if not groups else f"added {named} for a tone")
        else:
            right = bool(groups) and groups[0] == want and all(g == want for g in groups)
            why = "" if right else (f"named nothing (wanted {want})" if not groups else
                                    f"named {groups} (wanted only {want})")
    depths = [s["depth"]["peak_stiffness_loss"] for s in res.get("steps", [])
              if s.get("depth")]
    return dict(named=named, groups=groups, gap_before=before, gap_after=after, right=right,
                why=why, depth=depths[0] if depths else None)


def score_severity(truth_effects: list[dict], res: dict | None) -> dict:
    """Peak loss fitted / true, interval, status, and whether it is right."""
    if res is None:
        return dict(peak=float("nan"), interval=[float("nan")] * 2, status="no result",
                    truth=None, right=False, why="no result")
    peak = float(res["peak_stiffness_loss"])
    lo, hi = (float(x) for x in res["peak_stiffness_loss_interval_95"])
    status = str(res.get("status", ""))
    eff = truth_effects[0] if truth_effects else None
    truth = None if eff is None else eff.get("peak_stiffness_loss")
    if eff is None:
        right = peak <= HEALTHY_MAX and lo <= 0.0 + 1e-12
        why = "" if right else f"healthy reads {peak:.3f} [{lo:.3f}, {hi:.3f}]"
    elif truth is None:  # a profile fault: no stiffness loss; never a confident wrong number
        confident = "NOT DETERMINED" not in status.upper() and lo > 0.0
        right = not confident
        why = "" if right else f"a profile fault read as a determined loss {peak:.3f}"
    else:
        within = abs(peak - truth) <= REL_TOL * truth
        covers = lo <= truth <= hi
        right = within and covers
        why = "" if right else ", ".join(
            x for x in (None if within else f"{peak / truth:.2f}× the truth",
                        None if covers else "interval misses the truth") if x)
    return dict(peak=peak, interval=[lo, hi], status=status, truth=truth, right=right, why=why)


def run_machine(name: str, folder: Path, out: Path, records: list[str] | None, steps: set[str],
                reuse: bool, quick: bool, log) -> list[dict]:
    truth = json.loads((folder / "truth.json").read_text())["records"]
    mout = out / name
    mout.mkdir(parents=True, exist_ok=True)
    cal_dir = mout / "calibration"
    cal_spec = cal_dir / "calibrated.toml"
    rows: list[dict] = []
    if "calibrate" in steps and not (reuse and cal_spec.exists()):
        code, res, err, wall = run_cli(["calibrate", str(folder / "baseline-1.csv"), "--spec",
                                        str(folder / "gearbox.toml"), "--out", str(cal_dir),
                                        "--force"])
        row = dict(machine=name, record="baseline-1", step="calibrate", wall_s=wall, code=code,
                   right=code == 0 and cal_spec.exists(),
                   why="" if code == 0 else err.strip().splitlines()[-1:] or "failed")
        if res is not None:
            row.update(gap_before=_gap(res, "gap_before"), gap_after=_gap(res, "gap_heldout"),
                       gap_confirmed=_gap(res, "gap_confirmed"),
                       not_determined=res.get("not_determined", []),
                       contact_margin=res.get("contact_margin"))
            if row["right"] and res.get("teeth_part"):  # a healthy loaded gearbox's do not
                row.update(right=False, why=f"the calibrated twin's teeth part (contact margin "
                                            f"{_f(row['contact_margin'])})")
            elif row["right"] and not row["gap_after"] <= GAP_OK_DB:  # nan: not right
                row.update(right=False, why=f"held-out gap {_f(row['gap_after'])} dB > "
                                            f"{GAP_OK_DB:g} dB")
            # the twin the calibrated spec holds, simulated in full on its own record
            elif row["right"] and not row["gap_confirmed"] <= GAP_OK_DB:
                row.update(right=False, why=f"confirmed gap {_f(row['gap_confirmed'])} dB > "
                                            f"{GAP_OK_DB:g} dB")
        rows.append(row)
        log(row)
    if not cal_spec.exists():
        return rows
    names = [r for r in truth if r != "baseline-1" and (records is None or r in records)]
    for rec in names:
        effects = truth[rec].get("effects", [])
        path = str(folder / f"{rec}.csv")
        if "discover" in steps:
            args = ["discover", path, "--spec", str(cal_spec)]
            if quick:  # the depth is the severity step's (one path): not fitted twice
                args += ["--max-steps", "1", "--n-boot", "200", "--no-depth"]
            code, res, err, wall = run_cli(args)
            row = dict(machine=name, record=rec, step="discover", wall_s=wall, code=code,
                       **score_discover(effects, res if code == 0 else None))
            if code != 0:
                row["why"] = (err.strip().splitlines() or ["failed"])[-1]
            rows.append(row)
            log(row)
        loc = None
        if effects and effect_kind(effects[0]) in FAULT_LOCATION:
            loc = FAULT_LOCATION[effect_kind(effects[0])]
        elif not effects and rec == "baseline-2":
            loc = "sun"
        if "severity" in steps and loc is not None:
            code, res, err, wall = run_cli(["severity", path, "--spec", str(cal_spec),
                                            "--location", loc])
            row = dict(machine=name, record=rec, step="severity", location=loc, wall_s=wall,
                       code=code, **score_severity(effects, res if code == 0 else None))
            if res is not None:  # the whole answer, bands and shapes, for a later look
                (mout / "severity").mkdir(exist_ok=True)
                (mout / "severity" / f"{rec}.json").write_text(json.dumps(res, indent=1))
            if code != 0:
                row["why"] = (err.strip().splitlines() or ["failed"])[-1]
            rows.append(row)
            log(row)
    return rows


def _f(x, fmt=".2f") -> str:
    try:
        return "–" if x is None or x != x else format(float(x), fmt)
    except (TypeError, ValueError):
        return str(x)


def markdown(rows: list[dict], meta: dict) -> str:
    out = [f"# Family benchmark ({meta['commit']}, {meta['date']}, load {meta['load']})", "",
           "| machine | record | step | named / fitted | gap before → after (dB) | truth | "
           "right | why | wall (s) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r["step"] == "severity":
            lo, hi = r["interval"]
            what = f"{_f(r['peak'], '.3f')} [{_f(lo, '.3f')}, {_f(hi, '.3f')}] {r['status']}"
            gap = ""
            truth = "healthy" if r["truth"] is None and r["record"].startswith("baseline") \
                else ("profile" if r["truth"] is None else _f(r["truth"], ".2f"))
        elif r["step"] == "discover":
            what = ", ".join(r["groups"]) or "nothing"
            if r.get("depth") is not None:
                what += f" (depth {_f(r['depth'], '.3f')})"
            gap = f"{_f(r['gap_before'])} → {_f(r['gap_after'])}"
            truth = ""
        else:
            what = f"not determined: {', '.join(r.get('not_determined', []))}"
            if r.get("contact_margin") is not None:
                what += f"; contact margin {_f(r['contact_margin'])}"
            gap = f"{_f(r.get('gap_before'))} → {_f(r.get('gap_after'))}"
            if r.get("gap_confirmed") is not None:
                gap += f" (confirmed {_f(r['gap_confirmed'])})"
            truth = ""
        out.append(f"| {r['machine']} | {r['record']} | {r['step']} | {what} | {gap} | {truth} |"
                   f" {'yes' if r['right'] else '**no**'} | {r.get('why', '')} | "
                   f"{r['wall_s']:.0f} |")
    out += ["", "| machine | step | right / rows | wall (s) |", "|---|---|---|---|"]
    for key, (n_ok, n, wall) in summary(rows).items():
        out.append(f"| {key[0]} | {key[1]} | {n_ok} / {n} | {wall:.0f} |")
    return "\n".join(out) + "\n"


def summary(rows: list[dict]) -> dict:
    acc: dict = {}
    for r in rows:
        for key in ((r["machine"], r["step"]), ("all", r["step"]), ("all", "all")):
            ok, n, wall = acc.get(key, (0, 0, 0.0))
            acc[key] = (ok + bool(r["right"]), n + 1, wall + r["wall_s"])
    return acc


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--machines", nargs="*", default=None)
    p.add_argument("--records", nargs="*", default=None)
    p.add_argument("--steps", nargs="*", default=["calibrate", "discover", "severity"])
    p.add_argument("--reuse", action="store_true", help="reuse calibrated specs in --out")
    p.add_argument("--quick", action="store_true", help="discover --max-steps 1 --n-boot 200")
    p.add_argument("--out", type=Path, default=HERE / "out" / "family")
    args = p.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    found = machines()
    if not found:
        print(f"no independent records at {IND}")
        return 0
    chosen = args.machines or list(found)
    unknown = [m for m in chosen if m not in found]
    if unknown:
        p.error(f"unknown machine(s) {unknown}; known: {list(found)}")
    args.out.mkdir(parents=True, exist_ok=True)

    def log(row):
        extra = (f"{row.get('groups')} {_f(row.get('gap_before'))} → {_f(row.get('gap_after'))}"
                 if row["step"] == "discover" else
                 f"{_f(row.get('peak'), '.3f')} {row.get('interval')} truth {row.get('truth')}"
                 if row["step"] == "severity" else "")
        print(f"{row['machine']:22s} {row['record']:14s} {row['step']:9s} "
              f"{'ok ' if row['right'] else 'NO '} {row['wall_s']:6.0f} s {extra} "
              f"{row.get('why', '')}", file=sys.stderr, flush=True)

    rows: list[dict] = []
    t0 = time.perf_counter()
    for m in chosen:
        rows += run_machine(m, found[m], args.out, args.records, set(args.steps), args.reuse,
                            args.quick, log)
    import subprocess

    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=HERE, text=True,
                            capture_output=True).stdout.strip()
    meta = dict(commit=commit, date=time.strftime("%Y-%m-%d %H:%M"),
                load=" ".join(f"{x:.1f}" for x in os.getloadavg()),
                wall_s=time.perf_counter() - t0, quick=args.quick, steps=args.steps)
    summ = {f"{k[0]}/{k[1]}": dict(right=v[0], rows=v[1], wall_s=v[2])
            for k, v in summary(rows).items()}
    (args.out / "family.json").write_text(json.dumps(dict(meta=meta, rows=rows, summary=summ),
                                                     indent=1, default=str))
    (args.out / "family.md").write_text(markdown(rows, meta))
    print(markdown(rows, meta))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
