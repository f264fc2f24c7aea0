"""Drake back-end (PyPI ``drake``, ``pip install 'progmo[drake]'``): a continuous
``MultibodyPlant`` read from URDF, replayed by RK4 on Drake's own time derivatives.

* **Model.** The scene's URDF export, or for a ``kind = "urdf"`` scene the user's own file (a
  copy without ``<visual>``/``<collision>``; locked joints turned into fixed joints at the value the
  scene locks them at). A ``kind = "mjcf"`` scene is **not** read through Drake's MJCF parser: it
  misplaces every joint but the last of a multi-joint body, silently (34 % off in the mass matrix
  of ``mjcf_arm``; ``tests/python/test_drake.py`` keeps this negative control); Drake reads
  progmo's URDF export of the scene instead (route "progmo export", said in the notes), while
  MuJoCo and Pinocchio read the user's MJCF file itself. Root joints: free ->
  ``QuaternionFloatingJoint``; spherical -> ``BallRpyJoint`` (Drake 1.5x has no quaternion ball
  joint: roll-pitch-yaw coordinates, singular at pitch +-pi/2, where the replay then blows up
  visibly). Armature -> a joint actuator's rotor inertia (gear ratio 1). Gravity from the report.
* **Forces.** A ``LeafSystem`` wired to the plant's applied-generalized-force and applied-spatial-
  force inputs (the latter only when the scene has a force at a point), evaluated by Drake at every
  integrator stage from the plant's own state (bodies' poses from the plant's own context) and the
  stage time: u (``Reference.force_at``, sampled at the stage times, see below), coordinate forces,
  springs and dampers as generalized forces; the scene's point forces, attractors and gravity
  compensation as ``ExternallyAppliedSpatialForce`` on the bodies. ``model_terms`` maps the same
  forces with Drake's own Jacobians (``CalcJacobianTranslationalVelocity``); M, bias and gravity
  are ``CalcMassMatrix``, ``CalcBiasTerm``, ``CalcGravityGeneralizedForces``; joint damping of the
  user's file is Drake's own reading (``Joint.default_damping_vector``), applied by Drake itself.
* **Integrator.** Classical RK4 in fixed steps on Drake's own time derivatives
  (``Diagram.CalcTimeDerivatives`` of the plant with the force system: the plant's state
  derivative, quaternion rates included, with u and every scene force evaluated at the stage's
  time and state), so its stages fall on the reference's h/2 grid like Pinocchio's and MuJoCo's
  and every stage reads an exact sample of u. Drake's own ``RungeKutta5Integrator`` was tried
  first: its stages (c = 1/5, 3/10, 4/5, 8/9) are off that grid, and solving the reference at
  h/90 to feed them exactly cost 45x the samples (overhead_crane 455 s; xarm7_elbow_height past
  the solve's memory bound). Measured order: 4 (``tests/python/test_drake.py``, docs/guide.md).
* **Coordinates** (:class:`DrakeMap`): Drake's quaternion floating joint has q = (qw, qx, qy, qz,
  x, y, z) and v = (world angular, world linear velocity); ours (w, x, y, z) with body-frame angular
  and world-frame linear velocity: v_drake = P v with R on the angular rows, d(R w)/dt = R dw/dt
  (no (dP/dt) v term). A ball joint's rpy is converted from and to our quaternion.
* **Refused** (:class:`~progmo.simulators.Unsupported`, the check becomes ``not_checked`` with the
  reason): loop closures and a URDF ``<mimic>`` on a moving joint that the scene declares ignored
  (one progmo models is a system row whose reaction the check supplies: removed from the file Drake
  reads, as MuJoCo's equality is): a continuous Drake plant holds no
  constraint ("Continuous time does not support constraints"; its M, bias and inverse dynamics
  ignore them silently, drake#24957), and a discrete SAP plant holds them only softly.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import pathlib
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from typing import Any

import numpy as np

from . import BlowUp, ExpressionForces, Unsupported, attractor_force, require_forces
from .replay import Reference, Replay, rot_wxyz
from .robot_file import FILE_FORCES, RobotFile

NAME = "drake"
ACC_LIMIT = 1e8
SUPPORTED = ("attractor", "spring", "damper", "gravcomp", "point_force", "coordinate_force",
             "supplied_reaction")


def version() -> str:
    from importlib.metadata import version as v

    return v("drake")


# --- the URDF Drake reads ------------------------------------------------------------------------
def _rpy_of(R: np.ndarray) -> np.ndarray:
    from pydrake.math import RollPitchYaw, RotationMatrix

    return np.asarray(RollPitchYaw(RotationMatrix(R)).vector())


def _origin(j: ET.Element) -> np.ndarray:
    """The joint's parent-to-joint transform (4 x 4) from its ``<origin>``."""
    from pydrake.math import RollPitchYaw

    o = j.find("origin")
    xyz = np.array([float(x) for x in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split()])
    rpy = np.array([float(x) for x in (o.get("rpy", "0 0 0") if o is not None else "0 0 0").split()])
    T = np.eye(4)
    T[:3, :3] = RollPitchYaw(_f64(rpy)).ToRotationMatrix().matrix()
    T[:3, 3] = xyz
    return T


