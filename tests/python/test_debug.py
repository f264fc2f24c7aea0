"""progmo debug: MCAP with solver and simulator channels (schemas read back), CSV, first breach."""

import csv
import json
import pathlib

import pytest
from mcap.reader import make_reader

from progmo import debug
from progmo.cli import default_simulators

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENE = str(ROOT / "references" / "scenes" / "double_pendulum.toml")


def read(path):
    with open(path, "rb") as f:
        r = make_reader(f)
        summary = r.get_summary()
        topics = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
        msgs = {}
        for schema, ch, m in r.iter_messages():
            msgs.setdefault(ch.topic, []).append(json.loads(m.data))
    return topics, msgs


def test_clean_run_writes_mcap_and_csv(tmp_path, capsys):
    rc = debug.main([SCENE, "--simulator", "all", "--out", str(tmp_path), "--horizon", "1"])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "no tolerance breach" in out
    topics, msgs = read(tmp_path / "double_pendulum.mcap")
    for t in ("/progmo/state", "/progmo/control", "/progmo/residual"):
        assert t in topics and len(msgs[t]) == 1001
    for sim in default_simulators(None)[0]:  # every installed simulator (harness/setup.sh: all three)
        for t in ("state", "residual", "deviation"):
            assert len(msgs[f"/{sim}/{t}"]) == 1001
        tf = topics[f"/{sim}/tf"]
        assert tf.name == "foxglove.FrameTransform" and tf.encoding == "jsonschema"
        props = json.loads(tf.data)["properties"]
        assert set(props) >= {"timestamp", "parent_frame_id", "child_frame_id", "translation", "rotation"}
        frames = msgs[f"/{sim}/tf"]
        assert {m["child_frame_id"] for m in frames} >= {f"{sim}/upper", f"{sim}/lower"}
        m = frames[-1]
        assert set(m["timestamp"]) == {"sec", "nsec"} and m["parent_frame_id"] == "world"
        q = m["rotation"]
        assert abs(q["x"] ** 2 + q["y"] ** 2 + q["z"] ** 2 + q["w"] ** 2 - 1) < 1e-12
    assert topics["/mujoco/state"].encoding == "jsonschema"
    # MuJoCo and Pinocchio see the same lower body at the same place
    a = [m for m in msgs["/mujoco/tf"] if m["child_frame_id"] == "mujoco/lower"][-1]["translation"]
    b = [m for m in msgs["/pinocchio/tf"] if m["child_frame_id"] == "pinocchio/lower"][-1]["translation"]
    assert a == pytest.approx(b, abs=1e-9)
    with open(tmp_path / "double_pendulum_mujoco.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 1001 and "mujoco.q:q2" in rows[0] and "q:q2" in rows[0] and "u:q1" in rows[0]
    assert abs(float(rows[-1]["mujoco.q:q2"]) - float(rows[-1]["q:q2"])) < 1e-10


def test_corrupted_run_prints_first_breach(tmp_path, capsys):
    rc = debug.main([SCENE, "--simulator", "mujoco", "--out", str(tmp_path), "--horizon", "1",
                     "--corrupt-u-scale", "1.01"])
    out = capsys.readouterr().out
    assert rc == 1, out
    line = next(l for l in out.splitlines() if l.startswith("first tolerance breach"))
    assert "mujoco" in line and " at t = " in line and "budget" in line
    t = float(line.split(" at t = ")[1].split(" s")[0])
    assert 0 <= t < 0.5
    topics, msgs = read(tmp_path / "double_pendulum.mcap")
    assert "/pinocchio/state" not in topics
    assert {m["metric"] for m in msgs["/mujoco/breach"]} >= {"replay_residual", "replay_deviation"}


def test_bad_input_exit_2(tmp_path, capsys):
    assert debug.main([str(tmp_path / "missing.toml"), "--out", str(tmp_path)]) == 2
    assert debug.main([SCENE, "--simulator", "gazebo"]) == 2


def test_blow_up_keeps_mcap_and_csv_up_to_the_last_finite_state(tmp_path, capsys, monkeypatch):
    """The simulator blows up at t = 0.3 (forces exploding there): the recording and the CSV hold
    the replay up to the last finite state and the blow-up is the first breach, with its time."""
    orig = debug._run

    def exploding(*a, **kw):
        kw["corrupt_u"] = lambda t, u: u if t < 0.3 else 1e14 * (u + 1.0)
        return orig(*a, **kw)

    monkeypatch.setattr(debug, "_run", exploding)
    rc = debug.main([SCENE, "--simulator", "mujoco", "--out", str(tmp_path), "--horizon", "1", "--step", "1e-3"])
    out = capsys.readouterr().out
    assert rc == 1, out
    line = next(l for l in out.splitlines() if l.startswith("first tolerance breach"))
    assert "replay_blowup" in line and 0.3 <= float(line.split(" at t = ")[1].split(" s")[0]) <= 0.31
    topics, msgs = read(tmp_path / "double_pendulum.mcap")
    states = msgs["/mujoco/state"]
    assert 250 < len(states) and states[-1]["t"] < 0.31
    assert all(v is not None for m in states for v in m["q"].values())
    assert msgs["/mujoco/breach"][0]["metric"] == "replay_blowup"
    with open(tmp_path / "double_pendulum_mujoco.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(states) and float(rows[-1]["t"]) == states[-1]["t"]


def test_one_recording_layout_for_solve_and_debug(tmp_path, capsys):
    """debug's solver topics carry the schemas of `progmo solve`'s recording; every tree recording
    has a frame tree (one root, parents exist, unit quaternions, monotonic log times) and geometry."""
    import progmo

    scene = progmo.load("double_pendulum")
    scene.solve(output_dt=0.01).write_mcap(tmp_path / "solve.mcap")
    assert debug.main([SCENE, "--simulator", "all", "--out", str(tmp_path / "d"), "--horizon", "0.5"]) == 0
    solve_topics, solve_msgs = read(tmp_path / "solve.mcap")
    debug_topics, debug_msgs = read(tmp_path / "d" / "double_pendulum.mcap")
    for t in ("/progmo/state", "/progmo/control", "/progmo/residual", "/progmo/tf", "/progmo/scene"):
        assert solve_topics[t].name == debug_topics[t].name, t
        assert json.loads(solve_topics[t].data) == json.loads(debug_topics[t].data), t
        assert set(solve_msgs[t][-1]) == set(debug_msgs[t][-1]), t
    for sim in ("mujoco", "pinocchio"):
        assert json.loads(debug_topics[f"/{sim}/state"].data) == json.loads(solve_topics["/progmo/state"].data)
    for msgs in (solve_msgs, debug_msgs):
        frames = [m for topic, ms in msgs.items() if topic.endswith("/tf") for m in ms]
        children = {m["child_frame_id"] for m in frames}
        parents = {m["parent_frame_id"] for m in frames}
        assert parents == {"world"} and "world" not in children  # one root, every parent exists
        for m in frames:
            q = m["rotation"]
            assert abs(q["x"] ** 2 + q["y"] ** 2 + q["z"] ** 2 + q["w"] ** 2 - 1) < 1e-12
        scenes = [m for topic, ms in msgs.items() if topic.endswith("/scene") for m in ms]
        assert scenes and all(e["frame_id"] in children for s in scenes for e in s["entities"])
    assert {"progmo/upper", "mujoco/upper", "pinocchio/upper"} <= {
        m["child_frame_id"] for t, ms in debug_msgs.items() if t.endswith("/tf") for m in ms}
    ghost = debug_msgs["/progmo/scene"][0]["entities"][0]["cubes"][0]["color"]["a"]
    assert ghost < 1.0  # the solver's mechanism is drawn as a ghost beside the simulators'
    from mcap.reader import make_reader

    for f in (tmp_path / "solve.mcap", tmp_path / "d" / "double_pendulum.mcap"):
        with open(f, "rb") as fh:
            last: dict = {}
            for _, ch, m in make_reader(fh).iter_messages(log_time_order=False):
                assert m.log_time >= last.get(ch.topic, 0), (f, ch.topic)
                last[ch.topic] = m.log_time


def test_the_foxglove_layout_names_topics_the_recordings_have():
    import pathlib
    import re

    import progmo

    layout = json.loads((pathlib.Path(progmo.__file__).parent / "foxglove" / "progmo.json").read_text())
    text = json.dumps(layout["configById"])
    topics = set(re.findall(r'"(/[a-z]+/[a-z]+)', text))
    documented = {"/progmo/scene", "/progmo/residual", "/progmo/control", "/progmo/warning",
                  "/mujoco/scene", "/pinocchio/scene", "/mujoco/residual", "/pinocchio/residual",
                  "/mujoco/deviation", "/pinocchio/deviation"}
    assert topics <= documented, topics - documented
    # every panel in the layout tree is configured
    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])
    assert set(leaves(layout["layout"])) == set(layout["configById"])
