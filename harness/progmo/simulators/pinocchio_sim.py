"""Pinocchio 4.1 back-end: the scene's URDF export, a harness RK4 with ``pin.aba`` as the
acceleration oracle, Lie-group-correct (RKMK4 with ``dexpinv = inv(dIntegrate(.., ARG1))``) when the
model has ball or free joints; springs, dampers and attractors applied by the harness from
Pinocchio's own state as the export report prescribes; the scene's point forces as Pinocchio
external forces (``fext``, one spatial force per joint in its local frame) through ``aba`` and
``rnea``, its coordinate forces added to tau.

Loop closures (the report's ``closures``; URDF cannot carry them): one ``pin.RigidConstraintModel``
per closure between the frames of its two sites (``CONTACT_3D`` point, ``CONTACT_6D`` weld,
``LOCAL_WORLD_ALIGNED`` rows; a world side is joint 0 at the report's point), and the replay's
acceleration oracle is ``pin.constraintDynamics`` (``initConstraintDynamics`` once,
``ProximalSettings`` of :data:`PROX`) instead of ``aba``, with u (and every scene force, point
forces mapped through ``rnea`` with ``fext``) applied at every RK4 stage. Baumgarte gains
:data:`BAUMGARTE` (Kp, Kd) = (0, 0): the closures drift only with the RK4 error, which the replay
metrics then measure (Pinocchio solves J a = -gamma exactly at every stage)."""

from __future__ import annotations

import os
import tempfile
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin

from . import BlowUp, ExpressionForces, Unsupported, attractor_force, require_forces
from .replay import CoordMap, Reference, Replay
from .robot_file import FILE_FORCES, PinFile, RobotFile, name_report, pinocchio_model

ACC_LIMIT = 1e8
NAME = "pinocchio"

#: root joints the export may ask for (the report's Python expression -> constructor)
ROOT_JOINTS = {
    "pin.JointModelSpherical()": lambda: pin.JointModelSpherical(),
    "pin.JointModelFreeFlyer()": lambda: pin.JointModelFreeFlyer(),
}


def version() -> str:
    return pin.__version__


#: (``supplied_reaction``: the reference's force_at carries it, like u)
SUPPORTED = ("attractor", "spring", "damper", "gravcomp", "point_force", "coordinate_force",
             "supplied_reaction")

#: proximal solver of constraintDynamics: absolute and relative accuracy, mu, iterations. mu > 0
#: regularises the rows a planar loop's spatial closure leaves without gradient (the solver sets
#: them aside); the iterations refine the solution to the accuracy.
PROX = (1e-13, 1e-13, 1e-8, 50)
#: Baumgarte corrector gains (Kp, Kd) of the closure constraint models: none (see the module doc)
BAUMGARTE = (0.0, 0.0)
#: Pinocchio's contact type of each closure kind (distance: no constraint model in Pinocchio 4.1)
CONTACT = {"point": "CONTACT_3D", "weld": "CONTACT_6D"}


def _se3(point, quat_wxyz) -> "pin.SE3":
    w, x, y, z = quat_wxyz
    return pin.SE3(pin.Quaternion(w, x, y, z).normalized().toRotationMatrix(), np.array(point, float))


