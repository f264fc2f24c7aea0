"""The nightly check timed (issue 31's target: the whole catalog in <= 60 s wall on 2 cores).

One `progmo check` (the command `bash harness/nightly.sh` runs after its set-up) of every bundled
scene in every installed simulator, as a child process (`python -m progmo.cli check`) with the
default jobs (one per core): its wall time from start to exit, the number of checks, their
statuses and the check-seconds per simulator and per scene (from its results.json), so a missed
target says where the time goes. Its report and results stay in OUT/nightly/. `--smoke` checks one
scene only and says so (the target is then not measured).
"""

from __future__ import annotations

import collections
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from .common import log


def run(out: Path, scenes: list[str] | None = None) -> dict[str, Any]:
    """Run and time the check; raises RuntimeError when it cannot run or writes no results."""
    from ..parallel import default_jobs

    d = out / "nightly"
    cmd = [sys.executable, "-m", "progmo.cli", "check", "--out", str(d), "--no-plots", *(scenes or [])]
    log(f"[nightly] {' '.join(cmd[1:])}")
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    try:
        results = json.loads((d / "results.json").read_text())
    except (OSError, ValueError) as e:
        raise RuntimeError(f"progmo check wrote no results (exit {r.returncode}): {e}; "
                           f"stderr: {r.stderr.strip()[-500:]}") from None
    by_sim: dict[str, float] = collections.defaultdict(float)
    by_scene: dict[str, float] = collections.defaultdict(float)
    for x in results:
        by_sim[x["simulator"]] += x.get("wall_seconds") or 0.0
        by_scene[x["scene"]] += x.get("wall_seconds") or 0.0
    return dict(wall_s=wall, exit=r.returncode, checks=len(results), jobs=default_jobs(),
                cores=os.cpu_count() or 1, whole_catalog=not scenes,
                simulators=sorted(by_sim), statuses=dict(collections.Counter(x["status"] for x in results)),
                check_seconds_by_simulator=dict(by_sim),
                slowest_scenes=sorted(by_scene.items(), key=lambda kv: -kv[1])[:6],
                command="progmo check --no-plots" + "".join(f" {s}" for s in scenes or []))


def lines(res: dict[str, Any]) -> list[str]:
    """Key-number lines: the wall time and where the check-seconds went."""
    sims = ", ".join(f"{k} {v:.0f} s" for k, v in sorted(res["check_seconds_by_simulator"].items()))
    slow = ", ".join(f"{k} {v:.0f} s" for k, v in res["slowest_scenes"])
    return [f"nightly `{res['command']}`: {res['wall_s']:.0f} s wall, {res['checks']} checks "
            f"({', '.join(f'{k} {v}' for k, v in sorted(res['statuses'].items()))}), exit {res['exit']}, "
            f"{res['jobs']} jobs on {res['cores']} cores",
            f"nightly check-seconds by simulator: {sims}; slowest scenes (all simulators): {slow}"]
