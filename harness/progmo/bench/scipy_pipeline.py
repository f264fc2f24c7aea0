"""What a user would write instead of progmo: `scipy.integrate.solve_ivp` on y = (q, v) with the
constrained accelerations from Pinocchio.

The pipeline is independent of progmo's core except for the model file: the URDF comes from
`scene.export("urdf")` (checked against our mass matrix elsewhere: tests/python/test_export_parity.py).
The programme's Jacobian J and gamma are written by hand in numpy, as a user would, for the two
programme families of the bench scenes:

- joint rows  q_k - f(t) = 0:            J = e_k,  J a + gamma = 0 with gamma = -f''(t);
- tip height  z(q) - f(t) = 0 of a planar chain (hinges about y, links of length l, angles
  theta_k = q_1 + ... + q_k, z = -l sum_k cos theta_k):
  J_j = l sum_{k>=j} sin theta_k,  gamma = l sum_k cos theta_k (dtheta_k/dt)^2 - f''(t).

Pinocchio 4.1's `forwardDynamics(model, data, q, v, tau, J, gamma)` solves M a + b = tau + J^T lambda
with J a + gamma = 0 (the sign convention of simulators.md, checked against progmo in the tests:
gamma_pin = -gamma_progmo, the same lambda). tau = 0: gravity is in the model, the scenes have no
other applied forces. The control force is u = J^T lambda (data.lambda_c).

No drift control: the position rows are only enforced at acceleration level, so they drift at the
integrator's tolerance (a user adding Baumgarte terms or projection would pay more per step).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np


@dataclass
class Row:
    kind: str  # "joint" or "tip_z"
    f: Callable[[float], float]  # the time law
    fdd: Callable[[float], float]  # its second derivative
    k: int = 0  # joint index (0-based) of a joint row
    length: float = 0.0  # link length of a tip_z row
    # the law's family and constants, for the C++ anchor (bench/cpp/anchor.cpp):
    # ("one_minus_cos", amp, w): c + amp (1 - cos w t); ("sin", amp, w): c + amp sin w t
    law: tuple[str, float, float] | None = None


@dataclass
class Pipeline:
    """Pinocchio model + hand-written programme rows of one scene."""

    name: str
    model: object
    data: Any  # pinocchio.Data
    rows: list[Row]
    nq: int
    J: np.ndarray = field(init=False)
    gamma: np.ndarray = field(init=False)

    def __post_init__(self):
        self.J = np.zeros((len(self.rows), self.nq))
        self.gamma = np.zeros(len(self.rows))
        self.tau = np.zeros(self.nq)

    def constraints(self, t: float, q: np.ndarray, v: np.ndarray):
        """J and gamma (Pinocchio's sign: J a + gamma = 0) at (t, q, v)."""
        J, g = self.J, self.gamma
        for i, r in enumerate(self.rows):
            if r.kind == "joint":
                J[i, :] = 0.0
                J[i, r.k] = 1.0
                g[i] = -r.fdd(t)
            else:
                th = np.cumsum(q)
                thd = np.cumsum(v)
                s = np.sin(th)
                J[i, :] = r.length * np.cumsum(s[::-1])[::-1]
                g[i] = r.length * float(np.dot(np.cos(th), thd * thd)) - r.fdd(t)
        return J, g

    def accelerations(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """dv/dt and the control force u = J^T lambda."""
        import pinocchio as pin

        J, g = self.constraints(t, q, v)
        a = pin.forwardDynamics(self.model, self.data, q, v, self.tau, J, g)
        return np.array(a), J.T @ self.data.lambda_c

    def rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        """solve_ivp right-hand side: d(q, v)/dt = (v, a). u is not formed (not needed to integrate)."""
        import pinocchio as pin

        n = self.nq
        q, v = y[:n], y[n:]
        J, g = self.constraints(t, q, v)
        a = pin.forwardDynamics(self.model, self.data, q, v, self.tau, J, g)
        return np.concatenate((v, a))


def pipeline_for(scene) -> Pipeline:
    """The hand-written pipeline of a bench scene: the bundled double_pendulum and chain_8, and the
    chains of `common.chain_toml`. Other scenes raise NotImplementedError (listed as omissions)."""
    from .common import pinocchio_model

    p = dict(scene.parameters)
    names = [r["name"] for r in scene.rows]
    if scene.kind != "tree":
        raise NotImplementedError(f"{scene.name}: lagrangian scene, no URDF")
    if scene.name == "double_pendulum" and names == ["elbow"]:
        amp, w = p["amp"], p["w"]
        rows = [Row("joint", lambda t: amp * np.sin(w * t), lambda t: -amp * w * w * np.sin(w * t), k=1,
                    law=("sin", amp, w))]
    elif set(names) <= {"tip_height", "shoulder"} and "tip_height" in names:
        A, B, w, q0 = p["A"], p["B"], p["w"], p["q0"]
        l = p.get("l", 0.25)
        ztip0 = p["ztip0"]
        rows = []
        for nm in names:
            if nm == "tip_height":
                rows.append(Row("tip_z", lambda t: ztip0 + A * (1 - np.cos(w * t)),
                                lambda t: A * w * w * np.cos(w * t), length=l, law=("one_minus_cos", A, w)))
            else:
                rows.append(Row("joint", lambda t: q0 + B * (1 - np.cos(w * t)),
                                lambda t: B * w * w * np.cos(w * t), k=0, law=("one_minus_cos", B, w)))
        _check_planar_chain(scene, l)
    else:
        raise NotImplementedError(f"{scene.name}: no hand-written programme rows for {names}")
    model, data = pinocchio_model(scene)
    return Pipeline(scene.name, model, data, rows, model.nq)


def _check_planar_chain(scene, l: float) -> None:
    """The tip formula assumes hinges about y and links of length l: verify z(q0) against the
    scene's own tip-height row (its residual at t0 must vanish with our formula's ztip0)."""
    p = dict(scene.parameters)
    z = -l * np.sum(np.cos(np.cumsum(scene.q0)))
    if abs(z - p["ztip0"]) > 1e-12 * max(1.0, abs(z)):
        raise NotImplementedError(f"{scene.name}: not a uniform planar chain of link length {l}")


def solve(pipe: Pipeline, scene, method: str, rtol: float, atol: float, t1: float | None = None):
    """solve_ivp from the scene's initial state to t1 (dense output off); returns the OdeResult."""
    from scipy.integrate import solve_ivp

    y0 = np.concatenate((scene.q0, scene.v0))
    t1 = scene.t1 if t1 is None else t1
    return solve_ivp(pipe.rhs, (scene.t0, t1), y0, method=method, rtol=rtol, atol=atol)


# ---------------------------------------------------------------------------------------------
# The comparison: CPU time at equal error


SCIPY_METHODS = ("DOP853", "Radau")
# progmo's curve each scipy method is compared with (same family), and the reference it is measured
# against (a different integrator family, as for progmo's own runs)
PARTNER = {"DOP853": "dop853", "Radau": "radau5"}
REFERENCE_OF = {"DOP853": "radau5", "Radau": "dop853"}


def sweep(scene, ref, tols, repeats: int = 1, radau_min_tol: float = 0.0) -> list[dict]:
    from .common import cpu_time

    pipe = pipeline_for(scene)
    rows = []
    for method in SCIPY_METHODS:
        ref_state = ref.state[REFERENCE_OF[method]]
        for tol in tols:
            if method == "Radau" and tol < radau_min_tol:
                continue
            dt, r = cpu_time(lambda: solve(pipe, scene, method, tol, tol), repeats)
            ok = r.status == 0 and abs(r.t[-1] - scene.t1) < 1e-12
            err = float(np.abs(r.y[:, -1] - ref_state).max()) if ok else float("nan")
            rows.append(dict(scene=scene.name, method=f"scipy {method}", rtol=tol, atol=tol,
                             code="success" if ok else r.message, error=err, cpu_s=dt,
                             rhs_evals=int(r.nfev), jacobian_evals=int(r.njev), lu=int(r.nlu),
                             reference=REFERENCE_OF[method]))
    return rows


def ratios(scene_name: str, progmo_rows: list[dict], scipy_rows: list[dict],
           nodrift_rows: list[dict] | None = None) -> list[dict]:
    """CPU(scipy) / CPU(progmo) at common errors, interpolated log-log on each Pareto front.
    Partners: scipy DOP853 vs progmo dop853, scipy Radau vs progmo radau5 (both null_space), and
    the best of scipy vs the best of progmo (any formulation and integrator)."""
    from .common import common_error_levels, time_at_error

    def curve(rows) -> tuple[list[float], list[float]]:
        return [r["error"] for r in rows], [r["cpu_s"] for r in rows]

    pairs = []
    for m in SCIPY_METHODS:
        s = [r for r in scipy_rows if r["method"] == f"scipy {m}"]
        p = [r for r in progmo_rows if r["integrator"] == PARTNER[m] and r["formulation"] == "null_space"]
        pairs.append((f"scipy {m} / progmo {PARTNER[m]} null_space", s, p))
    if nodrift_rows:
        s = [r for r in scipy_rows if r["method"] == "scipy DOP853"]
        pairs.append(("scipy DOP853 / progmo dop853 null_space drift=none (same problem)", s, nodrift_rows))
    pairs.append(("best scipy / best progmo", scipy_rows, progmo_rows))
    out = []
    for label, s, p in pairs:
        for e in common_error_levels([curve(s), curve(p)]):
            ts, tp = time_at_error(*curve(s), e), time_at_error(*curve(p), e)
            out.append(dict(scene=scene_name, comparison=label, error=e, cpu_scipy=ts,
                            cpu_progmo=tp, ratio=ts / tp))
    return out


def agreement(scene, ref, tol: float = 1e-12) -> float:
    """Independent cross-check: scipy DOP853 + Pinocchio at a tight tolerance against progmo's
    dop853 reference (different code, different model evaluation): max |(q, v)| difference."""
    pipe = pipeline_for(scene)
    r = solve(pipe, scene, "DOP853", tol, tol)
    return float(np.abs(r.y[:, -1] - ref.state["dop853"]).max()) if r.status == 0 else float("nan")


def plot(scene_name, progmo_rows, scipy_rows, ratio_rows, ref, out, prov, nodrift_rows=()):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .common import log_plot
    from .workprecision import COLORS

    fig, axes = plt.subplots(1, 2, figsize=(12, 5.2))
    for xkey, ax in (("cpu_s", axes[0]), ("rhs_evals", axes[1])):
        for integ in ("dop853", "dopri5", "radau5"):
            pts = sorted((r[xkey], r["error"]) for r in progmo_rows
                         if r["integrator"] == integ and r["formulation"] == "null_space" and np.isfinite(r["error"]))
            if pts:
                x, y = zip(*pts)
                log_plot(ax, x, y, "-o", ms=4, color=COLORS[integ], label=f"progmo {integ} null_space")
        pts = sorted((r[xkey], r["error"]) for r in nodrift_rows if np.isfinite(r["error"]))
        if pts:
            x, y = zip(*pts)
            log_plot(ax, x, y, ":o", ms=4, color=COLORS["dop853"], mfc="none",
                     label="progmo dop853 null_space, drift control off")
        for m in SCIPY_METHODS:
            pts = sorted((r[xkey], r["error"]) for r in scipy_rows if r["method"] == f"scipy {m}" and np.isfinite(r["error"]))
            if pts:
                x, y = zip(*pts)
                log_plot(ax, x, y, "--s", ms=4, color=COLORS[f"scipy {m}"],
                         label=f"scipy {m} + pin.forwardDynamics")
        ax.axhline(ref.floor, color="gray", lw=0.8, ls=":")
        ax.set_xlabel("CPU time per solve (s)" if xkey == "cpu_s" else "RHS evaluations")
        ax.set_ylabel("final-state error")
        ax.grid(True, which="both", alpha=0.3)
    best = [r for r in ratio_rows if r["comparison"].startswith("best")]
    txt = "; ".join(f"{r['ratio']:.1f}x at {r['error']:.0e}" for r in best[:4]) or "no common error range"
    axes[0].set_title(f"{scene_name}: scipy + Pinocchio vs progmo", fontsize=10)
    axes[1].set_title(f"CPU(best scipy)/CPU(best progmo): {txt}", fontsize=8)
    axes[1].legend(fontsize=7)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    from .common import save_figure

    return save_figure(fig, out / f"scipy_{scene_name}.png", prov)
