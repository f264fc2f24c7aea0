"""A real robot: the Franka Panda of example-robot-data (scene panda_circle, n = 7, six rows) beside
Pinocchio on the same URDF, in the same run (issue 13, item 6).

- Model: Pinocchio's own reading of the scene's URDF (`pin.buildModelFromUrdf`, the finger joints
  removed with `pin.buildReducedModel` at q = 0, as the scene locks them). The C++ anchor
  (bench/cpp/anchor.cpp, header-only) builds the same model from those numbers (joint placements
  and inertias, and the joints' damping 0.003, applied as tau = -damping v in every variant since
  Pinocchio's aba and forwardDynamics leave model.damping out): the `pin` wheel does ship urdfdom and libpinocchio_parsers.so, but linking them
  would end the anchor's header-only build against Debian's Eigen, so the C++ side does not parse
  the URDF itself.
- One right-hand side (dv/dt and u): progmo's null_space and kkt (`Scene.rhs_benchmark`, a Rust
  loop) against the C++ variants of the anchor part (ABA; KKT with progmo's J and gamma given; the
  same-work sequences, which rebuild the rows from the kinematics: the TCP frame's
  LOCAL_WORLD_ALIGNED Jacobian and classical drift, position rows on the circle law and orientation
  rows held as d/dt w = 0). The scene's orientation rows are quaternion entries, Pinocchio's are the
  angular velocity: on the programmed motion the two sets span the same rows and give the same dv/dt
  and u, so agreement is checked at states of progmo's own solution (t0 and samples along it), to
  1e-10 relative (eps cond(A) if larger), before any timing; ABA against pin.aba. Timed as the
  anchor part times the chains (alternating rounds, thread CPU time, minima).
- One whole solve over the scene's span: progmo's `Scene.solve` at the scene's settings against
  scipy's solve_ivp (DOP853, same rtol and atol) with Pinocchio's Python binding as right-hand side
  (forwardKinematics, computeJointJacobians, the TCP's frame Jacobian and classical drift,
  forwardDynamics with J and gamma); both final states against a tight reference (progmo dop853 and
  radau5 at 1e-12: their difference is the floor). CPU time: median of a few runs. The anchor has no
  integrator: there is no C++ whole solve; its per-RHS time times progmo's RHS count is shown as
  the RHS share such a solve would pay.
- URDF load time: `progmo.load` of a scene holding only the [model] table (URDF import, tree build)
  against `pin.buildModelFromUrdf` (+ buildReducedModel) of the same file; best of several.
- A humanoid (bench/humanoid.py, issue 31 item 3): TALOS of talos_com_shift standing on both soles
  welded to the world, progmo's RHS against the anchor's constraintDynamics and lcaba on the check's
  own Pinocchio model and welds, agreement first (the anchor's binary, same run).
"""

from __future__ import annotations

import os
import tempfile
import time
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from .common import Provenance, cpu_time, log, scene_path, write_csv

SCENE = "panda_circle"
FRAME = "panda_hand_tcp"
#: the scene's rows as the anchor writes them: (row name, axis of the TCP frame's world motion, law)
ROWS = (("circle_x", 0, "circle_cos"), ("circle_y", 1, "circle_sin"), ("height", 2, "const"),
        ("down_w", 3, "const"), ("down_y", 4, "const"), ("down_z", 5, "const"))


def urdf_file(scene_file: Path) -> tuple[Path, dict[str, Any]]:
    """The scene's URDF (package:// through progmo.data.robot_path, the rule progmo.load uses) and
    its [model] table."""
    from .. import data

    with open(scene_file, "rb") as f:
        m = tomllib.load(f)["model"]
    rest = m["file"].removeprefix("package://")
    for d in data.robot_path():
        if (d / rest).is_file():
            return d / rest, m
    raise FileNotFoundError(f"{m['file']} not found (example-robot-data not installed?)")


def pin_model(urdf: Path, m: dict[str, Any]):
    """Pinocchio's model of the URDF with the scene's locked joints removed at q = 0."""
    import pinocchio as pin

    model = pin.buildModelFromUrdf(str(urdf))
    locked = [model.getJointId(n) for n in m.get("locked_joints", [])]
    if locked:
        model = pin.buildReducedModel(model, locked, pin.neutral(model))
    model.gravity.linear = np.array(m.get("gravity", [0.0, 0.0, 0.0]), dtype=float)
    return model


def parameters(scene) -> dict[str, float]:
    return dict(scene.parameters)