def _lock(j: ET.Element, value: float) -> None:
    """Joint ``j`` -> a fixed joint at ``value`` (its motion composed into its origin)."""
    T = _origin(j)
    ax_el = j.find("axis")
    axis = np.array([float(x) for x in (ax_el.get("xyz", "1 0 0") if ax_el is not None else "1 0 0").split()])
    axis = axis / np.linalg.norm(axis)
    M = np.eye(4)
    if j.get("type") in ("revolute", "continuous"):
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        M[:3, :3] = np.eye(3) + np.sin(value) * K + (1 - np.cos(value)) * K @ K
    elif j.get("type") == "prismatic":
        M[:3, 3] = value * axis
    else:
        raise Unsupported(f"locked joint {j.get('name')!r} of type {j.get('type')!r} in Drake")
    T = T @ M
    for tag in ("origin", "axis", "limit", "dynamics", "mimic", "calibration", "safety_controller"):
        for e in j.findall(tag):
            j.remove(e)
    j.set("type", "fixed")
    rpy = _rpy_of(T[:3, :3])
    ET.SubElement(j, "origin", xyz=" ".join(repr(float(x)) for x in T[:3, 3]),
                  rpy=" ".join(repr(float(x)) for x in rpy))


def user_urdf(robot: RobotFile, locked: dict[str, float]) -> str:
    """The user's URDF as Drake reads it: no geometry (no inertia in it; mesh paths Drake cannot
    resolve), locked joints fixed; a ``<mimic>`` progmo models as a system row is removed (its
    reaction is supplied with u, as in MuJoCo and Pinocchio), one declared ignored on a moving
    joint is refused (module doc)."""
    modelled = {m["joint"] for m in robot.mimics}
    root = ET.fromstring(robot.path.read_text())
    for link in root.iter("link"):
        for tag in ("visual", "collision"):
            for e in link.findall(tag):
                link.remove(e)
    for j in root.iter("joint"):
        name = j.get("name", "")
        mimic = j.find("mimic")
        if name in locked:
            _lock(j, locked[name])
        elif mimic is not None and name in modelled:
            j.remove(mimic)  # the system row mimic_NAME: its reaction is supplied
        elif mimic is not None:
            raise Unsupported(f"the <mimic> of joint {name!r}: Drake turns it into a coupler constraint, "
                              "which a continuous plant does not hold (\"Continuous time does not support "
                              "constraints\"; its M and bias ignore it, drake#24957)")
    for tag in ("transmission", "gazebo"):
        for e in root.findall(tag):
            root.remove(e)
    return ET.tostring(root, encoding="unicode")


# --- coordinates ---------------------------------------------------------------------------------
_WXYZ = ("qw", "qx", "qy", "qz")


