"""A fake ``run_check`` for the orchestration and report tests: no simulator, instant, and a
verdict chosen per (scene, simulator) by the JSON plan in $FAKE_CHECKS_PLAN (read at call time,
so it also reaches spawned worker processes). Plan values: "pass", "fail", "declared" (a not_checked the scene
declares), "not_checked" (undeclared), "error",
"raise", "interrupt", "die", "sleep:SECONDS", "regress" (a pass whose residual is 20x the usual),
"solve" (says "solving" on stderr, then the first Scene.solve of the process, a long one: the
interruption tests send Ctrl-C into it), default "pass"."""

from __future__ import annotations

import json
import math
import os
import pathlib

from progmo.results import Budget, CheckResult, Series, judge

PLAN_ENV = "FAKE_CHECKS_PLAN"


def make_result(scene: str, simulator: str, kind: str = "pass") -> CheckResult:
    if kind == "declared":
        return CheckResult(scene, simulator, "not_checked", expected=True,
                           reason="the simulator cannot represent a <knife edge> & co (declared in the scene)")
    if kind == "not_checked":
        return CheckResult(scene, simulator, "not_checked", reason="MJCF export: system constraints (`c`)")
    if kind == "error":
        return CheckResult(scene, simulator, "error", reason="pinocchio not importable: ModuleNotFoundError")
    scale = {"pass": 1.0, "fail": 1e4, "regress": 20.0}[kind]
    t = [0.01 * i for i in range(501)]
    res = [scale * 1e-13 * (1 + i) * (1 + 0.5 * math.sin(x)) for i, x in enumerate(t)]
    dev = [scale * 2e-13 * (1 + i) for i in range(len(t))]
    r = CheckResult(
        scene,
        simulator,
        "pass",
        metrics={
            "replay_residual": max(res),
            "replay_deviation": max(dev),
            "parity_mass": 2e-15,
            "replay_growth_rate": 0.3,
        },
        budgets=[
            Budget("replay_residual", 1e-9, "RK4 at h = 1e-3 with per-stage u: 4th order, measured 3e-12"),
            Budget("replay_deviation", 1e-8, "open-loop drift grows like the growth rate"),
            Budget("parity_mass", 1e-12, "mass matrices agree to round-off"),
        ],
        series=[
            Series("programme residual", t, res),
            Series("deviation |q - q_solver|", t, dev, "rad"),
            Series("u[0]", t, [math.sin(x) for x in t], "N m"),
            Series("u[1]", t, [0.5 * math.cos(2 * x) for x in t], "N m"),
        ],
        notes=["step 1e-3 (scene replay_step)"],
        wall_seconds=0.25,
    )
    return judge(r, {"replay_residual": 1.5} if kind == "fail" else None)


def run_check(scene_path, simulator, options=None):
    plan = json.loads(os.environ.get(PLAN_ENV, "{}"))
    scene = pathlib.Path(scene_path).stem
    kind = plan.get(f"{scene}/{simulator}", plan.get(scene, "pass"))
    if kind == "raise":
        raise RuntimeError(f"simulated crash in {scene} <{simulator}>")
    if kind == "interrupt":
        raise KeyboardInterrupt
    if kind == "die":  # the worker process dies (segfault, out of memory)
        os._exit(3)
    if kind == "solve":
        import sys

        import progmo

        scene = progmo.load("double_pendulum")
        print("solving", file=sys.stderr, flush=True)
        scene.solve(t1=1e6, output_dt=1.0)
        kind = "pass"
    if kind.startswith("sleep"):  # "sleep:5": a slow check (manual interruption tests)
        import time

        time.sleep(float(kind.partition(":")[2] or 5))
        kind = "pass"
    return make_result(scene, simulator, kind)