def model_text(scene, model) -> str:
    """The anchor's model file (anchor.py's format) from Pinocchio's model and the scene's rows."""
    names = [model.names[j] for j in range(1, model.njoints)]
    if names != list(scene.q_names):
        raise NotImplementedError(f"{scene.name}: Pinocchio's joint order {names} differs from {scene.q_names}")
    lines = ["progmo-anchor 1", f"joints {model.njoints - 1}",
             "gravity " + " ".join(repr(float(x)) for x in model.gravity.linear)]
    for i in range(1, model.njoints):
        jm = model.joints[i]
        kind = jm.shortname()
        if kind not in ("JointModelRX", "JointModelRY", "JointModelRZ", "JointModelPX", "JointModelPY", "JointModelPZ"):
            raise NotImplementedError(f"{scene.name}: joint type {kind} not supported by the C++ anchor")
        M, Y = model.jointPlacements[i], model.inertias[i]
        nums = [*np.asarray(M.rotation).ravel(), *np.asarray(M.translation), Y.mass, *np.asarray(Y.lever),
                *np.asarray(Y.inertia).ravel()]
        lines.append(f"joint {kind} {model.parents[i]} " + " ".join(repr(float(x)) for x in nums))
    if np.any(model.damping):  # the URDF's <dynamics damping>: tau = -damping v in every variant
        lines.append("damping " + " ".join(repr(float(x)) for x in model.damping))
    if [r["name"] for r in scene.rows] != [r[0] for r in ROWS]:
        raise NotImplementedError(f"{scene.name}: rows {[r['name'] for r in scene.rows]} are not the hand-written "
                                  f"ones {[r[0] for r in ROWS]}")
    f = model.frames[model.getFrameId(FRAME)]
    p = " ".join(repr(float(x)) for x in np.asarray(f.placement.translation))
    par = parameters(scene)
    lines.append(f"rows {len(ROWS)}")
    for _, axis, law in ROWS:
        amp, w = (par["r"], par["T"]) if law.startswith("circle") else (0.0, 0.0)
        lines.append(f"row tip {f.parentJoint} {p} {axis} {law} {amp!r} {w!r}")
    return "\n".join(lines) + "\n"


def trajectory_states(scene, count: int) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """t0 and count - 1 samples spread over progmo's solution (on the programmed motion)."""
    sol = scene.solve().raise_if_stopped()
    idx = np.unique(np.linspace(0, len(sol.t) - 1, max(count, 1)).round().astype(int))
    return [(float(sol.t[i]), np.array(sol.q[i]), np.array(sol.v[i])) for i in idx]


def agreement(scene, model, proc, states) -> tuple[dict[str, float], float]:
    """Largest relative disagreement per C++ variant with progmo's kkt (ABA with pin.aba) at the
    states; raises anchor.AnchorFailed beyond the tolerance (as anchor.agreement)."""
    import pinocchio as pin

    from .anchor import AGREEMENT, VARIANTS, WELD, AnchorFailed, _rel

    data = model.createData()
    worst = {v: 0.0 for v in VARIANTS + WELD}
    tol = AGREEMENT
    for t, q, v in states:
        got = proc.check(t, q, v)
        ref = scene.accelerations(t, q, v, "kkt")
        tol = max(tol, float(np.finfo(float).eps) * float(np.linalg.cond(scene.dynamics(t, q, v)["mass"])))
        a_aba = np.asarray(pin.aba(model, data, q, v, -model.damping * v))
        for var in VARIANTS:
            errs = [_rel(got[("a", var)], a_aba)] if var == "aba" else [_rel(got[(k, var)], ref[k]) for k in ("a", "u")]
            worst[var] = max(worst[var], *errs)
        # the welded frame (no time law): constraintDynamics and lcaba against the KKT solve of the
        # frame's own Jacobian and drift (a missing line is infinitely wrong)
        for var in WELD:
            worst[var] = max(worst[var], _rel(got.get(("a", var), [np.nan]), got.get(("a", "weld_kkt"), [0.0])))
    bad = {k: e for k, e in worst.items() if not e <= tol}
    if bad:
        raise AnchorFailed(f"{scene.name}: C++ and progmo disagree beyond {tol:.1e} relative: "
                           + ", ".join(f"{k} {e:.1e}" for k, e in bad.items())
                           + " (dv/dt and u against progmo's kkt; aba against pin.aba; weld_* against weld_kkt)")
    return worst, tol


