"""MuJoCo 4.0 back-end: the scene's MJCF export, RK4 with u fed at every stage through
``mjcb_control`` (process-global: always cleared in ``finally``). The scene's point forces go
through ``xfrc_applied`` (force at the body's CoM plus the moment of its lever arm), its coordinate
forces and the attractors through ``qfrc_applied``, all evaluated from the stage's own state.

Loop closures are the export's ``<equality>`` elements (soft constraints: see
``src/export/MUJOCO_CLOSURES.md``); their solref timeconst keeps its ratio to the step when the
replay changes the step."""

from __future__ import annotations

import numpy as np
import mujoco

from . import BlowUp, ExpressionForces, Unsupported, attractor_force, require_forces
from .replay import CoordMap, Reference, Replay
from .robot_file import FILE_FORCES, RobotFile, mujoco_addresses, mujoco_model, name_report

#: |qacc| beyond this is treated as a blow-up (MuJoCo returns huge values at singularities)
ACC_LIMIT = 1e8

NAME = "mujoco"


def version() -> str:
    return mujoco.__version__


#: harness forces this back-end applies (springs and dampers are in the MJCF itself;
#: ``supplied_reaction``: the reference's force_at carries it, like u)
SUPPORTED = ("attractor", "point_force", "coordinate_force", "supplied_reaction")


