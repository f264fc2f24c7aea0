"""Where checks run: ``local`` (this machine's cores, :func:`progmo.parallel.run_all`) or ``ray``
(a Ray cluster through Ray's task API; ``--address`` or ``RAY_ADDRESS``, else a Ray instance
started on this machine for the run).

Both take the same :class:`~progmo.parallel.Task` list and yield ``(task, CheckResult)`` as checks
finish; results do not depend on the executor (a check is a pure function of its scene file,
simulator and options), so callers aggregate them in task order. Both run the checks of one scene
file together, sharing its reference solve (``parallel.run_group``). A Ray task (one scene file's
checks) is idempotent and
retried when its worker dies (``max_retries``); the scene travels with the task as text, so
workers on other machines need only progmo installed (files a scene refers to must exist at the
same paths).
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from .parallel import Task, by_scene, error_result, last_line, run_all, run_group, runner_spec
from .results import CheckResult

EXECUTORS = ("local", "ray")
#: retries of a Ray task whose worker died (a crash, an OOM kill, a lost node)
RAY_RETRIES = 3


class ExecutorError(RuntimeError):
    """The executor cannot start (Ray not installed, no cluster at the address)."""


def run(tasks: list[Task], options: Any, *, executor: str = "local", jobs: int = 1,
        address: str | None = None) -> Iterator[tuple[Task, CheckResult]]:
    """Yield ``(task, result)`` for every task, in completion order."""
    if executor == "local":
        yield from run_all(tasks, options, jobs)
    elif executor == "ray":
        yield from _ray(tasks, options, address)
    else:
        raise ExecutorError(f"unknown executor {executor!r} (one of {', '.join(EXECUTORS)})")


def _check_remote(path: str, text: str, simulators: list[str], options: dict[str, Any], spec: str) -> list[dict]:
    """Body of the Ray task: the checks of one scene file in its simulators, in order, sharing the
    reference solve (``parallel.run_group``); the scene file from its path when this worker sees
    the same file, else from the text shipped with the task."""
    from .checks import CheckOptions

    opts = CheckOptions(**options)
    p = Path(path)
    try:
        same = p.is_file() and p.read_text() == text
    except OSError:
        same = False

    def group(at: str) -> list[dict]:
        tasks = [(i, Task(at, p.stem, sim)) for i, sim in enumerate(simulators)]
        return [r.to_json() for _, r in run_group(tasks, opts, spec)]
    if same:
        return group(path)
    with tempfile.TemporaryDirectory(prefix="progmo-ray-") as d:
        local = Path(d) / p.name
        local.write_text(text)
        return group(str(local))


def ray_init(address: str | None) -> Any:
    """Connect to (or start) Ray; raises ExecutorError with the reason."""
    try:
        import ray
    except ImportError as e:
        raise ExecutorError(f"the ray executor needs Ray (pip install 'progmo[ray]'): {e}") from None
    if not ray.is_initialized():
        addr = address or os.environ.get("RAY_ADDRESS") or None
        kw: dict[str, Any] = {} if addr else {"num_cpus": os.cpu_count() or 1}
        try:
            ray.init(address=addr, include_dashboard=False, log_to_driver=False, configure_logging=False, **kw)
        except Exception as e:  # noqa: BLE001 - Ray raises several kinds; report the reason
            raise ExecutorError(f"cannot start or reach Ray at {addr or 'a new local instance'}: "
                                f"{last_line(e)}") from None
    return ray


def _ray(tasks: list[Task], options: Any, address: str | None) -> Iterator[tuple[Task, CheckResult]]:
    ray = ray_init(address)
    remote = ray.remote(max_retries=RAY_RETRIES, retry_exceptions=False)(_check_remote)
    opts = dataclasses.asdict(options)
    spec = runner_spec()
    pending: dict[Any, list[Task]] = {}
    for g in by_scene(tasks):
        group = [t for _, t in g]
        try:
            text = Path(group[0].scene_path).read_text()
        except OSError as e:
            for t in group:
                yield t, error_result(t, f"cannot read the scene file: {e}")
            continue
        pending[remote.remote(group[0].scene_path, text, [t.simulator for t in group], opts, spec)] = group
    try:
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                group = pending.pop(ref)
                t0 = time.perf_counter()
                try:
                    rs = [CheckResult.from_json(x) for x in ray.get(ref)]
                except Exception as e:  # noqa: BLE001 - retries exhausted, or the cluster went away
                    rs = [error_result(t, f"the Ray task failed after {RAY_RETRIES} retries: {last_line(e)}",
                                       time.perf_counter() - t0) for t in group]
                yield from zip(group, rs)
    finally:
        for ref in pending:  # interrupted: do not leave work queued on the cluster
            try:
                ray.cancel(ref, force=True)
            except Exception:  # noqa: BLE001
                pass
