"""Runs (scene, simulator) checks on the local cores and turns anything that escapes a check into
an ``error`` result, so one broken check never stops the run.

The check function is named by a spec ``"module:function"`` (default
``progmo.checks:run_check``, overridable with the environment variable
``PROGMO_CHECK_RUNNER``) and looked up in the worker at call time: a test can substitute a fake
either by monkeypatching ``progmo.checks.run_check`` and running in-process (``jobs=1``) or
by naming a fake module in the spec (works with the process pool).
"""

from __future__ import annotations

import contextlib
import importlib
import multiprocessing
import os
import queue
import time
import traceback
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any

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


def by_scene(tasks: list[Task]) -> list[list[tuple[int, Task]]]:
    """The tasks grouped by scene file, in order of first appearance, each with its index."""
    groups: dict[str, list[tuple[int, Task]]] = {}
    for i, t in enumerate(tasks):
        groups.setdefault(t.scene_path, []).append((i, t))
    return list(groups.values())


def run_group(group: list[tuple[int, Task]], options, spec: str) -> Iterator[tuple[int, CheckResult]]:
    """The checks of one scene file in order, sharing their reference solves
    (:func:`progmo.checks.shared_solves`): its simulators solve the scene once."""
    from .checks import shared_solves

    with shared_solves():
        for i, t in group:
            yield i, run_task(t, options, spec)


#: the worker's channel back to the parent: each check's result as it finishes (set by _init_worker)
_RESULTS: Any = None


def _init_worker(results: Any) -> None:
    global _RESULTS
    _RESULTS = results


def _run_group_in_worker(group: list[tuple[int, Task]], options, spec: str) -> list[tuple[int, CheckResult]]:
    """Worker body: the group's results, each also sent to the parent as soon as it is known (a
    scene's first checks are reported, and kept if the run is interrupted, before its last ends)."""
    out = []
    for i, r in run_group(group, options, spec):
        if _RESULTS is not None:
            _RESULTS.put((i, r))
        out.append((i, r))
    return out


def run_all(tasks: list[Task], options, jobs: int) -> Iterator[tuple[Task, CheckResult]]:
    """Yield (task, result) as checks finish. The checks of one scene file run in one worker, in
    order, sharing their reference solves; scenes run in parallel over ``jobs`` workers (``jobs <=
    1``: in this process, in order). Workers are started with ``spawn`` (no forked copies of
    simulator or Rust state); a worker that dies turns its checks into ``error`` results (each
    rerun alone first) and the others continue."""
    spec = runner_spec()
    groups = by_scene(tasks)
    if jobs <= 1 or len(tasks) <= 1:
        for g in groups:
            for i, r in run_group(g, options, spec):
                yield tasks[i], r
        return
    ctx = multiprocessing.get_context("spawn")
    # The results channel is a manager's queue: each put is a whole message on the worker's own
    # connection. A plain multiprocessing.Queue shares one pipe and one lock among the workers, and
    # a worker dying while its feeder thread writes (os._exit, a crash, the OOM killer) leaves half
    # a message in the pipe, or the lock taken: the parent's read, or the other workers' writes,
    # then wait forever.
    manager = ctx.Manager()
    results = manager.Queue()
    broken: list[Task] = []
    seen: set[int] = set()

    def fresh(items) -> Iterator[tuple[Task, CheckResult]]:
        for i, r in items:
            if i not in seen:  # a result arrives by the queue and again with its group's future
                seen.add(i)
                yield tasks[i], r

    def drained() -> list[tuple[int, CheckResult]]:
        out = []
        with contextlib.suppress(queue.Empty):
            while True:
                out.append(results.get_nowait())
        return out

    pool = ProcessPoolExecutor(max_workers=min(jobs, len(groups)), mp_context=ctx,
                               initializer=_init_worker, initargs=(results,))
    try:
        pending: dict[Future, list[tuple[int, Task]]] = {
            pool.submit(_run_group_in_worker, g, options, spec): g for g in groups}
        while pending:
            done, _ = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            yield from fresh(drained())
            for f in done:
                g = pending.pop(f)
                try:
                    yield from fresh(f.result())
                except BrokenProcessPool:
                    yield from fresh(drained())
                    # maybe not these checks' fault: rerun each alone below
                    broken.extend(t for i, t in g if i not in seen)
                except Exception as e:  # noqa: BLE001
                    yield from fresh((i, error_result(t, f"check raised {last_line(e)}")) for i, t in g)
        pool.shutdown(wait=True)
    finally:
        # Interrupted (or the consumer stopped early): do not wait for running checks.
        pool.shutdown(wait=False, cancel_futures=True)
        _terminate(pool)
        manager.shutdown()
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