class PinocchioBackend:
    name = NAME

    def __init__(self, doc: str, report: dict, scene=None, withhold: tuple[str, ...] = (),
                 robot: RobotFile | None = None):
        """``robot``: build the model from the user's robot file (``robot_file``), not ``doc``."""
        if robot is not None:  # the file's own passive forces come from the simulator's reading
            report = {**report, "harness_forces": [hf for hf in report.get("harness_forces", [])
                                                  if hf["kind"] not in FILE_FORCES]}
        require_forces(report, SUPPORTED, "Pinocchio")
        self.file: PinFile | None = None
        self._fast = False  # set per replay: u is the only force (_u_only)
        report = self._load_model(doc, report, robot)
        self.route = "user's file" if robot is not None else "progmo export"
        self.report = report
        self.cm = CoordMap(report)
        self.expr = ExpressionForces(scene, report, withhold)
        self._withhold = withhold
        model = self.model
        model.gravity.linear = np.array(report["gravity"], float)
        if model.nq != self.cm.nq_sim or model.nv != self.cm.nv:
            raise ValueError(f"URDF has nq={model.nq}, nv={model.nv}; report {self.cm.nq_sim}, {self.cm.nv}")
        self.lie = model.nq != model.nv
        self._harness_forces(doc, report, robot, withhold)
        self.data = model.createData()
        self._closures(report.get("closures", []))
        sites = {c[k] for c in report.get("closures", []) for k in ("site_a", "site_b")}
        self.body_frames = [(f.name, i) for i, f in enumerate(model.frames)
                            if f.type == pin.FrameType.BODY and f.name != "universe" and f.name not in sites]
        #: our body name -> the Pinocchio joint that carries its link
        self.body_joint = {name: model.frames[i].parentJoint for name, i in self.body_frames}

    def _load_model(self, doc: str, report: dict, robot: RobotFile | None) -> dict:
        """``self.model`` from the user's robot file (``self.file``; the report then names its
        coordinates) or from the exported URDF ``doc`` (with the report's root joint and armature);
        the report the rest reads."""
        rj = report.get("root_joint")
        if robot is not None:
            if rj and rj["python"] != "pin.JointModelFreeFlyer()":
                raise Unsupported(f"root joint {rj['python']} over a robot file")
            self.file = pinocchio_model(robot, report["gravity"], rj)
            self.model = self.file.model
            report = name_report(report, self.file.addr)
            report["sim_q_offset"] = self.file.q_offset
            report["sim_unbounded"] = self.file.unbounded
            report["sim_planar"] = self.file.planar
            return report
        fd, path = tempfile.mkstemp(suffix=".urdf")
        try:
            with os.fdopen(fd, "w") as f:
                f.write(doc)
            if rj:
                if rj["python"] not in ROOT_JOINTS:
                    raise ValueError(f"unknown root joint {rj['python']!r}")
                self.model = pin.buildModelFromUrdf(path, ROOT_JOINTS[rj["python"]](), rj["name"])
            else:
                self.model = pin.buildModelFromUrdf(path)
        finally:
            os.unlink(path)
        # URDF has no armature: the export report lists it for model.armature (crba, rnea and
        # aba add it to the mass matrix diagonal)
        for a in report.get("armature", []):
            self.model.armature[a["sim_v"]:a["sim_v"] + a["nv"]] = a["armature"]
        return report

    def _harness_forces(self, doc: str, report: dict, robot: RobotFile | None, withhold: tuple[str, ...]) -> None:
        """The export report's harness forces: attractors and gravity compensation at operational
        frames on the bodies' CoMs (added to the model), springs and dampers."""
        model = self.model
        if robot is not None and robot.fmt == "mjcf" and any(
                hf["kind"] == "attractor" for hf in report.get("harness_forces", [])):
            raise Unsupported("attractors over an MJCF robot file in Pinocchio (no CoM frames)")
        coms = {}
        for link in ET.fromstring(doc if robot is None else robot.path.read_text()).iter("link"):
            o = link.find("inertial/origin")
            coms[link.get("name")] = np.array([float(x) for x in o.get("xyz", "0 0 0").split()]) \
                if o is not None else np.zeros(3)
        com_frames: dict[str, int] = {}

        def com_frame(b: str) -> int:
            """An operational frame at body b's CoM (one per body, shared by its forces)."""
            if b not in com_frames:
                fid = model.getFrameId(b, pin.FrameType.BODY)
                fr = model.frames[fid]
                place = fr.placement * pin.SE3(np.eye(3), coms.get(b, np.zeros(3)))
                com_frames[b] = model.addFrame(pin.Frame(b + "__com", fr.parentJoint, fid, place,
                                                         pin.FrameType.OP_FRAME))
            return com_frames[b]
        self.attractors = []
        self.springs = []
        self.dampers = []
        #: (CoM frame, world force -gravcomp m g): a body's gravity compensation (export report)
        self.gravcomp: list[tuple[int, np.ndarray]] = []
        for hf in report.get("harness_forces", []):
            if hf["kind"] == "attractor":
                bodies = [(com_frame(b), mass) for b, mass in hf["bodies"]]
                self.attractors.append((np.array(hf["point"], float), hf["mu"], bodies))
            elif hf["kind"] == "gravcomp":
                g = np.array(report["gravity"], float)
                self.gravcomp.append((com_frame(hf["body"]), -hf["gravcomp"] * hf["mass"] * g))
            elif hf["kind"] == "spring":
                self.springs.append((hf["sim_q"], hf["sim_v"], hf["stiffness"], hf["spring_ref"]))
            elif hf["kind"] == "damper":
                self.dampers.append((hf["sim_v"], hf["nv"], hf["damping"]))
        if "attractor" in withhold:
            self.attractors = []


    def _closures(self, closures: list[dict]) -> None:
        """Constraint models of the loop closures (module doc)."""
        model = self.model
        self.cmodels = pin.StdVec_RigidConstraintModel()
        self.closure_rows: list[tuple[str, int]] = []  # (closure, row count) in model order
        for c in closures:
            if c["kind"] not in CONTACT:
                raise Unsupported(f"Pinocchio has no constraint model for the {c['kind']} closure "
                                  f"{c['name']!r} (RigidConstraintModel: CONTACT_3D and CONTACT_6D only)")

            def side(site: str, body, point, quat):
                if model.existFrame(site):  # the export's site frame
                    fr = model.frames[model.getFrameId(site)]
                    return fr.parentJoint, fr.placement
                if body is None:
                    return 0, _se3(point, quat)
                # the user's robot file: the point on the body's own frame
                if not model.existFrame(body, pin.FrameType.BODY):
                    raise Unsupported(f"closure {c['name']!r}: body {body!r} is not a body of Pinocchio's "
                                      "reading of the file")
                fr = model.frames[model.getFrameId(body, pin.FrameType.BODY)]
                return fr.parentJoint, fr.placement * _se3(point, quat)
            j1, p1 = side(c["site_a"], c["body_a"], c["point_a"], c["quat_a"])
            j2, p2 = side(c["site_b"], c["body_b"], c["point_b"], c["quat_b"])
            cm = pin.RigidConstraintModel(getattr(pin.ContactType, CONTACT[c["kind"]]), model, j1, p1, j2, p2,
                                          pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            cm.name = c["name"]
            bp = cm.m_baumgarte_parameters if hasattr(cm, "m_baumgarte_parameters") else None
            if bp is not None:
                bp.Kp, bp.Kd = BAUMGARTE
            self.cmodels.append(cm)
            self.closure_rows.append((c["name"], 3 if c["kind"] == "point" else 6))
        self.cdatas = pin.StdVec_RigidConstraintData()
        for cm in self.cmodels:
            self.cdatas.append(cm.createData())
        self.prox = pin.ProximalSettings(*PROX)
        if len(self.cmodels):
            pin.initConstraintDynamics(model, self.data, self.cmodels, self.cdatas)

    def notes(self) -> list[str]:
        oracle = "pin.constraintDynamics (closures: " + ", ".join(
            f"{n} {'CONTACT_3D' if k == 3 else 'CONTACT_6D'}" for n, k in self.closure_rows) + \
            f"; proximal accuracy {PROX[0]:g}, mu {PROX[2]:g}; Baumgarte Kp, Kd = {BAUMGARTE})" \
            if len(self.cmodels) else "pin.aba"
        s = f"Pinocchio {pin.__version__}, harness RK4{' (RKMK4, Lie group)' if self.lie else ''} with {oracle}"
        if self.report.get("root_joint"):
            s += f"; root joint {self.report['root_joint']['python']}"
        return [s] + (self.file.notes if self.file is not None else [])

    def harness(self, qs, vs) -> np.ndarray:
        model, data = self.model, self.data
        f = np.zeros(model.nv) if self.file is None else self._file_passive(qs, vs)
        for iq, iv, k, ref in self.springs:
            f[iv] += -k * (qs[iq] - ref)
        for iv, n, c in self.dampers:
            f[iv:iv + n] += -c * vs[iv:iv + n]
        if self.attractors or self.gravcomp:
            pin.computeJointJacobians(model, data, qs)
            pin.updateFramePlacements(model, data)

            def at_com(fid: int, force: np.ndarray) -> np.ndarray:
                """J_com^T f: a world force at the CoM frame's origin as a generalized force."""
                J = pin.getFrameJacobian(model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
                return J[:3].T @ force
            for point, mu, bodies in self.attractors:
                for fid, mass in bodies:
                    f += at_com(fid, attractor_force(point, mu, mass, data.oMf[fid].translation))
            for fid, force in self.gravcomp:
                f += at_com(fid, force)
        return f

    def _file_passive(self, qs, vs) -> np.ndarray:
        """The robot file's passive forces Pinocchio's dynamics leaves out (robot_file module doc):
        -damping v (its own model.damping), springs -k (q - springref), gravcomp J_com^T (-gc m g)."""
        pf, model, data = self.file, self.model, self.data
        assert pf is not None
        f = -pf.damping * vs
        for iq, iv, k, ref in pf.springs:
            f[iv] += -k * (qs[iq] - ref)
        if pf.gravcomp:
            pin.computeJointJacobians(model, data, qs)
            pin.updateFramePlacements(model, data)
            for fid, com, mg in pf.gravcomp:
                J = pin.getFrameJacobian(model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
                r = data.oMf[fid].rotation @ com  # CoM offset from the frame origin, world axes
                Jc = J[:3] - pin.skew(r) @ J[3:]
                f += Jc.T @ (-mg * model.gravity.linear)
        return f

    def expression(self, t, qs, vs):
        """The scene's expression forces at Pinocchio's state: (fext or None, generalized force of
        the coordinate forces in Pinocchio's dofs). A world force f at world point p is the spatial
        force (f, p x f) about the world origin, moved into each joint's local frame (oMi^-1)."""
        f = np.zeros(self.model.nv)
        if not self.expr.active:
            return None, f
        q = self.cm.q_from_sim(qs)
        gen, pts = self.expr.at(t, q, self.cm.v_from_sim(q, vs))
        if gen is not None:
            f += self.cm.f_to_sim(q, gen)
        if not pts:
            return None, f
        pin.forwardKinematics(self.model, self.data, qs)
        fext = [pin.Force.Zero() for _ in range(self.model.njoints)]
        for body, pw, fw in pts:
            j = self.body_joint[body]
            fext[j] += self.data.oMi[j].actInv(pin.Force(fw, np.cross(pw, fw)))
        return fext, f

    def _external(self, t, qs, vs):
        """Generalized force of the expression forces, by Pinocchio's own mapping: the difference of
        rnea with and without fext, plus the coordinate forces."""
        fext, f = self.expression(t, qs, vs)
        if fext is not None:
            z = np.zeros(self.model.nv)
            f = f + pin.rnea(self.model, self.data, qs, vs, z) - pin.rnea(self.model, self.data, qs, vs, z, fext)
        return f

    def model_terms(self, t, q, v):
        model, data, cm = self.model, self.data, self.cm
        qs, vs = cm.q_to_sim(q), cm.v_to_sim(q, v)
        M = pin.crba(model, data, qs)
        M = np.triu(M) + np.triu(M, 1).T
        b = pin.rnea(model, data, qs, vs, np.zeros(model.nv))
        rhs_sim = -b + self.harness(qs, vs) + self._external(t, qs, vs)
        P = cm.P(q)
        return P.T @ M @ P, P.T @ (rhs_sim - M @ cm.Pdot_v(q, v))

    def closure_jacobian(self, t, q, v) -> np.ndarray:
        """Pinocchio's Jacobian of the closure constraints (rows in model order) in OUR v."""
        if not len(self.cmodels):
            return np.zeros((0, self.cm.nv))
        qs = self.cm.q_to_sim(q)
        pin.computeJointJacobians(self.model, self.data, qs)  # includes forward kinematics
        for cmod, cdat in zip(self.cmodels, self.cdatas):
            cmod.calc(self.model, self.data, cdat)  # the contact placements oMc1, oMc2
        J = pin.getConstraintsJacobian(self.model, self.data, self.cmodels, self.cdatas)
        return np.asarray(J) @ self.cm.P(q)

    def closure_forces(self, t, q, v, u) -> np.ndarray:
        """The closures' multipliers (contact forces, rows in model order) of constraintDynamics
        under the control force u (our coordinates) at (t, q, v)."""
        qs, vs = self.cm.q_to_sim(q), self.cm.v_to_sim(q, v)
        tau = self.cm.f_to_sim(q, u) + self.harness(qs, vs) + self._external(t, qs, vs)
        pin.constraintDynamics(self.model, self.data, qs, vs, tau, self.cmodels, self.cdatas, self.prox)
        return np.concatenate([np.asarray(d.contact_force.vector if k == 6 else d.contact_force.linear)
                               for d, (_, k) in zip(self.cdatas, self.closure_rows)])

    def instant_u(self, t, q, v, a, B, gamma, programme=None, actuated=False):
        """Ideal reaction of the programme rows (B a = gamma in our coordinates) by Pinocchio's
        constrained dynamics: J a_sim + gamma_pin = 0 with J = B P^T, gamma_pin = -(gamma + J Pdv).
        With closures (``programme``: the programme rows' indices in B): the force Pinocchio's
        inverse dynamics needs for a (rnea) split over Pinocchio's own closure Jacobian and our
        programme rows (least squares), u = B_p^T lambda_p. With actuators (``actuated``, servo-
        constraints: u = H tau is not a reaction of the rows): the inverse-dynamics force itself."""
        model, data, cm = self.model, self.data, self.cm
        if len(self.cmodels) or actuated:
            qs, vs = cm.q_to_sim(q), cm.v_to_sim(q, v)
            f = pin.rnea(model, data, qs, vs, cm.a_to_sim(q, v, a)) - self.harness(qs, vs) \
                - self._external(t, qs, vs)
            total = cm.f_from_sim(q, f)
            if not len(self.cmodels):
                return total
            Bp = B[programme] if programme is not None else B[:0]
            Jc = self.closure_jacobian(t, q, v)
            lam = np.linalg.lstsq(np.vstack([Jc, Bp]).T, total, rcond=None)[0]
            return Bp.T @ lam[len(Jc):]
        qs, vs = cm.q_to_sim(q), cm.v_to_sim(q, v)
        P = cm.P(q)
        J = np.ascontiguousarray(B @ P.T)
        g = -(gamma + J @ cm.Pdot_v(q, v))
        tau0 = self.harness(qs, vs) + self._external(t, qs, vs)
        pin.forwardDynamics(model, data, qs, vs, tau0, J, g, 0.0)
        lam = np.array(data.lambda_c).copy()
        return cm.f_from_sim(q, J.T @ lam)

    def inverse_force(self, t, q, v, a) -> np.ndarray:
        """The control force Pinocchio's inverse dynamics needs for dv/dt = a at (t, q, v), our
        coordinates: rnea (M with armature, bias) minus the passive and the scene's other forces."""
        cm = self.cm
        qs, vs = cm.q_to_sim(q), cm.v_to_sim(q, v)
        f = pin.rnea(self.model, self.data, qs, vs, cm.a_to_sim(q, v, a)) - self.harness(qs, vs) \
            - self._external(t, qs, vs)
        return cm.f_from_sim(q, f)

    def unmodelled(self) -> list[dict]:
        """Elements of Pinocchio's reading of a robot file progmo does not model: dry friction
        (model.friction), mimic joints; for MJCF also tendons and equalities (MuJoCo's compilation
        of the file: Pinocchio's reader skips them)."""
        if self.file is None:
            return []
        model, out = self.model, []
        by_v = {iv: n for n, (_, iv) in self.file.addr.items()}
        for i, f in enumerate(np.asarray(model.friction)):
            if f != 0.0:
                out.append({"kind": "frictionloss", "element": f"joint {by_v.get(i, i)} friction {f:g}",
                            "location": "Pinocchio's reading"})
        if len(model.mimicking_joints):
            out.append({"kind": "mimic", "element": "mimic joints " + ", ".join(
                model.names[j] for j in model.mimicking_joints), "location": "Pinocchio's reading"})
        out += self.file.skipped
        return out

    def joint_ranges(self) -> dict[str, tuple[float, float]]:
        """Finite position limits of Pinocchio's one-dof joints."""
        lo, hi = np.asarray(self.model.lowerPositionLimit), np.asarray(self.model.upperPositionLimit)
        out = {}
        for n, (iq, _) in self.file.addr.items() if self.file is not None else ():
            if iq < len(lo) and np.isfinite(lo[iq]) and np.isfinite(hi[iq]) and abs(lo[iq]) < 1e300:
                out[n] = (float(lo[iq]), float(hi[iq]))
        return out

    def _u_only(self) -> bool:
        """No force but u at a stage: no harness or file passive force, no expression force."""
        return (self.file is None and not (self.springs or self.dampers or self.attractors or self.gravcomp)
                and not self.expr.active)

    def _acc(self, t, qs, vs, ref):
        q = self.cm.q_from_sim(qs)
        if self._fast:  # the sum below with its zero terms left out (the same numbers)
            fext, tau = None, self.cm.f_to_sim(q, ref.force_at(t, q))
        else:
            fext, fc = self.expression(t, qs, vs)
            tau = self.cm.f_to_sim(q, ref.force_at(t, q)) + self.harness(qs, vs) + fc
        if len(self.cmodels):
            if fext is not None:  # point forces by Pinocchio's own mapping J^T f (rnea difference)
                z = np.zeros(self.model.nv)
                tau = tau + pin.rnea(self.model, self.data, qs, vs, z) \
                    - pin.rnea(self.model, self.data, qs, vs, z, fext)
            a = pin.constraintDynamics(self.model, self.data, qs, vs, tau, self.cmodels, self.cdatas,
                                       self.prox)
        elif fext is None:
            a = pin.aba(self.model, self.data, qs, vs, tau)
        else:
            a = pin.aba(self.model, self.data, qs, vs, tau, fext)
        if not (np.abs(a) < ACC_LIMIT).all():
            big = float(np.abs(a).max()) if np.isfinite(a).all() else float("inf")
            raise BlowUp(t, f"|ddq| = {big:.3g} > {ACC_LIMIT:g} (or non-finite)", big, ACC_LIMIT)
        return np.array(a)

    def _dth(self, qs, th, vs):
        if not self.lie:
            return vs
        Jd = pin.dIntegrate(self.model, qs, th, pin.ArgumentPosition.ARG1)
        return np.linalg.solve(Jd, vs)

    def replay(self, ref: Reference, frame_every: int = 0, start: int = 0, stop: int | None = None,
               x0: tuple[np.ndarray, np.ndarray] | None = None) -> Replay:
        """Steps ``start`` .. ``stop`` (default: the whole reference) from the reference's state at
        step ``start`` (``x0`` = (q, v): from that state instead: the Lyapunov probe)."""
        cm = self.cm
        stop = ref.steps if stop is None else stop
        n = stop - start
        nq, nv = cm.nq, cm.nv
        Q = np.zeros((n + 1, nq))
        V = np.zeros((n + 1, nv))
        A = np.zeros((n + 1, nv))
        frames: list = []
        q0, v0 = (ref.q[2 * start], ref.v[2 * start]) if x0 is None else x0
        qs = cm.q_to_sim(q0)
        vs = cm.v_to_sim(q0, v0)
        times = ref.t[::2][start: stop + 1]
        self._fast = self._u_only()
        self._q_start = np.asarray(q0, float)
        try:
            return self._steps(ref, frame_every, Q, V, A, frames, qs, vs, start, times)
        except BlowUp as e:  # keep the evidence: the samples stored before the blow-up
            j = self._stored
            e.partial = Replay(times[:j], Q[:j], V[:j], A[:j], frames, frame_every)
            raise

    def _steps(self, ref: Reference, frame_every, Q, V, A, frames, qs, vs, start, times) -> Replay:
        """The RKMK4 steps of ``replay``: Q, V, A filled in place, ``_stored`` of them so far."""
        model, data, cm = self.model, self.data, self.cm
        h, t0 = ref.h, ref.t0
        n = len(times) - 1
        integ = pin.integrate
        self._stored = 0
        for j in range(n + 1):
            k = start + j
            tk = t0 + k * h
            if not (np.isfinite(qs).all() and np.isfinite(vs).all()):
                raise BlowUp(tk, "non-finite state")
            a1 = self._acc(tk, qs, vs, ref)
            qo = cm.q_from_sim(qs, Q[j - 1] if j else self._q_start)
            Q[j], V[j] = qo, cm.v_from_sim(qo, vs)
            A[j] = cm.a_from_sim(qo, V[j], a1)
            self._stored = j + 1
            if frame_every and k % frame_every == 0:
                pin.framesForwardKinematics(model, data, qs)
                frames.append((tk, [(name, data.oMf[i].translation.copy(),
                                     _wxyz(data.oMf[i].rotation)) for name, i in self.body_frames]))
            if j == n:
                break
            d1 = vs
            th = 0.5 * h * d1
            v2 = vs + 0.5 * h * a1
            q2 = integ(model, qs, th)
            a2 = self._acc(tk + 0.5 * h, q2, v2, ref)
            d2 = self._dth(qs, th, v2)
            th = 0.5 * h * d2
            v3 = vs + 0.5 * h * a2
            q3 = integ(model, qs, th)
            a3 = self._acc(tk + 0.5 * h, q3, v3, ref)
            d3 = self._dth(qs, th, v3)
            th = h * d3
            v4 = vs + h * a3
            q4 = integ(model, qs, th)
            a4 = self._acc(tk + h, q4, v4, ref)
            d4 = self._dth(qs, th, v4)
            qs = integ(model, qs, h / 6.0 * (d1 + 2 * d2 + 2 * d3 + d4))
            vs = vs + h / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4)
        return Replay(times, Q, V, A, frames, frame_every)


def _wxyz(R):
    c = pin.Quaternion(R).coeffs()  # x, y, z, w
    return np.array([c[3], c[0], c[1], c[2]])
