"""Work-precision of progmo's solver: formulation x integrator x tolerance sweep.

Error = max-norm of the final state (q, v) at t1 minus a high-accuracy reference computed with a
*different* integrator: radau5 runs are measured against dop853 at rtol = atol = 1e-14; dop853 and
dopri5 runs against radau5 at rtol = atol = 1e-14 (1e-13 if that fails). Both references use the
null-space formulation and the scene's drift control; their mutual difference is reported as the
floor below which errors are not resolved. No closed form exists for these scenes (the free
coordinates obey nonlinear ODEs).

Cost = process CPU time around `scene.solve` (median of `repeats`), with output only at t0 and t1
so that sampling does not add evaluations; and the integrator's RHS evaluation count.
atol = rtol in the sweep (states are O(1)).
"""

from __future__ import annotations

from typing import Any

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .common import FORMULATIONS, INTEGRATORS, Provenance, cpu_time, log, log_plot, save_figure, write_csv

REF_TOL = 1e-14


@dataclass
class Reference:
    state: dict  # integrator -> final (q, v) concatenated
    tol: dict  # integrator -> rtol used
    cpu: dict
    floor: float  # max |dop853 ref - radau5 ref|

    def against(self, integrator: str) -> tuple[str, np.ndarray]:
        """The reference a run of `integrator` is measured against (never its own integrator)."""
        other = "dop853" if integrator == "radau5" else "radau5"
        return other, self.state[other]


def final_state(r) -> np.ndarray:
    return np.concatenate((r.q[-1], r.v[-1]))


def reference(scene) -> Reference:
    state, tols, cpu = {}, {}, {}
    for integ in ("dop853", "radau5"):
        for tol in (REF_TOL, 1e-13):
            dt, r = cpu_time(lambda: scene.solve(rtol=tol, atol=tol, integrator=integ,
                                                 output_dt=scene.t1 - scene.t0), 1)
            if r.success and abs(r.t[-1] - scene.t1) < 1e-12:
                state[integ], tols[integ], cpu[integ] = final_state(r), tol, dt
                break
        else:
            raise RuntimeError(f"{scene.name}: reference with {integ} failed ({r.code})")
    floor = float(np.abs(state["dop853"] - state["radau5"]).max())
    return Reference(state, tols, cpu, floor)


def sweep(scene, ref: Reference, tols, formulations=FORMULATIONS, integrators=INTEGRATORS,
          repeats: int = 3, drift: str | None = None) -> list[dict]:
    """drift None: the scene's drift control (projection in the bundled scenes)."""
    rows = []
    for form in formulations:
        for integ in integrators:
            ref_name, ref_state = ref.against(integ)
            for tol in tols:
                dt, r = cpu_time(lambda: scene.solve(rtol=tol, atol=tol, integrator=integ,
                                                     formulation=form, drift=drift,
                                                     output_dt=scene.t1 - scene.t0), repeats)
                ok = r.success and abs(r.t[-1] - scene.t1) < 1e-12
                err = float(np.abs(final_state(r) - ref_state).max()) if ok else float("nan")
                st = r.stats
                rows.append(dict(scene=scene.name, formulation=form, integrator=integ, rtol=tol,
                                 atol=tol, code=r.code, error=err, cpu_s=dt,
                                 rhs_evals=st["integrator"]["rhs_evals"],
                                 steps=st["integrator"]["steps"],
                                 rejected=st["integrator"]["rejected"],
                                 factorizations=st["factorizations"], reference=ref_name,
                                 drift=r.settings["drift"]["kind"]))
    return rows


def residual_run(scene, formulation="null_space", integrator="dop853", tol=1e-8):
    """One run sampled finely: the programme residual |g| (max over rows) against time."""
    r = scene.solve(rtol=tol, atol=tol, integrator=integrator, formulation=formulation)
    res = np.abs(r.residuals).max(axis=1) if r.residuals.size else np.zeros(len(r.t))
    return r.t, res, dict(formulation=formulation, integrator=integrator, rtol=tol,
                             drift=r.settings["drift"], code=r.code,
                             max_residual=float(np.max(r.max_residuals, initial=0.0)))


