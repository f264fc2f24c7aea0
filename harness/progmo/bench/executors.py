"""Throughput of the sweep executors (issue 16): one bundled sweep (double_pendulum, both
simulators) run on the local executor and on a Ray instance started on this machine, in the same
run; Ray's per-task overhead (latency of one round trip, and the cost per task of a batch of no-op
tasks); and, on paper from those figures, what a sweep of 10^5 checks costs on N machines."""

from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path
from typing import Any

from .common import log


def _sweep(spec: Path, out: Path, executor: str) -> tuple[float, int, list[float]]:
    from .. import sweep

    t0 = time.perf_counter()
    rc = sweep.main(["--spec", str(spec), "-o", str(out), "--executor", executor, "--fresh", "--no-plots"])
    wall = time.perf_counter() - t0
    if rc != 0:
        raise RuntimeError(f"the {executor} sweep ended with exit code {rc}")
    recs = [json.loads(x) for x in (out / "results.jsonl").read_text().splitlines()]
    return wall, len(recs), [r["result"]["wall_seconds"] for r in recs]


def run(out: Path, samples: int = 8, rounds: int = 200) -> dict[str, Any]:
    from .. import data
    from ..executors import ExecutorError, ray_init
    from ..parallel import default_jobs

    spec_text = (data.references() / "sweeps" / "double_pendulum.toml").read_text()
    spec_text = "\n".join(f"samples = {samples}" if ln.startswith("samples") else ln for ln in spec_text.splitlines())
    res: dict[str, Any] = {"samples": samples, "cores": default_jobs()}
    with tempfile.TemporaryDirectory(prefix="progmo-bench-sweep-") as d:
        spec = Path(d) / "double_pendulum.toml"
        spec.write_text(spec_text)
        log(f"[executors] local sweep: {samples} samples x 2 simulators")
        wall, n, per = _sweep(spec, out / "sweep_local", "local")
        res["local"] = {"checks": n, "wall_s": wall, "checks_per_s": n / wall,
                        "median_check_s": sorted(per)[len(per) // 2]}
        t0 = time.perf_counter()
        try:
            ray = ray_init(None)
        except ExecutorError as e:
            res["ray"] = {"skipped": str(e)}
            return res
        startup = time.perf_counter() - t0
        try:
            @ray.remote
            def noop(x: int) -> int:
                return x

            ray.get([noop.remote(i) for i in range(20)])  # warm the workers
            t0 = time.perf_counter()
            for i in range(min(rounds, 100)):
                ray.get(noop.remote(i))
            latency = (time.perf_counter() - t0) / min(rounds, 100)
            t0 = time.perf_counter()
            ray.get([noop.remote(i) for i in range(rounds)])
            batch = (time.perf_counter() - t0) / rounds
            log(f"[executors] Ray sweep: {samples} samples x 2 simulators")
            wall, n, per = _sweep(spec, out / "sweep_ray", "ray")
            res["ray"] = {"checks": n, "wall_s": wall, "checks_per_s": n / wall,
                          "median_check_s": sorted(per)[len(per) // 2], "startup_s": startup,
                          "task_latency_s": latency, "task_batch_cost_s": batch}
        finally:
            ray.shutdown()
    return res


def estimate(res: dict[str, Any], checks: int = 100_000) -> list[dict[str, Any]]:
    """On paper: wall time of `checks` checks on N machines of c cores, from the measured median
    check time and Ray's per-task cost (tasks spread evenly, the driver not the bottleneck)."""
    if "median_check_s" not in res.get("ray", {}):
        return []
    t_check = res["local"]["median_check_s"]
    o = res["ray"]["task_batch_cost_s"]
    rows = []
    for cores in (res["cores"], 32):
        for machines in (1, 10, 100):
            rows.append({"machines": machines, "cores": cores,
                         "hours": checks * (t_check + o) / (machines * cores) / 3600})
    return rows


def html(res: dict[str, Any]) -> tuple[str, list[str]]:
    from . import page

    lo = res["local"]
    rows = [["local (process pool)", str(lo["checks"]), f"{lo['wall_s']:.2f}", f"{lo['checks_per_s']:.2f}",
             f"{lo['median_check_s'] * 1e3:.0f}", "", ""]]
    summary = [f"executors: local {lo['checks_per_s']:.2f} checks/s on {res['cores']} cores "
               f"(median check {lo['median_check_s'] * 1e3:.0f} ms)"]
    ray = res.get("ray", {})
    if "skipped" in ray:
        text = f"<p>Ray part skipped: {ray['skipped']}</p>"
        summary.append(f"executors: Ray skipped ({ray['skipped']})")
    else:
        rows.append(["Ray (instance on this machine)", str(ray["checks"]), f"{ray['wall_s']:.2f}",
                     f"{ray['checks_per_s']:.2f}", f"{ray['median_check_s'] * 1e3:.0f}",
                     f"{ray['task_latency_s'] * 1e6:.0f}", f"{ray['task_batch_cost_s'] * 1e6:.0f}"])
        summary.append(f"executors: Ray {ray['checks_per_s']:.2f} checks/s (the instance already running; starting it "
                       f"took {ray['startup_s']:.1f} s); "
                       f"task round trip {ray['task_latency_s'] * 1e6:.0f} us, {ray['task_batch_cost_s'] * 1e6:.0f} us "
                       "per task in a batch")
        text = ""
    text = page.table(["executor", "checks", "wall (s)", "checks/s", "median check (ms)", "Ray round trip (us)",
                       "Ray cost per batched task (us)"], rows) + text
    est = estimate(res)
    if est:
        text += ("<p>On paper, 10<sup>5</sup> checks of this kind (median check time of the local run plus Ray's "
                 "per-task cost, spread evenly; data transfer and the driver's bookkeeping not modelled):</p>"
                 + page.table(["machines", "cores each", "hours"],
                              [[str(r["machines"]), str(r["cores"]), f"{r['hours']:.2g}"] for r in est]))
        summary.append("executors: 1e5 checks on paper: " + ", ".join(
            f"{r['machines']} x {r['cores']} cores {r['hours']:.2g} h" for r in est if r["cores"] == 32))
    return text, summary


if __name__ == "__main__":  # pragma: no cover - `progmo bench --only executors` is the entry
    r = run(Path(os.environ.get("OUT", "out/bench")))
    print(json.dumps(r, indent=1))
