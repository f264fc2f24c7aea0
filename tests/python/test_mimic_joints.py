"""URDF ``<mimic>`` joints as system constraints (issue 30 item 2): the follower obeys
q_joint = multiplier q_leader + offset as a system row ``mimic_JOINT`` (its reaction is an internal
force of the mechanism, not a control). In the check no simulator holds the coupling as progmo
does (MuJoCo's URDF compiler makes it a soft joint equality, compared with progmo's law and then
removed; Pinocchio 4.1 has no coupling constraint; a continuous Drake plant holds no constraint:
the <mimic> is removed from the file it reads), so its reaction is supplied with u and the row is
measured on the open-loop replay. Negative controls: the replay without the supplied reactions
fails; a multiplier MuJoCo reads otherwise is an error; a mimic declared ignored leaves the joints
independent (the old reading); a locked leader with a moving follower is refused at the <mimic>."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import progmo
from progmo.checks import CheckOptions, _run, run_check

pytest.importorskip("mujoco")
pytest.importorskip("pinocchio")

ARM = """<robot name="gripper_arm">
  <link name="base"><inertial><mass value="2"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="upper"><inertial><origin xyz="0 0 0.2" rpy="0.1 0.2 0.3"/><mass value="1.5"/>
    <inertia ixx="0.02" iyy="0.021" izz="0.003" ixy="0.001" ixz="-0.0005" iyz="0.0002"/></inertial></link>
  <link name="finger_a"><inertial><origin xyz="0 0.02 0.05"/><mass value="0.3"/>
    <inertia ixx="0.001" iyy="0.001" izz="0.0005" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="finger_b"><inertial><origin xyz="0 -0.02 0.05"/><mass value="0.3"/>
    <inertia ixx="0.001" iyy="0.001" izz="0.0005" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.1" rpy="0 0 0.5"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="100" velocity="10"/></joint>
  <joint name="finger_a_joint" type="prismatic"><parent link="upper"/><child link="finger_a"/>
    <origin xyz="0 0 0.4"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="100" velocity="10"/></joint>
  <joint name="finger_b_joint" type="prismatic"><parent link="upper"/><child link="finger_b"/>
    <origin xyz="0 0 0.4" rpy="0.2 0 0"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="100" velocity="10"/>
    <mimic joint="finger_a_joint" multiplier="-0.8" offset="0.01"/></joint>
</robot>
"""

SCENE = """name = "gripper"
[model]
kind = "urdf"
file = "arm.urdf"
gravity = [0.0, 0.0, -9.81]
{extra}
[model.ignore]
joint_limit = "inside"
effort_limit = "u is the force the motion needs"
velocity_limit = "not part of the dynamics"
{ignore}
[[programme]]
name = "sh"
expr = "shoulder - 0.5*sin(t)"
[[programme]]
name = "open"
expr = "finger_a_joint - 0.02*t*t"
[initial]
q = {{ finger_b_joint = 0.01 }}
v = {{ shoulder = 0.5 }}
[time]
t1 = 1.0
"""


def _scene(tmp: Path, arm: str = ARM, extra: str = "", ignore: str = "") -> Path:
    (tmp / "arm.urdf").write_text(arm)
    p = tmp / "gripper.toml"
    p.write_text(SCENE.format(extra=extra, ignore=ignore))
    return p


def test_the_mimic_is_a_system_row_and_holds_along_the_motion(tmp_path):
    scene = progmo.load(str(_scene(tmp_path)))
    rows = {r["name"]: r for r in scene.rows}
    assert rows["mimic_finger_b_joint"]["role"] == "system", rows
    assert scene.robot_file["mimics"] == [{"joint": "finger_b_joint", "leader": "finger_a_joint",
                                           "multiplier": -0.8, "offset": 0.01}]
    assert not [u for u in scene.unmodelled if u["kind"] == "mimic"]  # modelled, no record
    sol = scene.solve()
    names = list(scene.q_names)
    a, b = names.index("finger_a_joint"), names.index("finger_b_joint")
    q = sol.q
    assert abs(q[-1][a] - 0.02) < 1e-9  # the programme moved the leader
    assert max(abs(qk[b] - (-0.8 * qk[a] + 0.01)) for qk in q) < 1e-10


@pytest.mark.parametrize("sim", ["mujoco", "pinocchio", "drake"])
def test_a_motion_with_a_mimic_passes_with_its_reaction_supplied(tmp_path, sim):
    if sim == "drake":
        pytest.importorskip("pydrake")
    p = _scene(tmp_path)
    r = run_check(str(p), sim, CheckOptions())
    assert r.route == "user's file", r.route
    assert r.status == "pass", (r.reason, r.metrics)
    assert r.supplied == ["mimic_finger_b_joint"]
    assert r.metrics["inverse_dynamics"] <= 1e-12, r.metrics
    assert r.info["replay_supplied_residual"] < 1e-9, r.info
    bad, _ = _run(str(p), sim, withhold=("supplied_reaction",))
    assert bad.status == "fail", (bad.reason, bad.metrics)


def test_mujocos_reading_of_the_law_is_compared(tmp_path):
    p = _scene(tmp_path)
    other = tmp_path / "other.urdf"
    other.write_text(ARM.replace('multiplier="-0.8"', 'multiplier="-0.81"'))
    r, _ = _run(str(p), "mujoco", simulator_file=str(other))
    assert r.status == "error", (r.status, r.reason)
    assert "polycoef [0.01, -0.81, 0.0, 0.0, 0.0], progmo as offset 0.01, multiplier -0.8" in r.reason, r.reason


def test_a_mimic_declared_ignored_leaves_the_joints_independent(tmp_path):
    scene = progmo.load(str(_scene(tmp_path, ignore='mimic = "the fingers move apart"')))
    assert "mimic_finger_b_joint" not in {r["name"] for r in scene.rows}
    assert [u["element"] for u in scene.unmodelled if u["kind"] == "mimic"] == ["joint[finger_b_joint].mimic"]


def test_a_locked_leader_with_a_moving_follower_is_refused_at_the_mimic(tmp_path):
    with pytest.raises(progmo.SceneError) as e:
        progmo.load(str(_scene(tmp_path, extra='locked_joints = ["finger_a_joint"]')))
    assert re.search(r"arm\.urdf:15:.*`finger_a_joint` is locked and `finger_b_joint`.*moves", str(e.value), re.S), str(e.value)
    arm = ARM.replace('joint="finger_a_joint" multiplier', 'joint="nowhere" multiplier')
    with pytest.raises(progmo.SceneError, match="follows `nowhere`, which is not a joint of the file"):
        progmo.load(str(_scene(tmp_path, arm=arm)))
    # declared ignored, the joints are independent and the file loads (the old reading)
    scene = progmo.load(str(_scene(tmp_path, arm=arm, ignore='mimic = "the file names a joint it lacks"')))
    assert "finger_b_joint" in scene.q_names and not scene.robot_file["mimics"]