COLORS = {"dop853": "tab:blue", "dopri5": "tab:green", "radau5": "tab:red",
          "scipy DOP853": "black", "scipy Radau": "tab:purple"}
STYLES = {"null_space": "-", "null_space_stacked": (0, (5, 1, 1, 1)), "kkt": "--", "range_space": ":", "udwadia_kalaba": "-.",
          "articulated_body": (0, (1, 1))}
MARKERS = {"null_space": "o", "null_space_stacked": "D", "kkt": "s", "range_space": "^", "udwadia_kalaba": "x",
           "articulated_body": "v"}


def plot(scene_name: str, rows: list[dict], ref: Reference, res_run, out: Path, prov: Provenance) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(16, 5.2))
    for xkey, ax, label in (("cpu_s", axes[0], "CPU time per solve (s, median)"),
                            ("rhs_evals", axes[1], "RHS evaluations")):
        for form in FORMULATIONS:
            for integ in INTEGRATORS:
                pts = [(r[xkey], r["error"]) for r in rows
                       if r["formulation"] == form and r["integrator"] == integ and np.isfinite(r["error"])]
                if not pts:
                    continue
                x, y = zip(*pts)
                log_plot(ax, x, y, ls=STYLES[form], marker=MARKERS[form],
                         color=COLORS[integ], ms=4, lw=1, label=f"{integ} {form}")
        ax.axhline(ref.floor, color="gray", lw=0.8, ls=":")
        ax.set_xlabel(label)
        ax.set_ylabel("final-state error max|(q,v) - ref|")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_title(f"{scene_name}: error vs CPU time")
    axes[1].set_title("error vs RHS evaluations (gray: reference floor)")
    axes[1].legend(fontsize=6, ncol=2)
    t, res, info = res_run
    log_plot(axes[2], t, res, logx=False)
    if np.any(np.asarray(res) == 0):
        axes[2].legend(fontsize=7)
    axes[2].set_title(f"programme residual max|g|: {info['integrator']} {info['formulation']} "
                      f"rtol {info['rtol']:.0e}", fontsize=9)
    axes[2].set_xlabel("t (s)")
    axes[2].grid(True, which="both", alpha=0.3)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    return [save_figure(fig, out / f"workprecision_{scene_name}.png", prov)]


HEADER = ["scene", "formulation", "integrator", "drift", "rtol", "atol", "code", "error", "cpu_s",
          "rhs_evals", "steps", "rejected", "factorizations", "reference"]


def run(scenes, tols, out: Path, prov: Provenance, repeats: int = 3) -> dict:
    """Sweep every scene; write CSV and PNG; return {scene: {rows, reference, residual, files}}."""
    results: dict[str, dict[str, Any]] = {}
    all_rows = []
    for scene in scenes:
        log(f"[workprecision] {scene.name}: references")
        try:
            ref = reference(scene)
        except RuntimeError as e:  # a scene whose reference fails is reported, not fatal
            results[scene.name] = dict(skipped=str(e))
            continue
        log(f"[workprecision] {scene.name}: sweep over {len(tols)} tolerances")
        rows = sweep(scene, ref, tols, repeats=repeats)
        rr = residual_run(scene)
        files = plot(scene.name, rows, ref, rr, out, prov)
        write_csv(out / f"residual_{scene.name}.csv", prov, ["t", "max_abs_residual"], zip(rr[0], rr[1]))
        results[scene.name] = dict(rows=rows, reference=ref, residual=rr, files=files)
        all_rows += rows
    write_csv(out / "workprecision.csv", prov, HEADER, ([r[h] for h in HEADER] for r in all_rows))
    return results