class DrakeMap:
    """Our q/v <-> Drake's (module doc). Built from the export report's names (``sim_joint`` and
    the component suffix) and the plant's joints."""

    def __init__(self, report: dict, plant: Any):
        self.nq, self.nv = len(report["q_map"]), len(report["v_map"])
        self.scalar_q: list[tuple[int, int]] = []  # (ours, drake)
        self.scalar_v: list[tuple[int, int]] = []
        #: (kind, our q idx {suffix: i}, our v idx {suffix: i}, drake q start, drake v start)
        self.groups: list[tuple[str, dict[str, int], dict[str, int], int, int]] = []
        byj_q: dict[str, dict[str, int]] = {}
        byj_v: dict[str, dict[str, int]] = {}
        for key, byj in (("q_map", byj_q), ("v_map", byj_v)):
            for c in report[key]:
                byj.setdefault(c["sim_joint"], {})[c["name"].rsplit(".", 1)[-1] if "." in c["name"] else ""] = c["index"]
        for jname, qi in byj_q.items():
            j = plant.GetJointByName(jname)
            vi = byj_v[jname]
            if j.num_positions() == 1 and j.num_velocities() == 1:
                self.scalar_q.append((next(iter(qi.values())), j.position_start()))
                self.scalar_v.append((next(iter(vi.values())), j.velocity_start()))
            elif j.type_name() in ("quaternion_floating", "ball_rpy"):
                self.groups.append((j.type_name(), qi, vi, j.position_start(), j.velocity_start()))
            else:
                raise Unsupported(f"joint {jname!r}: Drake's {j.type_name()} joint has no map to progmo's coordinates")
        self.sim_nq, self.sim_nv = plant.num_positions(), plant.num_velocities()
        if self.sim_nv != self.nv:
            raise ValueError(f"Drake's plant has nv={self.sim_nv}; the report {self.nv}")
        self.quats = [[qi[k] for k in _WXYZ] for _, qi, _, _, _ in self.groups]
        self._sq = np.array([a for a, _ in self.scalar_q], int), np.array([b for _, b in self.scalar_q], int)
        self._sv = np.array([a for a, _ in self.scalar_v], int), np.array([b for _, b in self.scalar_v], int)
        # per group, index arrays (the maps run at every replay stage): (ball?, our q wxyz, our q xyz,
        # our angular v, Drake q start, Drake v start)
        self._g = [(kind == "ball_rpy", np.array([qi[k] for k in _WXYZ]),
                    np.array([qi[k] for k in "xyz"] if kind == "quaternion_floating" else [], int),
                    _span([vi[k] for k in ("wx", "wy", "wz")]), iq, iv)
                   for kind, qi, vi, iq, iv in self.groups]
        # P's constant entries: the one-dof joints' permutation, a free joint's linear rows
        self._P0 = np.zeros((self.nv, self.nv))
        self._P0[self._sv[1], self._sv[0]] = 1.0
        for kind, _, vi, _, iv in self.groups:
            if kind == "quaternion_floating":
                for a, k in enumerate(("vx", "vy", "vz")):
                    self._P0[iv + 3 + a, vi[k]] = 1.0

    def q_to_sim(self, q: np.ndarray) -> np.ndarray:
        Quaternion, RollPitchYaw = _rotation_types()
        qs = np.zeros(self.sim_nq)
        qs[self._sq[1]] = q[self._sq[0]]
        for ball, qw, xyz, _, iq, _ in self._g:
            w = q[qw]
            w = w / np.sqrt(w.dot(w))  # (np.linalg.norm's own arithmetic, without its overhead)
            if ball:
                qs[iq:iq + 3] = RollPitchYaw(Quaternion(w)).vector()
            else:
                qs[iq:iq + 4] = w
                qs[iq + 4:iq + 7] = q[xyz]
        return qs

    def q_from_sim(self, qs: np.ndarray) -> np.ndarray:
        _, RollPitchYaw = _rotation_types()
        q = np.zeros(self.nq)
        q[self._sq[0]] = qs[self._sq[1]]
        for ball, qw, xyz, _, iq, _ in self._g:
            if ball:
                w = RollPitchYaw(_f64(qs[iq:iq + 3])).ToQuaternion().wxyz()
            else:
                w = qs[iq:iq + 4]
                w = w / np.sqrt(w.dot(w))
                q[xyz] = qs[iq + 4:iq + 7]
            q[qw] = w
        return q

    def P(self, q: np.ndarray) -> np.ndarray:
        """v_drake = P(q) v: the identity but R (body -> world) on the angular rows."""
        P = self._P0.copy()
        for _, qw, _, ang, _, iv in self._g:
            P[iv:iv + 3, ang] = rot_wxyz(*q[qw].tolist())
        return P

    def v_to_sim(self, q, v, P=None):
        """``P``: P(q) when the caller has it (one build per replay stage)."""
        if not self.groups:  # one-dof joints only: P is a permutation
            out = np.empty(self.nv)
            out[self._sv[1]] = v[self._sv[0]]
            return out
        return (self.P(q) if P is None else P) @ v

    def v_from_sim(self, q, vs, P=None):
        if not self.groups:
            out = np.empty(self.nv)
            out[self._sv[0]] = vs[self._sv[1]]
            return out
        return (self.P(q) if P is None else P).T @ vs  # P orthogonal

    f_to_sim = v_to_sim  # P^-T = P
    f_from_sim = v_from_sim

    def a_from_sim(self, q, v, a_sim):  # d(R w)/dt = R dw/dt: no (dP/dt) v term
        return self.v_from_sim(q, a_sim)

    def a_to_sim(self, q, v, a):
        return self.v_to_sim(q, a)


