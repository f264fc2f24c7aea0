"""The humanoid beside Pinocchio's C++ constrained dynamics (issue 31, item 3): TALOS of the catalog
scene ``talos_com_shift`` (example-robot-data's talos_reduced URDF, free-floating base, upper body
locked: n = 18) with both soles welded to the world, and nothing else: the scene without its
programme (the robot standing under gravity on its welded feet, u = 0).

C++ side (bench/cpp/anchor.cpp, the anchor's binary): Pinocchio's model of the file as the check
builds it (``PinocchioBackend`` on the user's file: FreeFlyer root, locked joints reduced) written
joint by joint, and the check's two welds (its ``RigidConstraintModel``s: joint and placement of each
sole) as ``weld`` lines; variants ``weld_kkt`` (crba + nonLinearEffects + the soles' stacked LOCAL
Jacobians and drifts + forwardDynamics: the dense KKT reference), ``weld_cd`` (constraintDynamics)
and ``weld_lcaba`` (lcaba), and ``aba`` (no welds).
progmo side: the same scene's right-hand side (its 12 closure rows), each formulation, through
``Scene.rhs_benchmark``; and, for scale, the programmed motion's (``talos_com_shift``, s = n = 18).
Agreement first, at states of talos_com_shift's solution (on the welds: the soles at rest): every
C++ weld variant's dv/dt against progmo's kkt dv/dt mapped to Pinocchio's coordinates (the check's
``CoordMap``: quaternion order, body-frame linear velocity), relative to max |dv/dt|; beyond the
anchor's tolerance the part fails. Timing as the anchor's: alternated short loops, thread CPU time,
minima.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from . import anchor
from .common import Provenance, log, scene_path, write_csv

SCENE = "talos_com_shift"
#: the weld variants timed and checked (anchor.cpp)
WELD = ("weld_cd", "weld_lcaba", "weld_kkt")


def standing_text(path: Path) -> str:
    """The scene's text without its [[programme]] tables: the humanoid on its welded soles."""
    out: list[str] = []
    skip = False
    for line in path.read_text().splitlines():
        if line.startswith("["):
            skip = line.strip() == "[[programme]]"
        if line.startswith("name = ") and not out:
            line = 'name = "talos_standing"'
        if not skip:
            out.append(line)
    return "\n".join(out) + "\n"


def backend(scene):
    """The check's Pinocchio back-end on the scene's robot file (model, welds, coordinate map)."""
    from ..simulators.pinocchio_sim import PinocchioBackend
    from ..simulators.robot_file import robot_file

    return PinocchioBackend(*scene.export("urdf", supply_reactions=True), scene, robot=robot_file(scene))


def model_text(be) -> str:
    """anchor.cpp's model file: the back-end's Pinocchio model joint by joint, no rows, its welds."""
    model = be.model
    lines = ["progmo-anchor 1", f"joints {model.njoints - 1}",
             "gravity " + " ".join(repr(float(x)) for x in model.gravity.linear)]
    for i in range(1, model.njoints):
        kind = model.joints[i].shortname()
        if kind not in ("JointModelRX", "JointModelRY", "JointModelRZ", "JointModelFreeFlyer"):
            raise NotImplementedError(f"joint type {kind} not supported by the C++ anchor")
        M, Y = model.jointPlacements[i], model.inertias[i]
        nums = [*np.asarray(M.rotation).ravel(), *np.asarray(M.translation), Y.mass, *np.asarray(Y.lever),
                *np.asarray(Y.inertia).ravel()]
        lines.append(f"joint {kind} {model.parents[i]} " + " ".join(repr(float(x)) for x in nums))
    if np.any(model.damping):
        lines.append("damping " + " ".join(repr(float(x)) for x in model.damping))
    lines += ["rows 0", f"welds {len(be.cmodels)}"]
    for c in be.cmodels:
        if c.joint2_id != 0:
            raise NotImplementedError("a weld between two bodies (the anchor welds frames to the world)")
        P = c.joint1_placement
        lines.append(f"weld {c.joint1_id} " + " ".join(repr(float(x)) for x in
                                                      [*np.asarray(P.rotation).ravel(), *np.asarray(P.translation)]))
    return "\n".join(lines) + "\n"


class Process(anchor.Process):
    """The anchor on the humanoid: states sent in Pinocchio's coordinates (the check's CoordMap),
    no rows."""

    def __init__(self, exe: Path, be, workdir: Path, text: str | None = None):
        """`text`: the model file (default model_text(be))."""
        self.cm = be.cm
        super().__init__(exe, SimpleNamespace(name="talos_standing"), workdir,
                         text=model_text(be) if text is None else text)

    def _state(self, t, q, v) -> str:
        q, v = np.asarray(q, float), np.asarray(v, float)
        return f"{float(t)!r} " + " ".join(repr(float(x)) for x in [*self.cm.q_to_sim(q), *self.cm.v_to_sim(q, v)])


