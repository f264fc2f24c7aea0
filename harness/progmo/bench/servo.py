"""Servo-constraints (issue 17, item 5): the overhead crane at the servo and the ideal realization.

The same programme (the load's path) is solved twice: with `[[actuators]]` (trolley and hoist only:
the servo realization, a rank-1 decoupling reduced by one structure-algorithm step, index 5) and
without them (the ideal realization of the paper, u in the row space of B: another motion, with a
force on the swing joint). Accuracy of the servo runs: max |q - q_flat| over the output samples
against the crane's flat inverse (closed form, independent of the solver: the rope lies along
g - a_L). The ideal motion has no closed form: its runs are compared with a DOP853 run at
rtol = atol = 1e-13 of the same scene (the floor shown is that reference against a radau5 run at
1e-13). Cost: process CPU time of `scene.solve` (output every 0.1 s), RHS evaluations, and CPU time
per RHS: the servo/ideal ratio of the latter is the cost of the index reduction (the direct route
for the kept row, nested dual numbers of depth 2 over the combination z = p_x'' - c p_z'' for its
two further derivatives, plus the hidden-constraint projection).
The servo runs' error hardly depends on the tolerance: the crane is flat, its 6 hidden constraints
fix the whole state, and the projection after every step puts the state on the flat solution to
the projection tolerance (1e-12); the tolerance buys only step count.
Measured (`progmo bench --quick --only servo --out /tmp/servo6`, 2026-11-28, commit 450a6da): servo
5.1e-14 .. 7.0e-13 in 5.4 .. 8.1 ms CPU (140 .. 275 RHS, 30 .. 39 us CPU per RHS); ideal 1.5 .. 2.1 us
per RHS: the index reduction costs 18-19x per RHS in four runs (1164x with nested duals of depth 6 at
commit 2cfd5db). The servo error is the projection tolerance's (simplified Newton stops within
1e-12; full Newton overshot to 1e-16)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .common import Provenance, cpu_time, log, save_figure, scene_path, write_csv

OUTPUT_DT = 0.1


def flat_q(params: dict[str, float], t: np.ndarray) -> np.ndarray:
    """The crane's flat inverse (x, th, l) at times t (references/scenes/overhead_crane.toml)."""
    d, h, w, g, l0 = (params[k] for k in ("D", "H", "w", "g", "L0"))
    c = np.cos(w * t)
    ax, az = d * w * w * c, h * w * w * c
    xl, zl = d * (1 - c), -l0 + h * (1 - c)
    x = xl - zl * ax / (g + az)
    th = np.arctan2(ax, g + az)
    rope = -zl * np.hypot(ax, g + az) / (g + az)
    return np.stack([x, th, rope - l0], axis=1)


def ideal_scene_file(out: Path) -> Path:
    """overhead_crane without its [[actuators]] tables (the ideal realization), written to out."""
    text = scene_path("overhead_crane").read_text()
    lines, keep, skip = text.splitlines(), [], False
    for line in lines:
        if line.strip() == "[[actuators]]":
            skip = True
            continue
        if skip and (line.startswith("[") or line.startswith("#")):
            skip = False
        if not skip:
            keep.append(line)
    body = "\n".join(keep).replace('name = "overhead_crane"', 'name = "overhead_crane_ideal"', 1)
    path = out / "overhead_crane_ideal.toml"
    path.write_text(body + "\n")
    return path


