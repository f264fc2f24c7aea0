"""URDF ``planar`` joints (issue 30 item 2): imported as two slides and a hinge in the plane normal
to the joint's axis, named ``NAME_TX``, ``NAME_TY``, ``NAME_RZ`` as MuJoCo's URDF compiler names
them. References of independent origin: MuJoCo's and Pinocchio's own readings of the file (A and
G + Q at random states; an open-loop replay of a motion that turns past π). Pinocchio reads the
joint as JointModelPlanar (x, y, cos θ, sin θ; velocity in the moving frame), mapped by the check;
it ignores the file's axis, so another axis than z is not checked there (MuJoCo honours it).
Negative controls: a heavier puck in the simulators' copy fails; an axis flipped in MuJoCo's copy
fails."""

from __future__ import annotations

from pathlib import Path

import pytest

from progmo import checks, corpus

pytest.importorskip("mujoco")
pytest.importorskip("pinocchio")

PUCK = """<robot name="puck">
  <link name="base"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="puck"><inertial><origin xyz="0.1 0.02 0.03" rpy="0.2 0 0"/><mass value="{m}"/>
    <inertia ixx="0.15" iyy="0.2" izz="0.3" ixy="0.01" ixz="0" iyz="0.02"/></inertial></link>
  <link name="arm"><inertial><origin xyz="0.2 0 0"/><mass value="0.5"/>
    <inertia ixx="0.01" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="table" type="planar"><parent link="base"/><child link="puck"/>
    <origin xyz="0 0 0.5" rpy="0.3 0.1 0"/><axis xyz="{axis}"/><dynamics damping="0.2"/></joint>
  <joint name="hinge" type="revolute"><parent link="puck"/><child link="arm"/>
    <origin xyz="0.1 0 0.1"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="100" velocity="10"/></joint>
</robot>
"""

SCENE = """name = "puck"
[model]
kind = "urdf"
file = "{file}"
gravity = [0.0, 0.0, -9.81]
[model.ignore]
effort_limit = "u is judged as the force the motion needs"
velocity_limit = "not part of the dynamics"
joint_limit = "the hinge stays inside its range"
[[programme]]
name = "x"
expr = "table_TX - 0.2*sin(pi*t)"
[[programme]]
name = "y"
expr = "table_TY - 0.1*t*t"
[[programme]]
name = "turn"
expr = "table_RZ - (2.5 + 2.0*t*t)"
[[programme]]
name = "arm"
expr = "hinge - 0.3*t"
[initial]
q = {{ table_TX = 0.0, table_TY = 0.0, table_RZ = 2.5, hinge = 0.0 }}
v = {{ table_TX = "0.2*pi", table_TY = 0.0, table_RZ = 0.0, hinge = 0.3 }}
[time]
t1 = 1.0
"""


def _puck(tmp: Path, axis: str = "0 0 1", mass: float = 2.0, name: str = "puck.urdf") -> Path:
    f = tmp / name
    f.write_text(PUCK.format(axis=axis, m=mass))
    return f


def _fixed(records: list[dict]) -> dict:
    (rec,) = [r for r in records if r["root_joint"] == "fixed"]
    return rec


def test_planar_joint_matches_both_simulators(tmp_path):
    rec = _fixed(corpus.check_file("urdf", _puck(tmp_path), tmp_path))
    assert rec["imported"] and rec["nv"] == 4
    for s in corpus.SIMULATORS:
        assert rec["parity"][s]["status"] == "ok", rec["parity"][s]
        assert rec["parity"][s]["worst"] <= corpus.PARITY_TOL, rec["parity"][s]
    heavier = _puck(tmp_path, mass=2.02, name="heavier.urdf")
    bad = _fixed(corpus.check_file("urdf", _puck(tmp_path), tmp_path, simulator_file=heavier))
    for s in corpus.SIMULATORS:
        assert bad["parity"][s]["status"] == "ok" and bad["parity"][s]["worst"] > 1e-4, bad["parity"][s]


@pytest.mark.parametrize("axis", ["1 0 0", "0 -1 1", "0 0 -1"])
def test_planar_axis_is_the_planes_normal_as_mujoco_reads_it(tmp_path, axis):
    rec = _fixed(corpus.check_file("urdf", _puck(tmp_path, axis=axis), tmp_path))
    assert rec["parity"]["mujoco"]["status"] == "ok" and rec["parity"]["mujoco"]["worst"] <= corpus.PARITY_TOL
    assert rec["parity"]["pinocchio"]["status"] == "not_compared"
    assert "not normal to the file's axis" in rec["parity"]["pinocchio"]["reason"]
    flipped = _puck(tmp_path, axis="0 1 0", name="flipped.urdf")
    bad = _fixed(corpus.check_file("urdf", _puck(tmp_path, axis=axis), tmp_path, simulator_file=flipped,
                                   simulators=("mujoco",)))
    assert bad["parity"]["mujoco"]["worst"] > 1e-4


@pytest.mark.parametrize("sim", ["mujoco", "pinocchio"])
def test_a_motion_on_a_planar_joint_passes_open_loop(tmp_path, sim):
    """x, y and a turn from 2.5 to 4.5 rad (past π: Pinocchio's (cos θ, sin θ) wraps there) with
    the joint's damping, through the user's file."""
    scene = tmp_path / "puck.toml"
    scene.write_text(SCENE.format(file=_puck(tmp_path)))
    r = checks.run_check(str(scene), sim, checks.CheckOptions())
    assert r.route == "user's file", r.route
    assert r.status == "pass", r.reason
    assert r.metrics["inverse_dynamics"] <= 1e-12, r.metrics