# --- the back-end --------------------------------------------------------------------------------
class DrakeBackend:
    name = NAME
    scheme = "RK4 on Drake's CalcTimeDerivatives (fixed step)"

    def __init__(self, doc: str, report: dict, scene=None, withhold: tuple[str, ...] = (),
                 robot: RobotFile | None = None):
        if report.get("closures"):
            names = ", ".join(c["name"] for c in report["closures"])
            raise Unsupported(f"loop closures ({names}): a continuous Drake plant holds no constraint "
                              "(\"Continuous time does not support constraints\"; M, bias and inverse "
                              "dynamics ignore them silently, drake#24957); a discrete SAP plant holds "
                              "them only softly")
        self._notes: list[str] = []
        self.route = "progmo export"
        if robot is not None and robot.fmt == "urdf":
            locked = dict(getattr(scene, "robot_file", None) and scene.robot_file.get("locked_joints", []) or [])
            missing = [j for j in robot.locked if j not in locked]
            locked.update({j: 0.0 for j in missing})
            urdf = user_urdf(robot, locked)
            self.route = "user's file"
            # the file's passive forces are Drake's own reading (joint damping)
            report = {**report, "harness_forces": [hf for hf in report.get("harness_forces", [])
                                                  if hf["kind"] not in FILE_FORCES]}
            self._notes.append(f"Drake reads the user's file {robot.path.name} (geometry removed"
                               + (f"; locked joints fixed: {', '.join(sorted(locked))}" if locked else "") + ")")
        else:
            urdf = doc
            if robot is not None:
                self._notes.append(
                    f"Drake reads progmo's URDF export, not the user's MJCF file {robot.path.name}: Drake's "
                    "MJCF parser places every joint but the last of a multi-joint body at the parent frame, "
                    "silently (34 % off in the mass matrix of mjcf_arm); MuJoCo and Pinocchio check the file "
                    "itself")
        require_forces(report, SUPPORTED, "Drake")
        self.report = report
        self._build(urdf, report)
        self.cm = DrakeMap(report, self.plant)
        self.expr = ExpressionForces(scene, report, withhold)
        self._harness_forces(urdf, report, withhold)
        self._ref: Reference | None = None
        self._dia: Any = None

    # -- construction
    def _build(self, urdf: str, report: dict) -> None:
        from pydrake.multibody.parsing import Parser
        from pydrake.multibody.plant import MultibodyPlant
        from pydrake.multibody.tree import BallRpyJoint, QuaternionFloatingJoint
        from pydrake.systems.framework import DiagramBuilder

        builder = DiagramBuilder()
        plant: Any = builder.AddSystem(MultibodyPlant(0.0))  # (pydrake's stubs: a System)
        parser = Parser(plant)
        with _parser_log() as said:  # Drake's parser warnings become the check's notes, not stderr
            (inst,) = parser.AddModelsFromString(urdf, "urdf")
        self._notes += [f"Drake's URDF parser ({n} x): {m}" if n > 1 else f"Drake's URDF parser: {m}"
                        for m, n in said.items()]
        rj = report.get("root_joint")
        if rj:
            root = _root_link(urdf)
            body = plant.GetBodyByName(root, inst)
            cls = BallRpyJoint if "Spherical" in rj["python"] else QuaternionFloatingJoint
            if "Spherical" not in rj["python"] and "FreeFlyer" not in rj["python"]:
                raise Unsupported(f"root joint {rj['python']} in Drake")
            plant.AddJoint(cls(rj["name"], plant.world_frame(), body.body_frame()))
            if cls is BallRpyJoint:
                self._notes.append("spherical root joint as Drake's BallRpyJoint (roll-pitch-yaw, singular "
                                   "at pitch +-pi/2): Drake 1.5x has no quaternion ball joint")
        elif not any(c.get("conversion") == "body_frame" for c in report["v_map"]):
            # a fixed base: weld the root link (Drake would make it a floating body; Pinocchio and
            # MuJoCo fix it to the world)
            for root in _root_links(urdf):
                plant.WeldFrames(plant.world_frame(), plant.GetBodyByName(root, inst).body_frame())
        for a in report.get("armature", []):
            j = plant.GetJointByName(a["joint"])
            if a["nv"] != 1:
                raise Unsupported(f"armature on the {a['nv']}-dof joint {a['joint']!r} in Drake "
                                  "(rotor inertia needs a one-dof joint actuator)")
            act = plant.AddJointActuator(a["joint"] + "__armature", j)
            act.set_default_rotor_inertia(float(a["armature"]))
            act.set_default_gear_ratio(1.0)
        plant.mutable_gravity_field().set_gravity_vector(np.array(report["gravity"], float))
        plant.Finalize()
        self.plant, self._builder, self._inst = plant, builder, inst
        self.ctx = plant.CreateDefaultContext()
        if plant.num_actuators():
            plant.get_actuation_input_port().FixValue(self.ctx, np.zeros(plant.num_actuators()))
        self.damping = np.zeros(plant.num_velocities())
        for i in range(plant.num_joints()):
            j = plant.get_joint(_JointIndex(i))
            if j.num_velocities():
                self.damping[j.velocity_start():j.velocity_start() + j.num_velocities()] = j.default_damping_vector()

    def _harness_forces(self, urdf: str, report: dict, withhold: tuple[str, ...]) -> None:
        """Springs and dampers (generalized, Drake's dofs), attractors and gravity compensation
        (world forces at the bodies' CoMs, from the URDF's inertials)."""
        coms = {}
        for link in ET.fromstring(urdf).iter("link"):
            o = link.find("inertial/origin")
            coms[link.get("name")] = np.array([float(x) for x in o.get("xyz", "0 0 0").split()]) \
                if o is not None else np.zeros(3)
        addr = {c["sim_joint"]: c["index"] for c in report["v_map"]}
        self.springs: list[tuple[int, int, float, float]] = []  # (our q index, our v index, k, ref)
        self.dampers: list[tuple[int, float]] = []
        self.attractors: list[tuple[np.ndarray, float, list[tuple[str, float]]]] = []
        self.gravcomp: list[tuple[str, np.ndarray]] = []
        qaddr = {c["sim_joint"]: c["index"] for c in report["q_map"]}
        for hf in report.get("harness_forces", []):
            if hf["kind"] in ("spring", "damper") and hf.get("nv", 1) != 1:
                raise Unsupported(f"a {hf['kind']} on the multi-dof joint {hf['joint']!r} in Drake")
            if hf["kind"] == "spring":
                self.springs.append((qaddr[hf["joint"]], addr[hf["joint"]], hf["stiffness"], hf["spring_ref"]))
            elif hf["kind"] == "damper":
                self.dampers.append((addr[hf["joint"]], hf["damping"]))
            elif hf["kind"] == "attractor" and "attractor" not in withhold:
                self.attractors.append((np.array(hf["point"], float), hf["mu"], list(hf["bodies"])))
            elif hf["kind"] == "gravcomp":
                g = np.array(report["gravity"], float)
                self.gravcomp.append((hf["body"], -hf["gravcomp"] * hf["mass"] * g))
        self.coms = coms
        self._bodies: dict[str, tuple[Any, Any]] = {}
        self._easf: list = []  # the replay's ExternallyAppliedSpatialForce objects, refilled per stage

    def notes(self) -> list[str]:
        return [f"Drake {version()}, continuous MultibodyPlant, RK4 in fixed steps on its CalcTimeDerivatives "
                "(u and every scene force at each stage from Drake's state)"
                + (f"; root joint {self.report['root_joint']['python']}" if self.report.get("root_joint") else "")
                ] + self._notes

    # -- forces at a state (Drake's coordinates)
    def _set(self, ctx: Any, qs: np.ndarray, vs: np.ndarray) -> None:
        self.plant.SetPositions(ctx, qs)
        self.plant.SetVelocities(ctx, vs)

    def _forces(self, t: float, qs: np.ndarray, vs: np.ndarray, ref: Reference | None, ctx: Any
                ) -> tuple[np.ndarray, list[tuple[str, np.ndarray, np.ndarray]]]:
        """(generalized force in Drake's dofs, [(body, world point, world force)]): u from ``ref``
        (None: without u), springs, dampers, coordinate forces; point forces, attractors, gravcomp.
        ``ctx``: a plant context holding (qs, vs) (the bodies' poses of attractors and gravcomp)."""
        cm = self.cm
        q = cm.q_from_sim(qs)
        P = cm.P(q) if cm.groups else None  # built once for both maps
        v = cm.v_from_sim(q, vs, P)
        f = np.zeros(cm.nv)  # ours
        if ref is not None:
            f += ref.force_at(t, q)
        for iq, iv, k, r in self.springs:
            f[iv] += -k * (q[iq] - r)
        for iv, c in self.dampers:
            f[iv] += -c * v[iv]
        pts: list[tuple[str, np.ndarray, np.ndarray]] = []
        gen, epts = self.expr.at(t, q, v)
        if gen is not None:
            f += gen
        pts += epts
        for point, mu, bodies in self.attractors:
            for b, mass in bodies:
                com = self._com_world(ctx, b)
                pts.append((b, com, attractor_force(point, mu, mass, com)))
        for b, force in self.gravcomp:
            pts.append((b, self._com_world(ctx, b), force))
        return cm.v_to_sim(q, f, P), pts  # f_to_sim: P^-T = P

    def _body(self, name: str) -> tuple[Any, Any]:
        """(body, its index) by name, looked up once (the replay asks at every stage)."""
        got = self._bodies.get(name)
        if got is None:
            body = self.plant.GetBodyByName(name, self._inst)
            got = self._bodies[name] = (body, body.index())
        return got

    def _com_world(self, ctx: Any, body: str) -> np.ndarray:
        X = self.plant.EvalBodyPoseInWorld(ctx, self._body(body)[0])
        return np.asarray(X.multiply(self.coms.get(body, _ORIGIN)))

    def _spatial(self, ctx: Any, pts: list) -> list:
        """The point forces as Drake's ExternallyAppliedSpatialForce (body frame point, world force).
        The objects are kept and refilled (the output's ``set_value`` copies them into Drake)."""
        SpatialForce, ExternallyAppliedSpatialForce = _spatial_types()
        while len(self._easf) < len(pts):
            self._easf.append(ExternallyAppliedSpatialForce())
        for e, (b, pw, fw) in zip(self._easf, pts):
            body, index = self._body(b)
            X = self.plant.EvalBodyPoseInWorld(ctx, body)
            e.body_index = index
            e.p_BoBq_B = X.inverse().multiply(np.asarray(pw, float))
            e.F_Bq_W = SpatialForce(_ORIGIN, _f64(fw))
        return self._easf[:len(pts)]

    def _points_generalized(self, pts: list) -> np.ndarray:
        """J^T f of the point forces by Drake's Jacobians at ``self.ctx``."""
        from pydrake.multibody.tree import JacobianWrtVariable

        plant, out = self.plant, np.zeros(self.cm.nv)
        for b, pw, fw in pts:
            body = self._body(b)[0]
            p_B = plant.EvalBodyPoseInWorld(self.ctx, body).inverse().multiply(np.asarray(pw, float))
            J = plant.CalcJacobianTranslationalVelocity(self.ctx, JacobianWrtVariable.kV, body.body_frame(),
                                                        p_B, plant.world_frame(), plant.world_frame())
            out += J.T @ np.asarray(fw, float)
        return out

    def _rhs_sim(self, t: float, qs: np.ndarray, vs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(M, every non-control generalized force) in Drake's dofs."""
        plant = self.plant
        self._set(self.ctx, qs, vs)
        f, pts = self._forces(t, qs, vs, None, self.ctx)
        M = plant.CalcMassMatrix(self.ctx)
        rhs = -plant.CalcBiasTerm(self.ctx) + plant.CalcGravityGeneralizedForces(self.ctx) \
            - self.damping * vs + f + self._points_generalized(pts)
        return M, rhs

    # -- the Backend protocol
    def model_terms(self, t, q, v):
        cm = self.cm
        M, rhs = self._rhs_sim(t, cm.q_to_sim(q), cm.v_to_sim(q, v))
        P = cm.P(q)
        return P.T @ M @ P, P.T @ rhs

    def closure_jacobian(self, t, q, v) -> np.ndarray:
        return np.zeros((0, self.cm.nv))

    def closure_forces(self, t, q, v, u) -> np.ndarray:
        return np.zeros(0)

    def instant_u(self, t, q, v, a, B, gamma, programme=None, actuated=False):
        """Ideal reaction of the programme rows with Drake's M and forces: M a = rhs + B^T lambda,
        B a = gamma (the KKT system); with actuators the inverse-dynamics force M a - rhs."""
        M, rhs = self.model_terms(t, q, v)
        if actuated:
            return M @ a - rhs
        n, s = M.shape[0], B.shape[0]
        K = np.block([[M, -B.T], [B, np.zeros((s, s))]])
        sol = np.linalg.lstsq(K, np.concatenate([rhs, gamma]), rcond=None)[0]
        return B.T @ sol[n:]

    def inverse_force(self, t, q, v, a) -> np.ndarray:
        """Drake's inverse dynamics (``CalcInverseDynamics`` with its gravity and the file's joint
        damping) minus the scene's other forces, in our coordinates."""
        from pydrake.multibody.tree import MultibodyForces

        cm, plant = self.cm, self.plant
        qs, vs = cm.q_to_sim(q), cm.v_to_sim(q, v)
        self._set(self.ctx, qs, vs)
        f, pts = self._forces(t, qs, vs, None, self.ctx)
        forces = MultibodyForces(plant)
        plant.CalcForceElementsContribution(self.ctx, forces)
        tau = plant.CalcInverseDynamics(self.ctx, cm.a_to_sim(q, v, a), forces)
        tau = tau - f - self._points_generalized(pts)  # (the force elements include joint damping)
        return cm.f_from_sim(q, tau)

    def unmodelled(self) -> list[dict]:
        return []

    def joint_ranges(self) -> dict[str, tuple[float, float]]:
        out = {}
        plant = self.plant
        for i in range(plant.num_joints()):
            j = plant.get_joint(_JointIndex(i))
            if j.num_positions() == 1:
                lo, hi = float(j.position_lower_limits()[0]), float(j.position_upper_limits()[0])
                if np.isfinite(lo) and np.isfinite(hi):
                    out[j.name()] = (lo, hi)
        return out

    # -- replay
    def _diagram(self) -> tuple[Any, Any, Any]:
        """(diagram, its context, a derivatives buffer): the plant fed by the force system. Built once."""
        if self._dia is None:
            self._dia = _make_diagram(self)
        return self._dia

    def replay(self, ref: Reference, frame_every: int = 0, start: int = 0, stop: int | None = None,
               x0: tuple[np.ndarray, np.ndarray] | None = None) -> Replay:
        cm = self.cm
        stop = ref.steps if stop is None else stop
        n = stop - start
        X = np.zeros((n + 1, cm.sim_nq + cm.nv))  # Drake's states and accelerations, mapped at the end
        A = np.zeros((n + 1, cm.nv))
        q0, v0 = (ref.q[2 * start], ref.v[2 * start]) if x0 is None else x0
        times = ref.t[::2][start: stop + 1]
        self._ref = ref
        self._stored = 0
        frames: list = []
        try:
            self._steps(ref, frame_every, X, A, frames, cm.q_to_sim(q0), cm.v_to_sim(q0, v0), start, times)
            return Replay(times, *self._ours(X, A), frames, frame_every)
        except BlowUp as e:
            j = self._stored
            e.partial = Replay(times[:j], *self._ours(X[:j], A[:j]), frames, frame_every)
            raise
        finally:
            self._ref = None

    def _ours(self, X: np.ndarray, A: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, v, a) in our coordinates of Drake's states ``X`` and accelerations ``A`` (rows)."""
        cm, nq = self.cm, self.cm.sim_nq
        if not cm.groups:  # a permutation: every row at once
            (sq, sq_sim), (sv, sv_sim) = cm._sq, cm._sv
            Q, V, Ao = np.zeros((len(X), cm.nq)), np.empty((len(X), cm.nv)), np.empty((len(X), cm.nv))
            Q[:, sq], V[:, sv], Ao[:, sv] = X[:, sq_sim], X[:, nq + sv_sim], A[:, sv_sim]
            return Q, V, Ao
        Q, V, Ao = np.zeros((len(X), cm.nq)), np.zeros((len(X), cm.nv)), np.zeros((len(X), cm.nv))
        for j, (x, a) in enumerate(zip(X, A)):
            Q[j] = q = cm.q_from_sim(x[:nq])
            P = cm.P(q)
            V[j] = cm.v_from_sim(q, x[nq:], P)
            Ao[j] = cm.v_from_sim(q, a, P)  # a_from_sim: d(R w)/dt = R dw/dt
        return Q, V, Ao

    def _steps(self, ref, frame_every, X, A, frames, qs, vs, start, times) -> None:
        """Classical RK4 (fixed step h) on Drake's x' = f(t, x): every stage sets the diagram's
        time and the plant's state, so the force system evaluates u and the scene's forces there.
        Fills ``X`` (states) and ``A`` (Drake's accelerations) row by row (``self._stored`` rows)."""
        diagram, dctx, derivs = self._diagram()
        plant = self.plant
        pctx = plant.GetMyMutableContextFromRoot(dctx)
        h, t0 = ref.h, ref.t0
        n = len(times) - 1
        nq = plant.num_positions()
        dvec = derivs.get_vector()

        def f(t: float, x: np.ndarray) -> np.ndarray:
            dctx.SetTime(t)
            plant.SetPositionsAndVelocities(pctx, x)
            diagram.CalcTimeDerivatives(dctx, derivs)
            return dvec.CopyToVector()

        x = np.concatenate([qs, vs])
        for j in range(n + 1):
            tk = t0 + (start + j) * h
            if not np.isfinite(x).all():
                raise BlowUp(tk, "non-finite state")
            k1 = f(tk, x)
            a = k1[nq:]
            if not (np.abs(a) < ACC_LIMIT).all():
                big = float(np.abs(a).max()) if np.isfinite(a).all() else float("inf")
                raise BlowUp(tk, f"|ddq| = {big:.3g} > {ACC_LIMIT:g} (or non-finite)", big, ACC_LIMIT)
            X[j], A[j] = x, a
            self._stored = j + 1
            if frame_every and (start + j) % frame_every == 0:  # f(tk, x) has set the plant's state
                frames.append((tk, self._body_poses(pctx)))
            if j == n:
                break
            k2 = f(tk + 0.5 * h, x + 0.5 * h * k1)
            k3 = f(tk + 0.5 * h, x + 0.5 * h * k2)
            k4 = f(tk + h, x + h * k3)
            x = x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)

    def _body_poses(self, ctx: Any) -> list:
        """(name, world position, quaternion w x y z) of every body of the robot at ``ctx``."""
        plant, out = self.plant, []
        for i in plant.GetBodyIndices(self._inst):
            body = plant.get_body(i)
            X = plant.EvalBodyPoseInWorld(ctx, body)
            qt = X.rotation().ToQuaternion()
            out.append((body.name(), np.array(X.translation()), np.array([qt.w(), qt.x(), qt.y(), qt.z()])))
        return out


