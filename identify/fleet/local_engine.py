"""The local engine of a fleet run: the tasks one after another in this process, with retries."""

from __future__ import annotations

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from .plan import _Plan
from .store import _Writer
from .tasks import discover_task, failure_entry, fit_task


def _progress(total: int, enabled: bool):
    return Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TimeElapsedColumn(), TimeRemainingColumn(),
                    console=Console(stderr=True), disable=not enabled, transient=False)


def _run_local(pl: _Plan, spec_data, settings, fp, writer: _Writer, inject, attempts_dir,
               progress: bool) -> None:
    def attempt(fn, *args, **kw):
        err: BaseException | None = None
        for _ in range(settings.max_retries + 1):
            try:
                return fn(*args, **kw), None
            except (KeyboardInterrupt, SystemExit):
                raise
            except Exception as e:  # noqa: BLE001 — retried, then reported per record
                err = e
        return None, err

    n_disc = len(pl.discover_jobs) + (sum(map(len, pl.fit_tasks)) if settings.discover else 0)
    with _progress(sum(map(len, pl.fit_tasks)) + n_disc, progress) as bar:
        tid = bar.add_task("fleet fits", total=sum(map(len, pl.fit_tasks)))
        did = bar.add_task("discovery", total=n_disc, visible=settings.discover)
        disc = list(pl.discover_jobs)
        for task in pl.fit_tasks:
            payload = [j.to_dict() for j in task]
            out, err = attempt(fit_task, payload, spec_data, settings, fingerprint=fp,
                               engine="local", inject=inject, attempts_dir=attempts_dir)
            if err is not None:
                out = [failure_entry(j, err, stage="task", fingerprint=fp,
                                     attempts=settings.max_retries + 1) for j in payload]
            for job, entry in zip(task, out, strict=True):
                writer(entry)
                if settings.discover and entry["status"] == "ok":
                    disc.append((job, entry))
                elif settings.discover:
                    bar.advance(did)
            bar.advance(tid, len(task))
        for job, entry in disc:
            res, err = attempt(discover_task, job.to_dict(), spec_data, settings, entry,
                               fingerprint=fp, engine="local", inject=inject,
                               attempts_dir=attempts_dir)
            if err is not None:
                res = failure_entry(job.to_dict(), err, stage="discover", fingerprint=fp,
                                    kind="discover", attempts=settings.max_retries + 1)
            writer(res)
            bar.advance(did)

