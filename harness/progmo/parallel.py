"""Runs (scene, simulator) checks on the local cores and turns anything that escapes a check into
an ``error`` result, so one broken check never stops the run.

The check function is named by a spec ``"module:function"`` (default
``progmo.checks:run_check``, overridable with the environment variable
``PROGMO_CHECK_RUNNER``) and looked up in the worker at call time: a test can substitute a fake
either by monkeypatching ``progmo.checks.run_check`` and running in-process (``jobs=1``) or
by naming a fake module in the spec (works with the process pool).
"""

from __future__ import annotations

import importlib
import multiprocessing
import os
import time
import traceback
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass

from .results import STATUSES, CheckResult

DEFAULT_RUNNER = "progmo.checks:run_check"
RUNNER_ENV = "PROGMO_CHECK_RUNNER"


@dataclass(frozen=True)
class Task:
    """One check to run: the scene file, its name (for error results) and the simulator."""

    scene_path: str
    scene: str
    simulator: str


def runner_spec() -> str:
    return os.environ.get(RUNNER_ENV) or DEFAULT_RUNNER


def resolve(spec: str) -> Callable:
    module, _, attr = spec.partition(":")
    return getattr(importlib.import_module(module), attr or "run_check")


def last_line(exc: BaseException) -> str:
    """The last line of the exception's traceback (``Type: message``)."""
    lines = traceback.format_exception_only(type(exc), exc)
    return (lines[-1] if lines else repr(exc)).strip()


def run_task(task: Task, options, spec: str) -> CheckResult:
    """Run one check; never raises (except KeyboardInterrupt/SystemExit)."""
    t0 = time.perf_counter()
    try:
        r = resolve(spec)(task.scene_path, task.simulator, options)
        if not isinstance(r, CheckResult):
            raise TypeError(f"run_check returned {type(r).__name__}, not CheckResult")
        if r.status not in STATUSES:
            raise ValueError(f"run_check returned unknown status {r.status!r}")
        if not r.wall_seconds:
            r.wall_seconds = time.perf_counter() - t0
        return r
    except Exception as e:  # noqa: BLE001 - every failure of a check is a result
        return error_result(task, f"check raised {last_line(e)}", time.perf_counter() - t0)


def error_result(task: Task, reason: str, wall: float = 0.0) -> CheckResult:
    return CheckResult(task.scene, task.simulator, "error", reason=reason, wall_seconds=wall)


def default_jobs() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover (not Linux)
        return max(1, os.cpu_count() or 1)


def run_all(tasks: list[Task], options, jobs: int) -> Iterator[tuple[Task, CheckResult]]:
    """Yield (task, result) as checks finish. ``jobs <= 1`` runs in this process (in order).
    Workers are started with ``spawn`` (no forked copies of simulator or Rust state); a worker
    that dies turns its check into an ``error`` result and the others continue."""
    spec = runner_spec()
    if jobs <= 1 or len(tasks) <= 1:
        for t in tasks:
            yield t, run_task(t, options, spec)
        return
    ctx = multiprocessing.get_context("spawn")
    broken: list[Task] = []
    pool = ProcessPoolExecutor(max_workers=min(jobs, len(tasks)), mp_context=ctx)
    try:
        pending: dict[Future, Task] = {pool.submit(run_task, t, options, spec): t for t in tasks}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for f in done:
                t = pending.pop(f)
                try:
                    r = f.result()
                except BrokenProcessPool:
                    broken.append(t)  # maybe not this check's fault: rerun it alone below
                    continue
                except Exception as e:  # noqa: BLE001
                    r = error_result(t, f"check raised {last_line(e)}")
                yield t, r
        pool.shutdown(wait=True)
    finally:
        # Interrupted (or the consumer stopped early): do not wait for running checks.
        pool.shutdown(wait=False, cancel_futures=True)
        _terminate(pool)
    # A dead worker breaks the whole pool; rerun each affected check alone to find the culprit.
    for t in broken:
        solo = ProcessPoolExecutor(max_workers=1, mp_context=ctx)
        try:
            r = solo.submit(run_task, t, options, spec).result()
        except BrokenProcessPool:
            r = error_result(t, "the worker process running this check died (crash or out of memory)")
        finally:
            solo.shutdown(wait=False, cancel_futures=True)
        yield t, r


def _terminate(pool: ProcessPoolExecutor) -> None:
    """Stop the pool's worker processes still running (after an interrupt); no-op otherwise."""
    procs = getattr(pool, "_processes", None) or {}
    for p in list(procs.values()):
        if p.is_alive():
            p.terminate()