def run(out: Path, prov: Provenance, tols, repeats: int) -> dict:
    from .. import Scene

    servo = Scene(str(scene_path("overhead_crane")))
    ideal = Scene(str(ideal_scene_file(out)))
    if not servo.actuators or ideal.actuators:
        raise RuntimeError("overhead_crane: expected actuators on the servo scene and none on the ideal copy")
    params = dict(servo.parameters)
    log("[servo] ideal realization: references at rtol = atol = 1e-13 (dop853, radau5)")
    ref = ideal.solve(rtol=1e-13, atol=1e-13, integrator="dop853", output_dt=OUTPUT_DT)
    ref2 = ideal.solve(rtol=1e-13, atol=1e-13, integrator="radau5", output_dt=OUTPUT_DT)
    if not (ref.success and ref2.success):
        raise RuntimeError(f"overhead_crane_ideal reference runs failed: {ref.code}, {ref2.code}")
    floor = float(np.max(np.abs(ref.q - ref2.q)))
    rows = []
    for label, scene in (("servo", servo), ("ideal", ideal)):
        for tol in tols:
            log(f"[servo] overhead_crane {label} dop853 rtol = atol = {tol:.0e}")
            dt, r = cpu_time(lambda: scene.solve(rtol=tol, atol=tol, integrator="dop853", output_dt=OUTPUT_DT),
                             repeats, budget_s=5.0)
            err = float("nan")
            if r.success:
                target = flat_q(params, r.t) if label == "servo" else ref.q
                err = float(np.max(np.abs(r.q - target))) if target.shape == r.q.shape else float("nan")
            st = r.stats["integrator"]
            rows.append(dict(realization=label, rtol=tol, code=r.code, error=err, cpu_s=dt,
                             rhs_evals=st["rhs_evals"], steps=st["steps"],
                             us_per_rhs=dt / max(st["rhs_evals"], 1) * 1e6))
    header = ["realization", "rtol", "code", "error", "cpu_s", "rhs_evals", "steps", "us_per_rhs"]
    write_csv(out / "servo.csv", prov, header, ([r[h] for h in header] for r in rows))
    save_figure(_plot(rows, floor), out / "servo_crane.png", prov)
    return dict(rows=rows, floor=floor, reduction_cost=_ratio(rows))


def _ratio(rows) -> float:
    """Median over tolerances of (CPU per RHS, servo) / (CPU per RHS, ideal)."""
    by = {(r["realization"], r["rtol"]): r["us_per_rhs"] for r in rows}
    rs = [by[("servo", t)] / by[("ideal", t)] for (k, t) in by if k == "servo" and ("ideal", t) in by]
    return float(np.median(rs)) if rs else math.nan


def lines(res: dict) -> list[str]:
    out = []
    for label in ("servo", "ideal"):
        sel = [r for r in res["rows"] if r["realization"] == label and np.isfinite(r["error"])]
        best = min((r for r in sel if r["error"] < 1e-8), key=lambda r: r["cpu_s"], default=None)
        if best:
            out.append(f"servo overhead_crane {label}: cheapest run with error < 1e-8: rtol {best['rtol']:.0e}, "
                       f"error {best['error']:.1e} in {best['cpu_s'] * 1e3:.0f} ms CPU, {best['rhs_evals']} RHS "
                       f"({best['us_per_rhs']:.0f} us per RHS)")
        else:
            out.append(f"servo overhead_crane {label}: no run reached error < 1e-8")
    out.append(f"servo overhead_crane: cost of the index reduction (CPU per RHS, servo / ideal, median over "
               f"tolerances) {res['reduction_cost']:.0f}x; ideal reference floor {res['floor']:.1e}")
    return out


def _plot(rows, floor):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8))
    for label, color in (("servo", "tab:red"), ("ideal", "tab:blue")):
        pts = sorted((r["cpu_s"], r["rhs_evals"], r["error"]) for r in rows
                     if r["realization"] == label and np.isfinite(r["error"]) and r["error"] > 0)
        if pts:
            cpu, rhs, err = zip(*pts)
            axes[0].loglog(cpu, err, "-o", color=color, label=f"{label} (dop853)")
            axes[1].loglog(rhs, err, "-o", color=color, label=f"{label} (dop853)")
    for ax in axes:
        ax.axhline(floor, color="grey", ls=":", lw=1, label="ideal reference floor")
        ax.set_ylabel("max |q - q_ref| over samples")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    axes[0].set_xlabel("CPU time per solve (s)")
    axes[1].set_xlabel("RHS evaluations")
    axes[0].set_title("overhead crane: servo (flat inverse) vs ideal (tight run)", fontsize=10)
    axes[1].set_title("error vs RHS evaluations", fontsize=10)
    fig.tight_layout()
    return fig
