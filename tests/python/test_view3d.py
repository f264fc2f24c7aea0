"""The 3D view of recordings (src/output/scene3d.rs): a scene's view targets, the realized traces of
the programme's sites and the bodies' `shape`, read back from `progmo solve` and `progmo debug`
MCAPs and checked against closed forms written here (planar_arm_line: three links of length l in
the x-z plane, hinges about -y), not against the code that drew them."""

import json
import math
import pathlib
import re

import numpy as np
import pytest
from mcap.reader import make_reader

import progmo
from progmo import _core
from progmo import debug

ROOT = pathlib.Path(__file__).resolve().parents[2]
ARM = ROOT / "references" / "scenes" / "planar_arm_line.toml"
# planar_arm_line's parameters, from the file's [parameters] (l, q10, q20, q30, V)
L, Q10, Q20, Q30, V = 0.4, 0.3, 0.6, 0.5, -0.2
Z0 = L * (math.sin(Q10) + math.sin(Q10 + Q20) + math.sin(Q10 + Q20 + Q30))  # height of the line


def read(path):
    with open(path, "rb") as f:
        r = make_reader(f)
        summary = r.get_summary()
        topics = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        msgs: dict = {}
        for _, ch, m in r.iter_messages():
            msgs.setdefault(ch.topic, []).append((m.log_time, json.loads(m.data)))
    return topics, msgs


def tip(q, length=L):
    """Closed-form tip of the planar arm: x = l sum cos(Q_k), z = l sum sin(Q_k), Q_k the absolute
    link angles (a positive angle about -y raises the link)."""
    a = np.cumsum([q["q1"], q["q2"], q["q3"]])
    return np.array([length * np.cos(a).sum(), 0.0, length * np.sin(a).sum()])


def entities(msgs, topic):
    return {e["id"]: (t, e) for t, m in msgs[topic] for e in m["entities"]}


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    out = tmp_path_factory.mktemp("arm")
    assert _core.cli(["progmo", "solve", str(ARM), "--out", str(out), "--quiet"]) == 0
    return read(out / "recording.mcap")


def test_planar_arm_line_draws_its_target_line_and_the_tips_trace(solved):
    topics, msgs = solved
    assert topics["/progmo/scene"] == "foxglove.SceneUpdate"
    ents = entities(msgs, "/progmo/scene")
    # the declared target: a world-frame line at height z0 along x, drawn from the first sample on
    t_line, line = ents["progmo/target/line"]
    assert t_line == 0 and line["frame_id"] == "world"
    pts = line["lines"][0]["points"]
    assert len(pts) == 2 and all(abs(p["z"] - Z0) < 1e-12 and p["y"] == 0 for p in pts)
    assert abs(pts[1]["x"] - pts[0]["x"]) > 0.5  # spans the mechanism, along x
    # the realized trace of `tip` (the programme rows read tip.z and tip.x'): one point per sample,
    # at the end of the recording, equal to the closed-form tip of each recorded q
    states = [m for _, m in msgs["/progmo/state"]]
    t_trace, trace = ents["progmo/trace/tip"]
    assert trace["frame_id"] == "world" and t_trace == msgs["/progmo/state"][-1][0]
    tp = np.array([[p["x"], p["y"], p["z"]] for p in trace["lines"][0]["points"]])
    assert trace["lines"][0]["type"] == 0 and len(tp) == len(states) == 151
    want = np.array([tip(s["q"]) for s in states])
    assert np.abs(tp - want).max() < 1e-12
    # ... and the trace lies on the target line (programme_residual budget 1e-10), moving at V
    assert np.abs(tp[:, 2] - Z0).max() < 1e-10
    assert abs((tp[-1, 0] - tp[0, 0]) - V * 1.5) < 1e-8
    # negative control: the closed form with a wrong link length does not match the trace
    wrong = np.array([tip(s["q"], 1.01 * L) for s in states])
    assert np.abs(tp - wrong).max() > 1e-3