def agreement(standing, be, proc, states) -> tuple[dict[str, float], float]:
    """Largest relative disagreement of each C++ weld variant with progmo's kkt dv/dt (in
    Pinocchio's coordinates) and of aba with pin.aba, over the states; raises AnchorFailed beyond
    the tolerance (AGREEMENT, or eps cond(A) where larger)."""
    import pinocchio as pin

    from .anchor import AGREEMENT, AnchorFailed, _rel

    data = be.model.createData()
    worst = {v: 0.0 for v in ("aba",) + WELD}
    tol = AGREEMENT
    for t, q, v in states:
        got = proc.check(t, q, v)
        a = np.asarray(standing.accelerations(t, q, v, "kkt")["a"])
        ref = be.cm.a_to_sim(q, v, a)
        tol = max(tol, float(np.finfo(float).eps) * float(np.linalg.cond(standing.dynamics(t, q, v)["mass"])))
        qs, vs = be.cm.q_to_sim(q), be.cm.v_to_sim(q, v)
        worst["aba"] = max(worst["aba"], _rel(got.get(("a", "aba"), [np.nan]),
                                              pin.aba(be.model, data, qs, vs, -be.model.damping * vs)))
        for var in WELD:
            worst[var] = max(worst[var], _rel(got.get(("a", var), [np.nan]), ref))
    bad = {k: e for k, e in worst.items() if not e <= tol}
    if bad:
        raise AnchorFailed(f"{SCENE} on welded soles: C++ and progmo disagree beyond {tol:.1e} relative: "
                           + ", ".join(f"{k} {e:.1e}" for k, e in bad.items())
                           + " (weld_* against progmo's kkt dv/dt, aba against pin.aba)")
    return worst, tol


#: ratio = progmo / C++ in every row
HEADER = ["what", "progmo_s", "cpp_s", "ratio", "detail"]


def run(out: Path, prov: Provenance, exe: Path, rounds: int = 7, budget_s: float = 0.05,
        check_states: int = 5) -> dict[str, Any]:
    """Agreement (raises anchor.AnchorFailed), then `rounds` timing rounds; the row written to
    humanoid.csv and returned."""
    from .. import Scene
    from .anchor import PROGMO, rhs_cpu
    from .robot import trajectory_states

    path = scene_path(SCENE)
    programmed = Scene(str(path))
    with tempfile.TemporaryDirectory(prefix="progmo-humanoid-") as work:
        sp = Path(work) / "talos_standing.toml"
        sp.write_text(standing_text(path))
        standing = Scene(str(sp))
        be = backend(standing)
        states = trajectory_states(programmed, check_states)
        with Process(exe, be, Path(work)) as proc:
            worst, tol = agreement(standing, be, proc, states)
            log(f"[robot] {SCENE} on welded soles: agreement {max(worst.values()):.1e} (tolerance {tol:.1e}) "
                f"at {len(states)} states")
            t, q, v = states[0]
            probe = min(rhs_cpu(standing, 20, "null_space") for _ in range(3))
            iters = int(max(10, min(200000, budget_s / 5 / max(probe, 1e-9))))
            best: dict[str, float] = {}

            def keep(k: str, x: float) -> None:
                best[k] = min(best.get(k, np.inf), x)

            for r in range(rounds):
                log(f"[robot] {SCENE} timing round {r + 1} of {rounds}")
                for i in range(5):
                    def progmo() -> None:
                        for f in PROGMO:
                            keep(f"progmo_{f}", rhs_cpu(standing, iters, f))
                        keep("progmo_programmed", rhs_cpu(programmed, iters, "auto"))

                    def cpp() -> None:
                        for k, x in proc.bench(iters, t, q, v).items():
                            keep(k, x)

                    for step in ((progmo, cpp) if i % 2 == 0 else (cpp, progmo)):
                        step()
    row: dict[str, Any] = {f"{k}_s": x for k, x in best.items()}
    row.update(n=len(standing.v0), closure_rows=len(standing.rows), iterations=iters, rounds=rounds,
               agreement=max(worst.values()), agreement_tol=tol, agreement_by_variant=worst,
               agreement_states=len(states))
    fast = ("weld_cd", "weld_lcaba")
    row["weld_best"] = min(fast, key=lambda k: best[k])
    row["weld_best_s"] = best[row["weld_best"]]
    for f in PROGMO:
        row[f"ratio_{f}_weld"] = best[f"progmo_{f}"] / row["weld_best_s"]
    rows = [[f"standing_{f}_vs_best_weld", best[f"progmo_{f}"], row["weld_best_s"], row[f"ratio_{f}_weld"],
             f"C++ {row['weld_best']}"] for f in PROGMO]
    rows += [[f"standing_auto_vs_{k}", best["progmo_auto"], best[k], best["progmo_auto"] / best[k], k]
             for k in WELD + ("aba",)]
    rows.append(["programmed_auto_vs_best_weld", best["progmo_programmed"], row["weld_best_s"],
                 best["progmo_programmed"] / row["weld_best_s"], f"{SCENE} (s = n = 18) against the welded C++"])
    write_csv(out / "humanoid.csv", prov, HEADER, rows)
    return row
