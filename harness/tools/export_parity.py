#!/usr/bin/env python3
"""Parity of progmo's MJCF/URDF exports with our own dynamics: max |dM| and |dbias| over sample states.

Usage: export_parity.py NAME.json [NAME.xml] [NAME.urdf]
  (defaults: the .xml/.urdf next to the .json; the URDF is skipped when the JSON has no URDF report)

The JSON (written by the Rust test `export::tests::write_parity_fixtures` with PROGMO_EXPORT_DIR
set) holds both export reports and states {q, v, M, bias} in our coordinates, bias = C v + g (no
springs, dampers or attractors). Simulator quantities are mapped back to our coordinates through the
reports' q/v maps. For a Pinocchio free joint (v_sim = P(q) v_ours, P = blockdiag(R^T, 1)),
M_ours = P^T M_sim P and bias_ours = P^T (bias_sim + M_sim dP/dt v_ours), dP/dt v = -w x (R^T v_lin).
"""
import json
import os
import sys

import mujoco
import numpy as np
import pinocchio as pin


def rot_wxyz(w, x, y, z):
    n = np.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def velocity_map(report, q, v):
    """P with v_sim = P v_ours, and dP/dt v_ours (in simulator dof order)."""
    nv = len(report["v_map"])
    P = np.zeros((nv, nv))
    Pdv = np.zeros(nv)
    groups = {}
    for c in report["v_map"]:
        if c["conversion"] == "same":
            P[c["sim_index"], c["index"]] = 1.0
        else:
            groups.setdefault(c["sim_joint"], []).append(c)
    for joint, cs in groups.items():
        qi = {c["name"].rsplit(".", 1)[1]: c["index"] for c in report["q_map"] if c["sim_joint"] == joint}
        R = rot_wxyz(q[qi["qw"]], q[qi["qx"]], q[qi["qy"]], q[qi["qz"]])
        vi = {c["name"].rsplit(".", 1)[1]: c["index"] for c in report["v_map"] if c["sim_joint"] == joint}
        lin = [vi["vx"], vi["vy"], vi["vz"]]
        w = np.array([v[vi["wx"]], v[vi["wy"]], v[vi["wz"]]])
        rows = [c["sim_index"] for c in sorted(cs, key=lambda c: c["index"])]
        for a, r in enumerate(rows):
            for b, i in enumerate(lin):
                P[r, i] = R.T[a, b]
        Pdv[rows] = -np.cross(w, R.T @ np.asarray(v)[lin])
    return P, Pdv


def to_sim(report, q, v):
    nq, nv = len(report["q_map"]), len(report["v_map"])
    qs = np.zeros(nq)
    for c in report["q_map"]:
        qs[c["sim_index"]] = q[c["index"]]
    P, Pdv = velocity_map(report, q, v)
    return qs, P @ np.asarray(v), P, Pdv


def attractor_force(m, d, report):
    """Generalized attractor forces from MuJoCo's own state, as the report prescribes."""
    f = np.zeros(m.nv)
    jac = np.zeros((3, m.nv))
    for h in report["harness_forces"]:
        if h["kind"] != "attractor":
            continue
        for body, mass in h["bodies"]:
            bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, body)
            r = d.xipos[bid] - np.array(h["point"])
            force = -h["mu"] * mass * r / np.linalg.norm(r) ** 3
            mujoco.mj_jacBodyCom(m, d, jac, None, bid)
            f += jac.T @ force
    return f


def mujoco_parity(xml, report, states):
    """max |dM|, |dbias|, |dpassive| (springs, dampers), |dattractor|."""
    m = mujoco.MjModel.from_xml_path(xml)
    d = mujoco.MjData(m)
    dm = db = dp = da = 0.0
    for s in states:
        qs, vs, P, Pdv = to_sim(report, s["q"], s["v"])
        d.qpos[:], d.qvel[:] = qs, vs
        mujoco.mj_forward(m, d)
        M = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M)
        Mo = P.T @ M @ P
        bo = P.T @ (d.qfrc_bias + M @ Pdv)
        dm = max(dm, np.abs(Mo - np.array(s["M"])).max())
        db = max(db, np.abs(bo - np.array(s["bias"])).max())
        dp = max(dp, np.abs(P.T @ d.qfrc_passive - np.array(s["passive"])).max())
        fa = attractor_force(m, d, report)
        da = max(da, np.abs(P.T @ fa - np.array(s["attractor"])).max())
    return dm, db, dp, da


def pinocchio_parity(urdf, report, states):
    rj = report.get("root_joint")
    if rj:
        root = eval(rj["python"], {"pin": pin})
        model = pin.buildModelFromUrdf(urdf, root, rj["name"])
    else:
        model = pin.buildModelFromUrdf(urdf)
    model.gravity.linear = np.array(report["gravity"])
    data = model.createData()
    assert model.nq == len(report["q_map"]) and model.nv == len(report["v_map"])
    # the predicted Pinocchio order must be the real one
    for c in report["q_map"]:
        jid = model.getJointId(c["sim_joint"])
        j = model.joints[jid]
        assert j.idx_q <= c["sim_index"] < j.idx_q + j.nq, (c, j.idx_q)
    dm = db = 0.0
    for s in states:
        qs, vs, P, Pdv = to_sim(report, s["q"], s["v"])
        M = pin.crba(model, data, qs)
        M = np.triu(M) + np.triu(M, 1).T
        b = pin.rnea(model, data, qs, vs, np.zeros(model.nv))
        Mo = P.T @ M @ P
        bo = P.T @ (b + M @ Pdv)
        dm = max(dm, np.abs(Mo - np.array(s["M"])).max())
        db = max(db, np.abs(bo - np.array(s["bias"])).max())
    return dm, db


def main():
    js = sys.argv[1]
    base = os.path.splitext(js)[0]
    xml = sys.argv[2] if len(sys.argv) > 2 else base + ".xml"
    urdf = sys.argv[3] if len(sys.argv) > 3 else base + ".urdf"
    fx = json.load(open(js))
    states = fx["states"]
    scale = max(1.0, max(np.abs(np.array(s["bias"])).max() for s in states))
    dm, db, dp, da = mujoco_parity(xml, fx["mjcf"], states)
    floor = ", ".join(f'{c["body"]} +m {c["delta_mass"]:.0e} +I {c["delta_inertia"]:.0e}'
                      for c in fx["mjcf"]["mass_changes"]) or "none"
    print(f'{fx["name"]:28s} MuJoCo    max|dM| {dm:.1e}  max|dbias| {db:.1e}  |dpassive| {dp:.1e}  |dattractor| {da:.1e}  (|bias| <= {scale:.1f}; floor: {floor})')
    if fx.get("urdf") is not None and os.path.exists(urdf):
        dm, db = pinocchio_parity(urdf, fx["urdf"], states)
        print(f'{fx["name"]:28s} Pinocchio max|dM| {dm:.1e}  max|dbias| {db:.1e}')
    else:
        print(f'{fx["name"]:28s} Pinocchio: no URDF (unsupported)')


if __name__ == "__main__":
    main()
