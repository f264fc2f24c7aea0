"""Cost of one right-hand side (dv/dt and the control force u) against the number of links.

Chains of n links (common.chain_toml: tip-height and shoulder programme rows, 2 rows for n >= 3).
- progmo: `Scene.rhs_benchmark(N, formulation)` loops N evaluations in Rust (GIL released, wall
  clock): mass matrix, G + Q, the programme rows' jet (B, gamma) and the formulation's solve, then u.
  Best of `repeats` loops.
- Pinocchio: `pin.forwardDynamics(model, data, q, v, tau, J, gamma)` on the URDF export of the same
  chain with the SAME J and gamma (taken once from `scene.dynamics`, sign flipped to Pinocchio's
  J a + gamma = 0), plus u = J^T lambda, timed in a Python loop (`time.perf_counter`, best of
  `repeats`); and the full user pipeline (J, gamma written in numpy each call + forwardDynamics + u).
- The Python loop overhead (a no-op Python function with the same 7 arguments) is measured and
  reported; it is NOT subtracted.
All timings at the scene's initial state.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .common import Provenance, SceneDir, chain_toml, log, save_figure, write_csv

MARK = (7, 30)


def _best_loop(fn, iters: int, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(iters):
            fn()
        best = min(best, (time.perf_counter() - t) / iters)
    return float(best)


def python_overhead(iters: int = 20000, repeats: int = 5) -> float:
    """Seconds per iteration of a Python loop calling a no-op function with 7 arguments."""
    def noop(a, b, c, d, e, f, g):
        return None
    args = (1, 2, 3, 4, 5, 6, 7)
    return _best_loop(lambda: noop(*args), iters, repeats)


def measure(scene, formulations=("null_space", "kkt", "articulated_body"), budget_s: float = 0.05,
            repeats: int = 3) -> dict:
    import pinocchio as pin

    from .scipy_pipeline import pipeline_for

    t, q, v = scene.t0, np.array(scene.q0), np.array(scene.v0)
    row: dict[str, float] = dict(n=len(v))
    # iterations sized so each loop takes about budget_s
    probe = scene.rhs_benchmark(10, "null_space")
    iters = int(max(20, min(200000, budget_s / max(probe, 1e-9))))
    for f in formulations:
        row[f"progmo_{f}_s"] = min(scene.rhs_benchmark(iters, f) for _ in range(repeats))
    d = scene.dynamics(t, q, v)
    J, g = np.ascontiguousarray(d["B"]), -d["gamma"]
    pipe = pipeline_for(scene)
    model, data, tau = pipe.model, pipe.data, np.zeros(len(v))

    def fd():
        pin.forwardDynamics(model, data, q, v, tau, J, g)
        return J.T @ data.lambda_c

    row["pin_fd_u_s"] = _best_loop(fd, iters, repeats)
    row["pin_fd_only_s"] = _best_loop(lambda: pin.forwardDynamics(model, data, q, v, tau, J, g), iters, repeats)
    row["pin_pipeline_s"] = _best_loop(lambda: pipe.accelerations(t, q, v), iters, repeats)
    row["iterations"] = iters
    # the same answer (sanity): Pinocchio vs progmo's kkt at this state
    a_pin = pin.forwardDynamics(model, data, q, v, tau, J, g)
    a_pm = scene.accelerations(t, q, v, "kkt")["a"]
    row["max_abs_da"] = float(np.abs(np.asarray(a_pin) - a_pm).max())
    return row


def run(out: Path, prov: Provenance, quick: bool, ns=None) -> dict:
    from .. import Scene

    ns = ns or ([2, 4, 7, 16, 30, 64] if quick else [2, 4, 7, 8, 16, 30, 32, 64, 96, 128])
    budget = 0.03 if quick else 0.2
    overhead = python_overhead()
    rows = []
    with SceneDir() as d:
        for n in ns:
            log(f"[scaling] n = {n}")
            scene = Scene(str(d.write(f"chain_{n}", chain_toml(n, name=f"chain_{n}"))))
            rows.append(measure(scene, budget_s=budget))
    header = ["n", "progmo_null_space_s", "progmo_kkt_s", "progmo_articulated_body_s", "pin_fd_only_s", "pin_fd_u_s",
              "pin_pipeline_s", "iterations", "max_abs_da"]
    write_csv(out / "scaling.csv", prov, header, ([r[h] for h in header] for r in rows))
    fig = _plot(rows, overhead)
    save_figure(fig, out / "scaling.png", prov)
    return dict(rows=rows, python_overhead_s=overhead)


def _plot(rows, overhead):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["n"] for r in rows]
    fig, ax = plt.subplots(figsize=(7.5, 5.2))
    for key, lab, st in (("progmo_null_space_s", "progmo null_space (Rust loop)", "-o"),
                         ("progmo_kkt_s", "progmo kkt (Rust loop)", "--o"),
                         ("progmo_articulated_body_s", "progmo articulated_body (Rust loop)", "-.o"),
                         ("pin_fd_u_s", "pin.forwardDynamics + u (Python loop)", "-s"),
                         ("pin_pipeline_s", "user pipeline: numpy J, gamma + forwardDynamics", ":s")):
        ax.loglog(n, [r[key] * 1e6 for r in rows], st, ms=4, label=lab)
    ax.axhline(overhead * 1e6, color="gray", lw=0.8, ls=":", label=f"Python call overhead {overhead * 1e6:.2f} us")
    for m in MARK:
        ax.axvline(m, color="k", lw=0.6, alpha=0.4)
        ax.text(m, ax.get_ylim()[1], f" n={m}", va="top", fontsize=7)
    ax.set_xlabel("links n")
    ax.set_ylabel("microseconds per RHS (dv/dt and u)")
    ax.set_title("RHS cost vs chain length (2 programme rows)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    return fig


def at(rows, n: int) -> dict | None:
    return next((r for r in rows if r["n"] == n), None)
