"""The paper's claim measured: does avoiding A^-1 (null-space form) reduce round-off?

For scenes with growing cond(A) (two-link chains with tip/upper mass ratio 1 ... 1e-8, 8-link chains
with masses falling geometrically to the tip, uniform chains of 2 ... 128 links), at a few sample
states, each formulation's f64 dv/dt and u (`Scene.accelerations`) are compared with an
extended-precision reference: A, F = G + Q, B, gamma are taken from `scene.dynamics` in f64 and the
KKT system [A, -B^T; B, 0] [a; lambda] = [F; gamma] is solved with mpmath at 50 digits (the f64
inputs converted exactly). This isolates each formulation's own round-off on the same f64 data; it
says nothing about the error of A, F, B, gamma themselves. u = sum over programme rows B_i^T lambda_i.
Relative error = max-norm of the difference / max-norm of the reference, maximum over the states.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .common import FORMULATIONS, Provenance, SceneDir, chain_toml, log, log_plot, save_figure, write_csv

DIGITS = 50


def kkt_reference(A, F, B, gamma, programme_rows, digits: int = DIGITS):
    """(a, lambda, u) of A a - F = B^T lambda, B a = gamma, solved in mpmath at `digits` digits and
    rounded to f64 at the end."""
    import mpmath

    A, F, B, gamma = (np.asarray(x, dtype=float) for x in (A, F, B, gamma))
    n, s = A.shape[0], B.shape[0]
    with mpmath.workdps(digits):
        K = mpmath.matrix(n + s, n + s)
        rhs = mpmath.matrix(n + s, 1)
        for i in range(n):
            for j in range(n):
                K[i, j] = mpmath.mpf(float(A[i, j]))
            for j in range(s):
                K[i, n + j] = -mpmath.mpf(float(B[j, i]))
            rhs[i] = mpmath.mpf(float(F[i]))
        for i in range(s):
            for j in range(n):
                K[n + i, j] = mpmath.mpf(float(B[i, j]))
            rhs[n + i] = mpmath.mpf(float(gamma[i]))
        x = mpmath.lu_solve(K, rhs)
        a = [x[i] for i in range(n)]
        lam = [x[n + i] for i in range(s)]
        u = [mpmath.fsum(B[i, j] * lam[i] for i in programme_rows) for j in range(n)]
        return (np.array([float(v) for v in a]), np.array([float(v) for v in lam]),
                np.array([float(v) for v in u]))


def sample_states(scene, count: int, seed: int = 7):
    """(t0, q0, v0) and `count - 1` perturbed states (seeded)."""
    rng = np.random.default_rng(seed)
    states = [(scene.t0, np.array(scene.q0), np.array(scene.v0))]
    for _ in range(count - 1):
        q = scene.q0 + rng.uniform(-0.05, 0.05, len(scene.q0))
        v = scene.v0 + rng.uniform(-0.5, 0.5, len(scene.v0))
        states.append((float(rng.uniform(scene.t0, scene.t1)), q, v))
    return states


def measure(scene, states) -> list[dict]:
    prog = [i for i, r in enumerate(scene.rows) if r["role"] == "programme"]
    err = {f: [0.0, 0.0] for f in FORMULATIONS}
    fails = {}
    cond = 0.0
    for t, q, v in states:
        d = scene.dynamics(t, q, v)
        A = d["mass"]
        F = d["velocity_terms"] + d["applied_forces"]
        cond = max(cond, float(np.linalg.cond(A)))
        a_ref, _, u_ref = kkt_reference(A, F, d["B"], d["gamma"], prog)
        for f in FORMULATIONS:
            try:
                r = scene.accelerations(t, q, v, f)
            except Exception as e:  # noqa: BLE001 - a failing formulation is a result, reported
                fails[f] = str(e)
                continue
            ea = np.abs(r["a"] - a_ref).max() / max(np.abs(a_ref).max(), 1e-300)
            eu = np.abs(r["u"] - u_ref).max() / max(np.abs(u_ref).max(), 1e-300)
            err[f][0], err[f][1] = max(err[f][0], ea), max(err[f][1], eu)
    return [dict(scene=scene.name, n=len(scene.v0), cond_A=cond, formulation=f,
                 rel_err_a=(float("nan") if f in fails else err[f][0]),
                 rel_err_u=(float("nan") if f in fails else err[f][1]),
                 note=fails.get(f, "")) for f in FORMULATIONS]


def families(quick: bool, smoke: bool = False):
    """(family, name, toml) of the conditioning scenes."""
    if smoke:
        return [("2-link, m2/m1", "two_link_m2_1e-06", chain_toml(2, masses=[1.0, 1e-6], length=0.5, q0=0.3,
                                                                  name="two_link_m2_1e-06")),
                ("uniform chain, n links", "chain_4", chain_toml(4, name="chain_4"))]
    ratios = [1.0, 1e-2, 1e-4, 1e-6, 1e-8] if not quick else [1.0, 1e-4, 1e-8]
    out = []
    for r in ratios:
        out.append(("2-link, m2/m1", f"two_link_m2_{r:.0e}", chain_toml(2, masses=[1.0, r], length=0.5,
                                                                      q0=0.3, name=f"two_link_m2_{r:.0e}")))
    for r in ratios:
        ms = [r ** (k / 7) for k in range(8)]
        out.append(("8-link, tip/base mass", f"chain8_tip_{r:.0e}", chain_toml(8, masses=ms, name=f"chain8_tip_{r:.0e}")))
    for n in ([2, 8, 32, 64, 128] if not quick else [2, 8, 32]):
        out.append(("uniform chain, n links", f"chain_{n}", chain_toml(n, name=f"chain_{n}")))
    return out


def run(out: Path, prov: Provenance, quick: bool, states: int = 3, smoke: bool = False) -> list[dict]:
    from .. import Scene

    rows = []
    with SceneDir() as d:
        for fam, name, text in families(quick, smoke):
            log(f"[conditioning] {name}")
            scene = Scene(str(d.write(name, text)))
            for r in measure(scene, sample_states(scene, states)):
                r["family"] = fam
                rows.append(r)
    header = ["family", "scene", "n", "cond_A", "formulation", "rel_err_a", "rel_err_u", "note"]
    write_csv(out / "conditioning.csv", prov, header, ([r[h] for h in header] for r in rows))
    plot(rows, out, prov)
    return rows


def plot(rows, out: Path, prov: Provenance) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .workprecision import MARKERS, STYLES

    fams = list(dict.fromkeys(r["family"] for r in rows))
    fig, axes = plt.subplots(2, len(fams), figsize=(5 * len(fams), 8), squeeze=False)
    for j, fam in enumerate(fams):
        for i, key in enumerate(("rel_err_a", "rel_err_u")):
            ax = axes[i, j]
            for f in FORMULATIONS:
                pts = sorted((r["cond_A"], r[key]) for r in rows if r["family"] == fam and r["formulation"] == f)
                x, y = zip(*pts)
                log_plot(ax, x, y, ls=STYLES[f], marker=MARKERS[f], label=f)
            ax.set_xlabel("cond(A)")
            ax.set_ylabel("relative error of " + ("dv/dt" if key == "rel_err_a" else "u"))
            ax.set_title(fam, fontsize=9)
            ax.grid(True, which="both", alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("f64 round-off of each formulation vs an mpmath 50-digit KKT solve on the same f64 A, F, B, gamma",
                 fontsize=9)
    fig.tight_layout(rect=(0, 0.05, 1, 0.97))
    return save_figure(fig, out / "conditioning.png", prov)