class PinPipeline:
    """dv/dt of the panda_circle programme with Pinocchio's Python binding (a user's pipeline)."""

    def __init__(self, scene, model):
        import pinocchio as pin
        import scipy.integrate  # noqa: F401 - imported here, not inside the timed solve

        self.pin, self.model, self.data = pin, model, model.createData()
        self.fid = model.getFrameId(FRAME)
        par = parameters(scene)
        self.r, self.T = par["r"], par["T"]
        self.tau = np.zeros(model.nv)
        self.evals = 0

    def desired(self, t: float) -> np.ndarray:
        """Second derivatives of the TCP's position law (circle_x, circle_y, height)."""
        W = 2 * np.pi / self.T
        th, thd, thdd = W * t - np.sin(W * t), W * (1 - np.cos(W * t)), W * W * np.sin(W * t)
        return np.array([-self.r * (thd ** 2 * np.cos(th) + thdd * np.sin(th)),
                         self.r * (thdd * np.cos(th) - thd ** 2 * np.sin(th)), 0.0])

    def accelerations(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        pin, model, data = self.pin, self.model, self.data
        self.evals += 1
        pin.forwardKinematics(model, data, q, v, np.zeros(model.nv))
        pin.computeJointJacobians(model, data, q)
        J = pin.getFrameJacobian(model, data, self.fid, pin.LOCAL_WORLD_ALIGNED)
        acc = pin.getFrameClassicalAcceleration(model, data, self.fid, pin.LOCAL_WORLD_ALIGNED)
        gamma = np.concatenate([acc.linear - self.desired(t), acc.angular])
        # the URDF's joint damping (model.damping, which forwardDynamics leaves out)
        np.multiply(model.damping, v, out=self.tau)
        self.tau *= -1.0
        return np.asarray(pin.forwardDynamics(model, data, q, v, self.tau, J, gamma))

    def solve(self, t0, t1, q0, v0, rtol, atol):
        from scipy.integrate import solve_ivp

        n = len(q0)

        def f(t, y):
            return np.concatenate([y[n:], self.accelerations(t, y[:n], y[n:])])

        self.evals = 0
        return solve_ivp(f, (t0, t1), np.concatenate([q0, v0]), method="DOP853", rtol=rtol, atol=atol,
                         t_eval=[t1])


def load_times(scene_file: Path, repeats: int) -> dict[str, float]:
    """Best wall seconds of: progmo.load of a [model]-only scene; pin.buildModelFromUrdf (+ reduce)."""
    from .. import Scene

    urdf, m = urdf_file(scene_file)
    locked = ", ".join(f'"{j}"' for j in m.get("locked_joints", []))
    text = (f'name = "urdf_load"\n[model]\nkind = "urdf"\nfile = "{urdf}"\nlocked_joints = [{locked}]\n'
            f"gravity = {list(m.get('gravity', [0.0, 0.0, 0.0]))}\n[initial]\n[time]\nt1 = 1.0\n")
    best = dict(progmo_load_s=np.inf, pin_urdf_s=np.inf, pin_urdf_reduced_s=np.inf)
    with tempfile.TemporaryDirectory(prefix="progmo-urdf-") as d:
        p = os.path.join(d, "urdf_load.toml")
        Path(p).write_text(text)
        Scene(p)  # warm: the first read of the file (page cache) is not what is compared
        import pinocchio as pin

        for _ in range(repeats):
            t = time.perf_counter()
            Scene(p)
            best["progmo_load_s"] = min(best["progmo_load_s"], time.perf_counter() - t)
            t = time.perf_counter()
            model = pin.buildModelFromUrdf(str(urdf))
            best["pin_urdf_s"] = min(best["pin_urdf_s"], time.perf_counter() - t)
            ids = [model.getJointId(n) for n in m.get("locked_joints", [])]
            pin.buildReducedModel(model, ids, pin.neutral(model))
            best["pin_urdf_reduced_s"] = min(best["pin_urdf_reduced_s"], time.perf_counter() - t)
    return best


#: ratio = progmo / Pinocchio in every row
HEADER = ["what", "progmo_s", "pinocchio_s", "ratio", "detail"]


def run(out: Path, prov: Provenance, rounds: int = 7, budget_s: float = 0.05, check_states: int = 5,
        solve_repeats: int = 3, load_repeats: int = 10) -> dict[str, Any]:
    """The robot part: the C++ agreement check (raises anchor.AnchorFailed) and RHS timing rounds,
    then the whole solve and the load times. Without a C++ toolchain (anchor.Unavailable) the RHS
    comparison is skipped, res["rhs_skipped"] says why, and the rest still runs."""
    from .. import Scene
    from . import anchor, workprecision

    path = scene_path(SCENE)
    scene = Scene(str(path))
    urdf, m = urdf_file(path)
    model = pin_model(urdf, m)
    res: dict[str, Any] = dict(scene=SCENE, urdf=str(urdf), n=len(scene.v0), s=len(scene.rows), rhs=None)
    try:
        exe, cached = anchor.build()
    except anchor.Unavailable as e:
        res["rhs_skipped"] = str(e)
    else:
        res["build_cached"] = cached
        res["rhs"] = rhs_comparison(scene, model, exe, rounds, budget_s, check_states)
        from . import humanoid  # the humanoid on welded soles beside constraintDynamics / lcaba

        log(f"[robot] {humanoid.SCENE} on welded soles beside Pinocchio's C++ constrained dynamics")
        res["humanoid"] = humanoid.run(out, prov, exe, rounds, budget_s, check_states)

    log(f"[robot] {SCENE}: whole solve (progmo, scipy DOP853 + Pinocchio's Python binding, reference)")
    st = scene.settings
    rtol, atol = float(st["rtol"]), float(st["atol"])
    ref = workprecision.reference(scene)
    _, ref_state = ref.against("dop853")
    cpu_p, sol = cpu_time(lambda: scene.solve(output_dt=scene.t1 - scene.t0), solve_repeats)
    sol.raise_if_stopped()
    final_p = np.concatenate([sol.q[-1], sol.v[-1]])
    pipe = PinPipeline(scene, model)
    cpu_s, ivp = cpu_time(lambda: pipe.solve(scene.t0, scene.t1, np.array(scene.q0), np.array(scene.v0), rtol, atol),
                          solve_repeats)
    final_s = np.asarray(ivp.y[:, -1])
    progmo_evals = int(sol.stats["integrator"]["rhs_evals"])
    rhs = res["rhs"]
    res["solve"] = dict(rtol=rtol, atol=atol, integrator=st["integrator"], drift=sol.settings["drift"]["kind"],
                        progmo_cpu_s=cpu_p, progmo_rhs_evals=progmo_evals,
                        progmo_error=float(np.abs(final_p - ref_state).max()),
                        scipy_cpu_s=cpu_s, scipy_rhs_evals=int(ivp.nfev), scipy_success=bool(ivp.success),
                        scipy_error=float(np.abs(final_s - ref_state).max()) if ivp.success else float("nan"),
                        reference_floor=ref.floor, ratio=cpu_s / cpu_p,
                        cpp_rhs_share_s=progmo_evals * rhs["same_best_s"] if rhs else float("nan"))
    log(f"[robot] URDF load times ({load_repeats} repeats)")
    res["load"] = load_times(path, load_repeats)

    s, ld = res["solve"], res["load"]
    rows = []
    if rhs:
        rows += [["rhs_null_space_vs_cpp_same_work", rhs["progmo_null_space_s"], rhs["same_best_s"],
                  rhs["ratio_null_space"], rhs["same_best"]],
                 ["rhs_kkt_vs_cpp_same_work", rhs["progmo_kkt_s"], rhs["same_best_s"], rhs["ratio_kkt"],
                  rhs["same_best"]],
                 ["rhs_null_space_vs_cpp_kkt_given", rhs["progmo_null_space_s"], rhs["kkt_s"],
                  rhs["progmo_null_space_s"] / rhs["kkt_s"], "J, gamma given"]]
    rows += [["whole_solve_vs_scipy_pin_python", s["progmo_cpu_s"], s["scipy_cpu_s"], s["progmo_cpu_s"] / s["scipy_cpu_s"],
              f"final-state errors {s['progmo_error']:.1e} / {s['scipy_error']:.1e}"],
             ["urdf_load", ld["progmo_load_s"], ld["pin_urdf_s"], ld["progmo_load_s"] / ld["pin_urdf_s"],
              f"pin with buildReducedModel {ld['pin_urdf_reduced_s']:.3e} s"]]
    write_csv(out / "robot.csv", prov, HEADER, rows)
    return res


def rhs_comparison(scene, model, exe: Path, rounds: int, budget_s: float, check_states: int) -> dict[str, Any]:
    """Agreement at states of progmo's solution (raises anchor.AnchorFailed), then the timing
    rounds; anchor.Timing's row plus the agreement figures."""
    from . import anchor

    states = trajectory_states(scene, check_states)
    with tempfile.TemporaryDirectory(prefix="progmo-robot-") as work:
        with anchor.Process(exe, scene, Path(work), text=model_text(scene, model)) as proc:
            worst, tol = agreement(scene, model, proc, states)
            log(f"[robot] {SCENE}: agreement {max(worst.values()):.1e} (tolerance {tol:.1e}) at {len(states)} states")
            tm = anchor.Timing(scene, proc, budget_s)
            for r in range(rounds):
                log(f"[robot] RHS timing round {r + 1} of {rounds}")
                tm.round()
    row = tm.row()
    row.update(agreement=max(worst.values()), agreement_tol=tol, agreement_by_variant=worst,
               agreement_states=len(states))
    return row
