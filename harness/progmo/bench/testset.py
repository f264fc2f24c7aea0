"""IVP Test Set: the car axis (references/testset/caraxis.toml) against its published reference.

Reference: the test set's quad-precision solution at t = 3 (R/ex_reference.R "caraxis", 21 digits),
shipped in the package as `references/testset/published/caraxis_R_gamd_quad_reference.csv` (a copy
of the test set's file; provenance in references/testset/README.md and published/caraxis.md). y = (xl, yl, xr, yr, xl', yl', xr', yr', lambda1,
lambda2) with lambda1 = progmo's multiplier of the programme row `road` and lambda2 that of the
system row `axle` (same sign and scale, README).

Accuracy = the test set's mixed significant digits mescd = -log10(max_i |y_i - ref_i| /
(atol/rtol + |ref_i|)) with atol = rtol (ratio 1), on y(1:8) (states) and y(1:10) (with the
multipliers). Cost = process CPU time of `scene.solve` (median of repeats, output at t1 only) and
RHS evaluations. The rigid slider crank (references/testset/crank_rigid.toml) is checked against
its closed form in tests/testset.rs; the flexible crank's published values are not reproduced (its
elastic terms are not available), so it is not part of this sweep.
"""

from __future__ import annotations

from typing import Literal

import csv
from pathlib import Path

import numpy as np

from .. import data
from .common import Provenance, cpu_time, log, save_figure, write_csv

METHODS: tuple[Literal["dop853", "radau5"], ...] = ("dop853", "radau5")


def reference_csv() -> Path:
    return data.testset_dir() / "published" / "caraxis_R_gamd_quad_reference.csv"


def load_reference() -> np.ndarray:
    path = reference_csv()
    if not path.exists():
        raise FileNotFoundError(f"caraxis reference not found at {path} (it ships with the package: a broken installation?)")
    with path.open() as f:
        rows = list(csv.DictReader(f))
    ref = np.array([float(r["value"]) for r in sorted(rows, key=lambda r: int(r["index"]))])
    if ref.shape != (10,):
        raise ValueError(f"{path}: expected 10 reference values, found {ref.shape[0]}")
    return ref


def mescd(y: np.ndarray, ref: np.ndarray, ratio: float = 1.0) -> float:
    e = float(np.max(np.abs(y - ref) / (ratio + np.abs(ref))))
    return float("inf") if e == 0.0 else -np.log10(e)


def caraxis_y(scene, r) -> np.ndarray:
    names = [row["name"] for row in scene.rows]
    road, axle = names.index("road"), names.index("axle")
    lam = r.lambda_[-1]
    return np.concatenate((r.q[-1], r.v[-1], [lam[road], lam[axle]]))


def run(out: Path, prov: Provenance, tols, repeats: int) -> dict:
    from .. import Scene

    ref = load_reference()
    scene = Scene(str(data.testset_dir() / "caraxis.toml"))
    rows = []
    for method in METHODS:
        for tol in tols:
            log(f"[testset] caraxis {method} rtol = atol = {tol:.0e}")
            dt, r = cpu_time(lambda: scene.solve(rtol=tol, atol=tol, integrator=method,
                                                 output_dt=scene.t1 - scene.t0), repeats)
            ok = r.success and abs(r.t[-1] - scene.t1) < 1e-12
            st = r.stats["integrator"]
            y = caraxis_y(scene, r) if ok else np.full(10, np.nan)
            rows.append(dict(problem="caraxis", method=method, rtol=tol, atol=tol, code=r.code,
                             mescd_states=mescd(y[:8], ref[:8]) if ok else float("nan"),
                             mescd_all=mescd(y, ref) if ok else float("nan"),
                             cpu_s=dt, rhs_evals=st["rhs_evals"], steps=st["steps"],
                             rejected=st["rejected"], jacobian_evals=st["jacobian_evals"]))
    header = ["problem", "method", "rtol", "atol", "code", "mescd_states", "mescd_all", "cpu_s",
              "rhs_evals", "steps", "rejected", "jacobian_evals"]
    write_csv(out / "testset.csv", prov, header, ([r[h] for h in header] for r in rows))
    save_figure(_plot(rows), out / "testset_caraxis.png", prov)
    return dict(rows=rows)


def _plot(rows):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8))
    for method, color in zip(METHODS, ("tab:blue", "tab:red")):
        pts = sorted((r["cpu_s"], r["rhs_evals"], r["mescd_all"]) for r in rows
                     if r["method"] == method and np.isfinite(r["mescd_all"]))
        if pts:
            cpu, rhs, scd = zip(*pts)
            axes[0].semilogx(cpu, scd, "-o", color=color, label=f"progmo {method}")
            axes[1].semilogx(rhs, scd, "-o", color=color, label=f"progmo {method}")
    axes[0].set_xlabel("CPU time per solve (s)")
    axes[1].set_xlabel("RHS evaluations")
    for ax in axes:
        ax.set_ylabel("mescd y(1:10) (q, v, lambda)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    axes[0].set_title("IVP Test Set car axis, t = 3: digits vs CPU time", fontsize=10)
    axes[1].set_title("digits vs RHS evaluations (Radau5 counts Jacobian-free RHS only)", fontsize=9)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    return fig


def best_at(rows, method: str, digits: float):
    """The cheapest run of `method` reaching `digits` (mescd over all 10 components)."""
    ok = [r for r in rows if r["method"] == method and np.isfinite(r["mescd_all"]) and r["mescd_all"] >= digits]
    return min(ok, key=lambda r: r["cpu_s"], default=None)