def test_a_body_shape_replaces_the_derived_box(solved, tmp_path):
    _, msgs = solved
    ents = entities(msgs, "/progmo/scene")
    for b in ("link1", "link2", "link3"):
        _, e = ents[f"progmo/{b}"]
        # shape = { capsule = [0.02, 0.4], quat = z -> x }: a cylinder 0.4 long, 0.04 wide, at the
        # CoM (0.2, 0, 0), its axis along the link (x), and the two end spheres at x = 0 and 0.4
        assert e["cubes"] == [] and len(e["cylinders"]) == 1
        c = e["cylinders"][0]
        assert (c["size"]["x"], c["size"]["y"], c["size"]["z"]) == pytest.approx((0.04, 0.04, 0.4), abs=1e-15)
        p, o = c["pose"]["position"], c["pose"]["orientation"]
        assert (p["x"], p["y"], p["z"]) == pytest.approx((0.2, 0.0, 0.0), abs=1e-15)
        # rotate z by the quaternion: must give x
        w, x, y, z = o["w"], o["x"], o["y"], o["z"]
        zrot = np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])
        assert np.allclose(zrot, [1, 0, 0], atol=1e-12)
        ends = sorted(s["pose"]["position"]["x"] for s in e["spheres"] if s["size"]["x"] == pytest.approx(0.04))
        assert ends == pytest.approx([0.0, 0.4], abs=1e-12)
    # negative control: a scene without `shape` keeps the derived inertia box (double_pendulum)
    scene = progmo.load("double_pendulum")
    scene.solve(output_dt=0.1).write_mcap(tmp_path / "dp.mcap")
    _, dp = read(tmp_path / "dp.mcap")
    dpe = entities(dp, "/progmo/scene")
    assert all(e["cubes"] and not e["cylinders"] for i, (_, e) in dpe.items() if i.startswith("progmo/"))
    assert not any("/target/" in i or "/trace/" in i for i in dpe)  # no declared target, no site in the rows


def test_debug_recording_has_the_same_targets_and_traces(tmp_path, capsys):
    assert debug.main([str(ARM), "--simulator", "mujoco", "--out", str(tmp_path), "--horizon", "0.1"]) == 0
    topics, msgs = read(tmp_path / "planar_arm_line.mcap")
    solver = entities(msgs, "/progmo/scene")
    sim = entities(msgs, "/mujoco/scene")
    assert "progmo/target/line" in solver and not any("/target/" in i for i in sim)  # drawn once
    for ents, prefix, topic in ((solver, "progmo", "/progmo/state"), (sim, "mujoco", "/mujoco/state")):
        _, trace = ents[f"{prefix}/trace/tip"]
        tp = np.array([[p["x"], p["y"], p["z"]] for p in trace["lines"][0]["points"]])
        states = [m for _, m in msgs[topic]]
        assert len(tp) == len(states)
        # every point is the closed-form tip of the recorded configuration, on the line
        assert np.abs(tp - np.array([tip(s["q"]) for s in states])).max() < 1e-12
        # on the line within the scene's replay_residual budget 5e-10 (measured: 1.3e-13 solver,
        # 1.0e-14 mujoco replay over 0.1 s)
        assert np.abs(tp[:, 2] - Z0).max() < 5e-10
    # the layout's 3D panel shows the scene topics these recordings carry
    layout = json.loads((pathlib.Path(progmo.__file__).parent / "foxglove" / "progmo.json").read_text())
    shown = set(layout["configById"]["3D!progmo"]["topics"])
    assert {"/progmo/scene", "/mujoco/scene"} <= shown and {"/progmo/scene", "/mujoco/scene"} <= set(topics)
    # every topic a layout panel names is in a recording of this kind (the pinocchio replay is not
    # run here; /progmo/warning is written only when the solver warns)
    named = set(re.findall(r'"(/[a-z]+/[a-z]+)', json.dumps(layout["configById"])))
    have = set(topics) | {t.replace("/mujoco/", "/pinocchio/") for t in topics} | {"/progmo/warning"}
    assert named <= have, named - have


def test_knife_edge_path_target_is_the_solved_contact_path(tmp_path):
    """knife_edge declares the closed-form path of its blade's contact point as a path target: the
    drawn samples (200 over [0, 10] s) must lie on the solved (x, y) at the same times (the solver
    is the independent side here; tests/catalog.rs checks it against the same closed form)."""
    scene = progmo.load("knife_edge")
    sol = scene.solve(output_dt=0.05)  # samples at k * 0.05: every drawn time is one (10 / 199 is not)
    sol.write_mcap(tmp_path / "k.mcap")
    _, msgs = read(tmp_path / "k.mcap")
    _, path = entities(msgs, "/progmo/scene")["progmo/target/closed_form_path"]
    pts = np.array([[p["x"], p["y"], p["z"]] for p in path["lines"][0]["points"]])
    assert len(pts) == 200 and np.all(pts[:, 2] == 0)
    ts = np.linspace(0.0, 10.0, 200)
    x = np.interp(ts, sol.t, sol.q[:, 0])
    y = np.interp(ts, sol.t, sol.q[:, 1])
    # linear interpolation between 0.05 s samples of a path with speed <= 1.8 m/s and curvature
    # radius >= 1.25 m: chord error <= (1.8 * 0.05)^2 / (8 * 1.25) = 8.1e-4 m
    assert np.abs(pts[:, 0] - x).max() < 1e-3 and np.abs(pts[:, 1] - y).max() < 1e-3
    # negative control: the path drawn with the wrong turning sign does not match
    assert np.abs(pts[:, 1] + y).max() > 0.5