@contextlib.contextmanager
def _parser_log() -> Iterator[dict[str, int]]:
    """Collect what Drake logs (its ``drake`` Python logger) while the block runs: {message without
    the file position: count}; nothing reaches stderr meanwhile."""
    said: dict[str, int] = {}

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            m = re.sub(r"^<literal-string>\.urdf:\d+: (warning: )?", "", record.getMessage())
            said[m] = said.get(m, 0) + 1

    log, keep = logging.getLogger("drake"), Keep()
    log.addHandler(keep)
    propagate, log.propagate = log.propagate, False
    try:
        yield said
    finally:
        log.removeHandler(keep)
        log.propagate = propagate


@functools.cache
def _rotation_types() -> tuple[Any, Any]:
    """(Quaternion, RollPitchYaw), imported once (as :func:`_spatial_types`)."""
    from pydrake.common.eigen_geometry import Quaternion
    from pydrake.math import RollPitchYaw

    return Quaternion, RollPitchYaw


@functools.cache
def _spatial_types() -> tuple[Any, Any]:
    """(SpatialForce, ExternallyAppliedSpatialForce), imported once (pydrake's lazy module lookup
    costs microseconds a call, and the replay needs them at every stage)."""
    from pydrake.multibody.math import SpatialForce
    from pydrake.multibody.plant import ExternallyAppliedSpatialForce

    return SpatialForce, ExternallyAppliedSpatialForce


