"""URDF ``continuous`` joints over the user's file: Pinocchio reads them as unbounded revolute joints
(q = (cos θ, sin θ), one velocity); the check maps progmo's angle θ to and from that pair, keeping θ
continuous over whole turns. Was: "no coordinate map", the Pinocchio side not checked.

Reference of independent origin: Pinocchio's own reading of the file (A, G + Q at random states in
the corpus comparison; its RKMK replay of u). Negative controls: a heavier link in Pinocchio's copy
fails the comparison; the angle read back without the step before wraps by 2π."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from progmo import checks, corpus
from progmo.simulators.replay import CoordMap

pytest.importorskip("pinocchio")
pytest.importorskip("mujoco")

ARM = """<robot name="wheel_arm">
  <link name="base"><inertial><mass value="2"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="upper"><inertial><origin xyz="0 0 0.2" rpy="0.1 0.2 0.3"/><mass value="{m}"/>
    <inertia ixx="0.02" iyy="0.021" izz="0.003" ixy="0.001" ixz="-0.0005" iyz="0.0002"/></inertial></link>
  <link name="lower"><inertial><origin xyz="0.05 0 0.15"/><mass value="1"/>
    <inertia ixx="0.01" iyy="0.01" izz="0.002" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.1" rpy="0 0 0.5"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="100" velocity="10"/></joint>
  <joint name="elbow" type="continuous"><parent link="upper"/><child link="lower"/>
    <origin xyz="0 0 0.4" rpy="0.3 0 0"/><axis xyz="{axis}"/></joint>
</robot>
"""

SCENE = """name = "wheel_arm"
[model]
kind = "urdf"
file = "{file}"
gravity = [0.0, 0.0, -9.81]
[model.ignore]
effort_limit = "u is judged as the force the motion needs"
velocity_limit = "not part of the dynamics"
joint_limit = "the shoulder stays inside its range"
[[programme]]
name = "shoulder"
expr = "shoulder - 0.3*sin(pi*t)"
[[programme]]
name = "elbow_turns"
expr = "elbow - (2.5 + 2.0*t*t)"
[initial]
q = {{ shoulder = 0.0, elbow = 2.5 }}
v = {{ shoulder = "0.3*pi", elbow = 0.0 }}
[time]
t1 = 1.0
"""


def _arm(tmp: Path, mass: float = 1.5, axis: str = "1 0 1", name: str = "arm.urdf") -> Path:
    f = tmp / name
    f.write_text(ARM.format(m=mass, axis=axis))
    return f


@pytest.mark.parametrize("axis", ["1 0 1", "0 0 1"])  # unaligned (RevoluteUnboundedUnaligned), RUBZ
def test_continuous_joint_is_compared_with_pinocchios_reading(tmp_path, axis):
    arm = _arm(tmp_path, axis=axis)
    (rec,) = [r for r in corpus.check_file("urdf", arm, tmp_path) if r["root_joint"] == "fixed"]
    for s in corpus.SIMULATORS:
        assert rec["parity"][s]["status"] == "ok", rec["parity"][s]
        assert rec["parity"][s]["worst"] <= corpus.PARITY_TOL, rec["parity"][s]
    heavier = _arm(tmp_path, mass=1.5 * 1.01, axis=axis, name="heavier.urdf")
    (bad,) = [r for r in corpus.check_file("urdf", arm, tmp_path, simulator_file=heavier,
                                           simulators=("pinocchio",)) if r["root_joint"] == "fixed"]
    assert bad["parity"]["pinocchio"]["status"] == "ok" and bad["parity"]["pinocchio"]["worst"] > 1e-4


def test_a_motion_over_pi_on_a_continuous_joint_passes_in_pinocchio(tmp_path):
    """The elbow turns from 2.5 to 4.5 rad (past π, where atan2 wraps): the replay reads the angle
    back continuous and the open-loop replay stays on the motion."""
    scene = tmp_path / "wheel_arm.toml"
    scene.write_text(SCENE.format(file=_arm(tmp_path)))
    r = checks.run_check(str(scene), "pinocchio", checks.CheckOptions())
    assert r.route == "user's file", r.route
    assert r.status == "pass", r.reason
    assert r.metrics["replay_deviation"] <= 1e-8, r.metrics
    assert r.metrics["inverse_dynamics"] <= 1e-12, r.metrics


def test_angle_is_read_back_continuous_only_with_the_step_before():
    report = {"q_map": [{"index": 0, "sim_index": 0, "name": "a", "sim_joint": "a"},
                        {"index": 1, "sim_index": 1, "name": "b", "sim_joint": "b"}],
              "v_map": [{"index": 0, "sim_index": 0, "name": "a", "sim_joint": "a", "conversion": "same"},
                        {"index": 1, "sim_index": 1, "name": "b", "sim_joint": "b", "conversion": "same"}],
              "sim_unbounded": [1]}
    cm = CoordMap(report)
    assert cm.nq_sim == 3
    q = np.array([0.7, 4.0])
    qs = cm.q_to_sim(q)
    np.testing.assert_allclose(qs, [0.7, math.cos(4.0), math.sin(4.0)], rtol=0, atol=1e-16)
    np.testing.assert_allclose(cm.q_from_sim(qs, near=np.array([0.0, 3.9])), q, rtol=0, atol=1e-15)
    # negative control: without the step before, atan2's branch (-π, π] is 2π away
    assert cm.q_from_sim(qs)[1] == pytest.approx(4.0 - 2 * math.pi, abs=1e-15)
