"""Shared machinery of the simulator back-ends: coordinate maps between our q/v and a simulator's
qpos/dof vectors (from the export report), the solver's reference trajectory sampled at every RK4
stage time, and the metrics computed on a replayed trajectory.

Conventions (see ``src/export/mod.rs`` and ``shared/notes/simulators.md``):

* ``q_sim[c.sim_index] = q[c.index]`` for every entry of the report's ``q_map`` (quaternion
  component reordering for Pinocchio is in the map);
* ``v_sim = P(q) v`` with ``P`` the identity on ``same`` entries and ``R^T`` on the three linear
  entries of a free joint whose conversion is ``body_frame`` (Pinocchio); generalized forces map as
  ``f_sim = P^-T u`` (``P`` is orthogonal: ``f_sim = P u``), back as ``u = P^T f_sim``;
* accelerations: ``a_sim = P a + (dP/dt) v`` with ``(dP/dt) v = -w x (R^T v_lin)``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np


def rot_wxyz(w: float, x: float, y: float, z: float) -> np.ndarray:
    # on Python floats (the replays call this at every stage): the same IEEE operations as on
    # numpy scalars, without their per-operation overhead
    w, x, y, z = float(w), float(x), float(y), float(z)
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


class CoordMap:
    """Our q/v <-> a simulator's qpos/dof vectors, built from an export report."""

    def __init__(self, report: dict):
        self.report = report
        self.nq = len(report["q_map"])
        self.nv = len(report["v_map"])
        self.q_idx = np.array([c["index"] for c in report["q_map"]], dtype=int)
        self.q_sim = np.array([c["sim_index"] for c in report["q_map"]], dtype=int)
        #: planar joints whose simulator velocity is in the moving frame (Pinocchio's reading of a
        #: URDF planar joint, ``sim_planar``: its first (qpos, dof)): (our θ position index, our x,
        #: y, θ velocity indices, simulator rows x, y, θ); v_sim[x, y] = R(θ)^T (x', y')
        self.planar: list[tuple[int, list[int], list[int]]] = []
        byq = {c["sim_index"]: c["index"] for c in report["q_map"]}
        byv = {c["sim_index"]: c["index"] for c in report["v_map"]}
        for iq, iv in report.get("sim_planar", []):
            self.planar.append((byq[iq + 2], [byv[iv], byv[iv + 1], byv[iv + 2]], [iv, iv + 1, iv + 2]))
        turned = {r for _, _, rows in self.planar for r in rows[:2]}
        self.same = [c for c in report["v_map"] if c["conversion"] == "same" and c["sim_index"] not in turned]
        self.same_idx = np.array([c["index"] for c in self.same], dtype=int)
        self.same_sim = np.array([c["sim_index"] for c in self.same], dtype=int)
        # free joints whose linear velocity is body-frame in the simulator
        groups: dict[str, list[dict]] = {}
        for c in report["v_map"]:
            if c["conversion"] != "same":
                groups.setdefault(c["sim_joint"], []).append(c)
        self.frames = []  # (q indices wxyz, lin v indices, ang v indices, sim rows)
        for joint, cs in groups.items():
            qi = {c["name"].rsplit(".", 1)[1]: c["index"] for c in report["q_map"]
                  if c["sim_joint"] == joint}
            vi = {c["name"].rsplit(".", 1)[1]: c["index"] for c in report["v_map"]
                  if c["sim_joint"] == joint}
            rows = [c["sim_index"] for c in sorted(cs, key=lambda c: c["index"])]
            self.frames.append(([qi["qw"], qi["qx"], qi["qy"], qi["qz"]],
                                [vi["vx"], vi["vy"], vi["vz"]],
                                [vi["wx"], vi["wy"], vi["wz"]], rows))
        # quaternion groups of OUR q (for comparisons up to sign)
        self.quats: list[list[int]] = []
        byj: dict[str, dict[str, int]] = {}
        for c in report["q_map"]:
            suffix = c["name"].rsplit(".", 1)[-1]
            if suffix in ("qw", "qx", "qy", "qz"):
                byj.setdefault(c["sim_joint"], {})[suffix] = c["index"]
        for d in byj.values():
            if len(d) == 4:
                self.quats.append([d["qw"], d["qx"], d["qy"], d["qz"]])

        #: (simulator qpos index, offset): q_sim = q - offset there (``sim_q_offset`` of a robot
        #: file read by Pinocchio: MJCF joint ``ref``)
        self.q_offset = [(int(i), float(o)) for i, o in report.get("sim_q_offset", [])]
        #: simulator qpos index of each unbounded revolute joint (Pinocchio's reading of a URDF
        #: ``continuous`` joint: q_sim = (cos θ, sin θ) there, θ ours; v alike)
        self.unbounded = sorted(int(i) for i in report.get("sim_unbounded", []))
        #: the simulator's number of position coordinates
        self.nq_sim = self.nq + len(self.unbounded)
        by_sim = dict(zip(self.q_sim.tolist(), self.q_idx.tolist()))
        #: our q index of each unbounded angle
        self.unbounded_ours = [by_sim[i] for i in self.unbounded]

    # -- positions
    def q_to_sim(self, q: np.ndarray) -> np.ndarray:
        qs = np.zeros(self.nq_sim)
        qs[self.q_sim] = q[self.q_idx]
        for i, o in self.q_offset:
            qs[i] -= o
        for i in self.unbounded:
            qs[i], qs[i + 1] = np.cos(qs[i]), np.sin(qs[i])
        return qs

    def q_from_sim(self, qs: np.ndarray, near: np.ndarray | None = None) -> np.ndarray:
        """Our q of the simulator's; an unbounded joint's angle atan2(sin, cos) taken within π of
        ``near`` (our q of the step before: the angle stays continuous over turns)."""
        if self.q_offset or self.unbounded:
            qs = np.array(qs, float)
            for i in self.unbounded:
                qs[i] = np.arctan2(qs[i + 1], qs[i])
            for i, o in self.q_offset:
                qs[i] += o
        q = np.zeros(self.nq)
        q[self.q_idx] = qs[self.q_sim]
        if self.unbounded and near is not None:
            for k in self.unbounded_ours:
                q[k] += 2.0 * np.pi * np.round((near[k] - q[k]) / (2.0 * np.pi))
        return q

    # -- velocity map
    def P(self, q: np.ndarray) -> np.ndarray:
        """v_sim = P(q) v (q: ours)."""
        P = np.zeros((self.nv, self.nv))
        P[self.same_sim, self.same_idx] = 1.0
        for qi, lin, ang, rows in self.frames:
            R = rot_wxyz(*q[qi])
            for a, r in enumerate(rows):
                P[r, lin] = R.T[a]
        for th, xyw, rows in self.planar:
            c, s = np.cos(q[th]), np.sin(q[th])
            P[rows[0], xyw[:2]] = (c, s)
            P[rows[1], xyw[:2]] = (-s, c)
        return P

    def Pdot_v(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(dP/dt) v in simulator dof order."""
        out = np.zeros(self.nv)
        for qi, lin, ang, rows in self.frames:
            R = rot_wxyz(*q[qi])
            w = v[ang]
            out[rows] = -np.cross(w, R.T @ v[lin])
        for th, (ix, iy, iw), rows in self.planar:
            c, s = np.cos(q[th]), np.sin(q[th])
            wz, vx, vy = v[iw], v[ix], v[iy]
            out[rows[0]] = wz * (-s * vx + c * vy)
            out[rows[1]] = wz * (-c * vx - s * vy)
        return out

    def v_to_sim(self, q, v):
        if not self.frames and not self.planar:
            vs = np.zeros(self.nv)
            vs[self.same_sim] = v[self.same_idx]
            return vs
        return self.P(q) @ v

    def v_from_sim(self, q, vs):
        if not self.frames and not self.planar:
            v = np.zeros(self.nv)
            v[self.same_idx] = vs[self.same_sim]
            return v
        return self.P(q).T @ vs  # P orthogonal

    def f_to_sim(self, q, u):
        return self.v_to_sim(q, u)  # P^-T = P

    def f_from_sim(self, q, fs):
        return self.v_from_sim(q, fs)  # P^T

    def a_from_sim(self, q, v, a_sim):
        if not self.frames and not self.planar:
            return self.v_from_sim(q, a_sim)
        return self.P(q).T @ (a_sim - self.Pdot_v(q, v))

    def a_to_sim(self, q, v, a):
        if not self.frames and not self.planar:
            return self.v_to_sim(q, a)
        return self.P(q) @ a + self.Pdot_v(q, v)


@dataclass
class Reference:
    """The solver's trajectory at every RK4 stage time of a replay with step h (output_dt = h/2)."""

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    u: np.ndarray
    residual: np.ndarray
    h: float
    steps: int
    t0: float
    solve_seconds: float = 0.0
    #: multipliers and dg/dt of the rows (recordings; None when not kept)
    lam: np.ndarray | None = None
    residual_rate: np.ndarray | None = None
    #: a state-dependent actuation map: H(t, q) (n x m) and tau at every stage time; the replay
    #: then applies H at the simulator's own state, u_sim = H(t, q_sim) tau(t) (plus u - u_model,
    #: a deliberate corruption of u by a negative control)
    actuation: Callable[[float, np.ndarray], np.ndarray] | None = None
    tau: np.ndarray | None = None
    u_model: np.ndarray | None = None
    #: the generalized reaction B_s^T lambda_s of the system rows the simulator's document leaves
    #: out (export report ``supplied_reaction``) at every stage time, from this solve: applied with
    #: u at the stage time (open loop)
    supplied: np.ndarray | None = None

    def _at(self, x: np.ndarray, time: float) -> np.ndarray:
        """x at a stage time (exact grid value; linear interpolation off the grid)."""
        s = (time - self.t0) / (0.5 * self.h)
        k = int(round(s))
        if abs(s - k) < 1e-6 and 0 <= k < len(self.t):
            return x[k]
        k = min(max(int(np.floor(s)), 0), len(self.t) - 2)
        f = s - k
        return (1 - f) * x[k] + f * x[k + 1]

    def u_at(self, time: float) -> np.ndarray:
        """u at a stage time (exact grid value; linear interpolation off the grid)."""
        return self._at(self.u, time)

    def force_at(self, time: float, q: np.ndarray) -> np.ndarray:
        """The generalized force to apply at a stage time and the simulator's state q (ours): u(t),
        or with a state-dependent actuation map H(t, q) tau(t); plus the supplied reactions r(t)."""
        if self.actuation is None or self.tau is None:
            f = self.u_at(time)
        else:
            f = self.actuation(time, q) @ self._at(self.tau, time)
            if self.u_model is not None:
                f = f + self._at(self.u, time) - self._at(self.u_model, time)
        if self.supplied is not None:
            f = f + self._at(self.supplied, time)
        return f


@dataclass
class Replay:
    """A replayed trajectory in OUR coordinates, at t0 + k h, k = 0..steps."""

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    #: optional body frames per sample: list of (name, pos[3], quat wxyz[4]) lists
    frames: list = field(default_factory=list)
    frame_every: int = 1


def quat_aware_diff(cm: CoordMap, q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """|q1 - q2| per entry (rows: samples), quaternions compared up to sign."""
    d = np.abs(q1 - q2)
    for g in cm.quats:
        alt = np.abs(q1[:, g] + q2[:, g])
        use_alt = alt.max(axis=1) < d[:, g].max(axis=1)
        d[np.ix_(use_alt, g)] = alt[use_alt]
    return d


def growth_rate(t: np.ndarray, dev: np.ndarray) -> float:
    """Exponential growth rate (1/s) of the deviation: least-squares fit of log(dev) over the
    horizon, skipping the first 10% (where the deviation rises from exact zero) and values at
    round-off level."""
    if len(t) < 4:
        return float("nan")
    T = t[-1] - t[0]
    keep = (t >= t[0] + 0.1 * T) & (dev > 1e-15) & np.isfinite(dev)
    if keep.sum() < 4:
        return float("nan")
    slope, _ = np.polyfit(t[keep], np.log(dev[keep]), 1)
    return float(slope)


def first_time_above(t: np.ndarray, x: np.ndarray, limit: float) -> float | None:
    bad = ~(x <= limit)
    if not bad.any():
        return None
    return float(t[int(np.argmax(bad))])


def downsample(n: int, most: int = 400) -> np.ndarray:
    if n <= most:
        return np.arange(n)
    idx = np.unique(np.linspace(0, n - 1, most).round().astype(int))
    return idx