#: a body's origin, and a zero torque (read only)
_ORIGIN = np.zeros(3)
_ORIGIN.flags.writeable = False


def _span(idx: list[int]) -> Any:
    """Consecutive indices as a slice (a view, cheaper to assign through), else an index array."""
    return slice(idx[0], idx[0] + len(idx)) if idx == list(range(idx[0], idx[0] + len(idx))) else np.array(idx)


def _f64(x: Any) -> Any:
    """A float array (typed Any: pydrake's stubs spell ndarray[float64] unsatisfiably)."""
    return np.asarray(x, float)


def _JointIndex(i: int) -> Any:
    from pydrake.multibody.tree import JointIndex

    return JointIndex(i)


def _root_links(urdf: str) -> list[str]:
    """Links no joint attaches (besides ``world``)."""
    root = ET.fromstring(urdf)
    children = {c.get("link") for j in root.iter("joint") if (c := j.find("child")) is not None}
    links = [link.get("name") for link in root.iter("link") if link.get("name") != "world"]
    return [str(n) for n in links if n not in children]


def _root_link(urdf: str) -> str:
    free = _root_links(urdf)
    if len(free) != 1:
        raise ValueError(f"URDF has {len(free)} root links ({', '.join(map(str, free))}); expected one")
    return str(free[0])