class MujocoBackend:
    name = NAME

    def __init__(self, doc: str, report: dict, scene=None, withhold: tuple[str, ...] = (),
                 robot: RobotFile | None = None):
        """``robot``: build the model from the user's robot file (``robot_file``), not ``doc``."""
        if robot is not None:  # the file's own passive forces come from the simulator's reading
            report = {**report, "harness_forces": [hf for hf in report.get("harness_forces", [])
                                                  if hf["kind"] not in FILE_FORCES]}
        require_forces(report, SUPPORTED, "MuJoCo")
        self._file_notes: list[str] = []
        if robot is not None:
            self.m, self._file_notes = mujoco_model(robot, report["gravity"], report.get("closures", []))
            report = name_report(report, mujoco_addresses(self.m))
        else:
            self.m = mujoco.MjModel.from_xml_string(doc)
        self.route = "user's file" if robot is not None else "progmo export"
        self.report = report
        self.cm = CoordMap(report)
        self.expr = ExpressionForces(scene, report, withhold)
        self._withhold_attractors = "attractor" in withhold
        self.d = mujoco.MjData(self.m)
        m = self.m
        # ideal rigid-body dynamics: the export disables contacts etc.; make sure of the rest
        m.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
        m.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_ACTUATION)
        if m.nq != self.cm.nq or m.nv != self.cm.nv:
            raise ValueError(f"MJCF has nq={m.nq}, nv={m.nv}; report {self.cm.nq}, {self.cm.nv}")
        self.attractors = []
        for hf in report.get("harness_forces", []):
            if hf["kind"] == "attractor":
                bodies = [(mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, b), mass)
                          for b, mass in hf["bodies"]]
                self.attractors.append((np.array(hf["point"], float), hf["mu"], bodies))
            else:  # springs and dampers are in the MJCF (qfrc_passive)
                pass
        self._jac = np.zeros((3, m.nv))
        self._h0 = float(m.opt.timestep)
        self._solref0 = np.array(m.eq_solref, float).copy()
        #: rows of each closure in MuJoCo's efc order (connect 3, weld 6, tendon 1)
        self.closure_names = [c["name"] for c in report.get("closures", [])]
        self.body_names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, i) for i in range(m.nbody)]
        self.body_id = {n: i for i, n in enumerate(self.body_names)}

    def notes(self) -> list[str]:
        ch = self.report.get("mass_changes", [])
        s = f"MuJoCo {mujoco.__version__}, RK4, u written to qfrc_applied at every stage (mjcb_control)"
        if self.m.neq:
            s += (f"; closures {', '.join(self.closure_names)} as equality constraints (solref timeconst "
                  f"{self._solref0[0, 0] / self._h0:g} steps, solimp {' '.join(f'{x:g}' for x in self.m.eq_solimp[0, :3])}; "
                  "Newton, tolerance 1e-15)")
        if ch and not self._file_notes:
            s += "; mass floor on " + ", ".join(
                f'{c["body"]} (+m {c["delta_mass"]:.0e}, +I {c["delta_inertia"]:.0e})' for c in ch)
        return [s] + self._file_notes

    def harness(self) -> np.ndarray:
        """Generalized attractor forces from MuJoCo's own state (needs kinematics)."""
        f = np.zeros(self.m.nv)
        if self._withhold_attractors:
            return f
        for point, mu, bodies in self.attractors:
            for bid, mass in bodies:
                force = attractor_force(point, mu, mass, self.d.xipos[bid])
                mujoco.mj_jacBodyCom(self.m, self.d, self._jac, None, bid)
                f += self._jac.T @ force
        return f

    def expression(self, t: float) -> np.ndarray:
        """The scene's expression forces at MuJoCo's current state (needs kinematics): point forces
        written to ``xfrc_applied`` (at the CoM ``xipos``, with the moment (p - xipos) x f), the
        coordinate forces returned as a generalized force in MuJoCo's dofs."""
        d, cm = self.d, self.cm
        d.xfrc_applied[:] = 0.0
        f = np.zeros(self.m.nv)
        if not self.expr.active:
            return f
        q = cm.q_from_sim(d.qpos)
        gen, pts = self.expr.at(t, q, cm.v_from_sim(q, d.qvel))
        if gen is not None:
            f += cm.f_to_sim(q, gen)
        for body, pw, fw in pts:
            b = self.body_id[body]
            d.xfrc_applied[b, :3] += fw
            d.xfrc_applied[b, 3:] += np.cross(pw - d.xipos[b], fw)
        return f

    def _xfrc_generalized(self) -> np.ndarray:
        """J^T of the current ``xfrc_applied`` (MuJoCo's own mapping, mj_applyFT at the CoM)."""
        m, d = self.m, self.d
        out = np.zeros(m.nv)
        for b in range(1, m.nbody):
            w = d.xfrc_applied[b]
            if np.any(w):
                mujoco.mj_applyFT(m, d, w[:3].copy(), w[3:].copy(), d.xipos[b].copy(), b, out)
        return out

    def _set(self, t, q, v):
        self.d.time = t
        self.d.qpos[:] = self.cm.q_to_sim(q)
        self.d.qvel[:] = self.cm.v_to_sim(q, v)
        self.d.qfrc_applied[:] = 0.0
        self.d.xfrc_applied[:] = 0.0

    def model_terms(self, t, q, v):
        m, d, cm = self.m, self.d, self.cm
        mujoco.set_mjcb_control(None)
        self._set(t, q, v)
        mujoco.mj_forward(m, d)
        M = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M)
        rhs_sim = -d.qfrc_bias + d.qfrc_passive + self.harness() + self.expression(t) \
            + self._xfrc_generalized()
        P = cm.P(q)
        return P.T @ M @ P, P.T @ (rhs_sim - M @ cm.Pdot_v(q, v))

    def _equality_rows(self) -> np.ndarray:
        """Indices of the efc rows of equality constraints (after mj_forward), in efc order."""
        return np.flatnonzero(np.asarray(self.d.efc_type)[: self.d.nefc] == mujoco.mjtConstraint.mjCNSTR_EQUALITY)

    def closure_jacobian(self, t, q, v) -> np.ndarray:
        """MuJoCo's Jacobian of the equality (closure) rows, efc order, in OUR v."""
        m, d, cm = self.m, self.d, self.cm
        if not m.neq:
            return np.zeros((0, cm.nv))
        mujoco.set_mjcb_control(None)
        self._set(t, q, v)
        mujoco.mj_forward(m, d)
        J = np.asarray(d.efc_J).reshape(-1, m.nv)[: d.nefc][self._equality_rows()]
        return J @ cm.P(q)

    def closure_forces(self, t, q, v, u) -> np.ndarray:
        """MuJoCo's equality forces (efc_force, efc order) at (t, q, v) under the control force u."""
        m, d, cm = self.m, self.d, self.cm
        mujoco.set_mjcb_control(None)
        self._set(t, q, v)
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        d.qfrc_applied[:] = cm.f_to_sim(q, u) + self.harness() + self.expression(t)
        mujoco.mj_forward(m, d)
        return np.asarray(d.efc_force)[: d.nefc][self._equality_rows()].copy()

    def instant_u(self, t, q, v, a, B, gamma, programme=None, actuated=False):
        """u from MuJoCo's inverse dynamics (mj_inverse, equality off: M a + bias - passive), also
        with actuators (``actuated``: servo-constraints, u = H tau). With
        closures (``programme``: the programme rows' indices in B) that force is split over MuJoCo's
        own closure Jacobian (efc_J) and our programme rows (least squares), u = B_p^T lambda_p."""
        m, d, cm = self.m, self.d, self.cm
        mujoco.set_mjcb_control(None)
        Jc = self.closure_jacobian(t, q, v) if m.neq else None
        eq = int(mujoco.mjtDisableBit.mjDSBL_EQUALITY)
        flags = m.opt.disableflags
        m.opt.disableflags = flags | eq
        try:
            self._set(t, q, v)
            d.qacc[:] = cm.a_to_sim(q, v, a)
            mujoco.mj_inverse(m, d)
            f = d.qfrc_inverse.copy() - self.harness() - self.expression(t) - self._xfrc_generalized()
        finally:
            m.opt.disableflags = flags
        total = cm.f_from_sim(q, f)
        if Jc is None or programme is None:  # inverse_force: the whole force, closures' share included
            return total
        Bp = B[programme]
        lam = np.linalg.lstsq(np.vstack([Jc, Bp]).T, total, rcond=None)[0]
        return Bp.T @ lam[len(Jc):]

    def inverse_force(self, t, q, v, a) -> np.ndarray:
        """The generalized force MuJoCo's inverse dynamics needs for dv/dt = a at (t, q, v), our
        coordinates: qfrc_inverse (M with armature, bias, minus passive forces) minus the scene's
        other forces; with loop closures it includes their reactions (equalities off)."""
        return self.instant_u(t, q, v, a, np.zeros((0, self.cm.nv)), np.zeros(0))

    def unmodelled(self) -> list[dict]:
        """Elements of MuJoCo's reading of a robot file progmo does not model (robot_file doc)."""
        m = self.m
        if self.route != "user's file":
            return []
        out = []
        for j in range(m.njnt):
            n = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
            f = m.dof_frictionloss[m.jnt_dofadr[j]]
            if f != 0.0:
                out.append({"kind": "frictionloss", "element": f"joint {n} frictionloss {f:g}",
                            "location": "MuJoCo's reading"})
        for i in range(m.ntendon):
            out.append({"kind": "tendon", "element": f"tendon {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_TENDON, i) or i}",
                        "location": "MuJoCo's reading"})
        for i in range(m.neq):
            if mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_EQUALITY, i) in self.closure_names:
                continue  # the scene's loop closures, added to the file's model (robot_file)
            out.append({"kind": "equality", "element": f"equality {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_EQUALITY, i) or i}",
                        "location": "MuJoCo's reading"})
        if m.opt.density or m.opt.viscosity or np.any(m.opt.wind):
            out.append({"kind": "fluid", "element": "fluid forces (option density/viscosity/wind)",
                        "location": "MuJoCo's reading"})
        return out

    def joint_ranges(self) -> dict[str, tuple[float, float]]:
        """Ranges of MuJoCo's limited hinge and slide joints (radians, metres)."""
        m = self.m
        return {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j): (float(m.jnt_range[j, 0]), float(m.jnt_range[j, 1]))
                for j in range(m.njnt) if m.jnt_limited[j] and int(m.jnt_type[j]) in (2, 3)}

    def replay(self, ref: Reference, frame_every: int = 0, start: int = 0, stop: int | None = None,
               x0: tuple[np.ndarray, np.ndarray] | None = None) -> Replay:
        """Steps ``start`` .. ``stop`` (default: the whole reference) from the reference's state at
        step ``start`` (``x0`` = (q, v): from that state instead: the Lyapunov probe)."""
        m, d, cm = self.m, self.d, self.cm
        h, t0 = ref.h, ref.t0
        stop = ref.steps if stop is None else stop
        n = stop - start
        m.opt.timestep = h
        if m.neq:  # closures: solref timeconst keeps its ratio to the step (MUJOCO_CLOSURES.md)
            m.eq_solref[:, 0] = self._solref0[:, 0] * h / self._h0
        q0, v0 = (ref.q[2 * start], ref.v[2 * start]) if x0 is None else x0
        nq, nv = len(ref.q[0]), len(ref.v[0])
        Q = np.zeros((n + 1, nq))
        V = np.zeros((n + 1, nv))
        A = np.zeros((n + 1, nv))
        frames = []
        cur_q = [q0]

        def control(model, data):
            # a state-dependent actuation map is evaluated at this RK4 stage's own state
            qs = cm.q_from_sim(data.qpos) if ref.actuation is not None else cur_q[0]
            u = ref.force_at(data.time, qs)
            data.qfrc_applied[:] = cm.f_to_sim(cur_q[0], u) + self.harness() + self.expression(data.time)

        def control_u_only(model, data):
            # the same force when u is all there is (no attractor, no expression force, one-to-one
            # dofs): u's entries written into MuJoCo's dofs, the others stay zero (set below)
            qs = cm.q_from_sim(data.qpos) if ref.actuation is not None else cur_q[0]
            data.qfrc_applied[sim_dofs] = ref.force_at(data.time, qs)[our_dofs]

        self._set(t0 + start * h, q0, v0)
        u_only = not cm.frames and not self.expr.active and (self._withhold_attractors or not self.attractors)
        sim_dofs, our_dofs = cm.same_sim, cm.same_idx
        if u_only:
            d.xfrc_applied[:] = 0.0
            d.qfrc_applied[:] = 0.0
        mujoco.set_mjcb_control(control_u_only if u_only else control)
        times = ref.t[::2][start: stop + 1]
        try:
            for j in range(n + 1):
                k = start + j
                tk = t0 + k * h
                d.time = tk
                mujoco.mj_forward(m, d)
                qo = cm.q_from_sim(d.qpos)
                if not (np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all()):
                    raise BlowUp(tk, "non-finite state")
                if not (np.abs(d.qacc) < ACC_LIMIT).all():
                    big = float(np.abs(d.qacc).max())
                    raise BlowUp(tk, f"|qacc| = {big:.3g} > {ACC_LIMIT:g}", big, ACC_LIMIT)
                Q[j] = qo
                V[j] = cm.v_from_sim(qo, d.qvel)
                A[j] = cm.a_from_sim(qo, V[j], d.qacc)
                if frame_every and k % frame_every == 0:
                    frames.append((tk, [(self.body_names[b], d.xpos[b].copy(), d.xquat[b].copy())
                                        for b in range(1, m.nbody)]))
                if j == n:
                    break
                cur_q[0] = qo
                d.time = tk
                mujoco.mj_step(m, d)
        except BlowUp as e:  # keep the evidence: samples start .. k-1 are finite
            e.partial = Replay(times[:j], Q[:j], V[:j], A[:j], frames, frame_every)
            raise
        finally:
            mujoco.set_mjcb_control(None)
        return Replay(times, Q, V, A, frames, frame_every)