def _make_diagram(be: DrakeBackend) -> tuple[Any, Any, Any]:
    """The plant with a force system on its applied-force inputs (module doc), the diagram's
    context and a derivatives buffer for the RK4 replay."""
    from pydrake.common.value import AbstractValue
    from pydrake.multibody.plant import ExternallyAppliedSpatialForce
    from pydrake.systems.framework import LeafSystem

    plant: Any = be.plant
    builder = be._builder
    nx, nv = plant.num_multibody_states(), plant.num_velocities()
    nq = plant.num_positions()
    # the plant's own context in the diagram's (set below): the callbacks read the bodies' poses there,
    # where Drake has set the stage's state (no second context to set and recompute)
    plant_ctx: list[Any] = []
    cache: dict[str, Any] = {"key": None, "ref": None}  # the last stage's forces
    # no point force, attractor or gravity compensation: the spatial input stays unconnected (empty)
    points = bool(be.attractors or be.gravcomp or be.expr.points and be.expr.active)

    class Feed(LeafSystem):
        def __init__(self) -> None:
            super().__init__()
            self._x: Any = self.DeclareVectorInputPort("x", nx)
            self.DeclareVectorOutputPort("tau", nv, self._tau)
            if points:
                self.DeclareAbstractOutputPort(
                    "spatial", lambda: AbstractValue.Make([ExternallyAppliedSpatialForce()]), self._spatial)

        def at(self, ctx: Any) -> tuple[np.ndarray, list]:
            """The stage's forces, computed once for both outputs."""
            x = self._x.Eval(ctx)
            t = ctx.get_time()
            if not points:  # the one output: nothing to share
                return be._forces(t, x[:nq], x[nq:], be._ref, plant_ctx[0])
            key = (t, x.tobytes())
            if cache["key"] != key or cache["ref"] is not be._ref:
                assert be._ref is not None
                cache["key"], cache["ref"] = key, be._ref
                cache["val"] = be._forces(t, x[:nq], x[nq:], be._ref, plant_ctx[0])
            return cache["val"]

        def _tau(self, ctx, out):
            out.SetFromVector(self.at(ctx)[0])

        def _spatial(self, ctx, out):
            out.set_value(be._spatial(plant_ctx[0], self.at(ctx)[1]))

    feed = builder.AddSystem(Feed())
    builder.Connect(plant.get_state_output_port(), feed.get_input_port(0))
    builder.Connect(feed.get_output_port(0), plant.get_applied_generalized_force_input_port())
    if points:
        builder.Connect(feed.get_output_port(1), plant.get_applied_spatial_force_input_port())
    diagram = builder.Build()
    dctx = diagram.CreateDefaultContext()
    plant_ctx.append(plant.GetMyContextFromRoot(dctx))
    if plant.num_actuators():
        plant.get_actuation_input_port().FixValue(plant.GetMyMutableContextFromRoot(dctx),
                                                  np.zeros(plant.num_actuators()))
    return diagram, dctx, diagram.AllocateTimeDerivatives()

def mjcf_parity(path: str, report: dict, q: np.ndarray) -> np.ndarray:
    """Drake's mass matrix of an MJCF file read by Drake's own MJCF parser, in our coordinates
    (one-dof joints matched by name): the negative control of the route Drake does not take."""
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant

    plant: Any = MultibodyPlant(0.0)
    Parser(plant).AddModels(pathlib.Path(path))
    plant.Finalize()
    ctx = plant.CreateDefaultContext()
    cm = DrakeMap({**report, "root_joint": None}, plant)
    plant.SetPositions(ctx, cm.q_to_sim(q))
    M = plant.CalcMassMatrix(ctx)
    return cm.P(q).T @ M @ cm.P(q)

