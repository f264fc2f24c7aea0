"""The Drake back-end (issue 32): forces and conventions reach Drake, its RK4 replay on Drake's
derivatives is 4th order because u is read at every stage time, and the negative controls fail in Drake as in the other
two simulators (a withheld force, a 1 % mass error, Drake's MJCF reading of mjcf_arm). Skipped, and
said, where Drake is not installed."""

import pathlib
import re

import numpy as np
import pytest

pytest.importorskip("pydrake", reason="Drake is not installed (pip install 'progmo[drake]')")

from progmo import Scene  # noqa: E402
from progmo import checks  # noqa: E402
from progmo.checks import CheckOptions, _run, run_check  # noqa: E402
from progmo.simulators import Unsupported  # noqa: E402
from progmo.simulators import drake_sim  # noqa: E402
from progmo.simulators.replay import Reference  # noqa: E402
from progmo.simulators.robot_file import RobotFile  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENES = ROOT / "references" / "scenes"
POINT = str(ROOT / "tests" / "scenes" / "point_forces.toml")
#: a short replay of point_forces at h = 5e-3
SHORT = CheckOptions(horizon=0.5, step=5e-3)


def test_point_and_coordinate_forces_reach_drake():
    r = run_check(POINT, "drake", SHORT)
    assert r.status == "pass", (r.reason, r.metrics)
    assert r.metrics["parity_bias"] < 1e-13 and r.metrics["instant_u"] < 1e-12, r.metrics
    assert r.metrics["replay_residual"] < 1e-9 and r.metrics["replay_deviation"] < 1e-9, r.metrics
    assert any("RK4 in fixed steps on its CalcTimeDerivatives" in n for n in r.notes), r.notes


@pytest.mark.parametrize("kind", ["point_force", "coordinate_force"])
def test_a_force_withheld_from_drake_fails(kind):
    r, _ = _run(POINT, "drake", SHORT, withhold=(kind,))
    assert r.status == "fail", (r.reason, r.metrics)
    b = next(b for b in r.breaches if b.metric == "parity_bias")
    assert b.value > 1e-3
    force = "the scene's point forces" if kind == "point_force" else "the coordinate force on q1"
    assert re.fullmatch(rf"joint q[12], {force} \(discrepancy = -1 x its force: the simulator misses it\)",
                        b.where), b.where


def test_a_one_percent_mass_error_fails_in_drake():
    def wrong(doc):
        k = [m.start() for m in re.finditer(r'<mass value="1\.0"/>', doc)][-1]
        return doc[:k] + doc[k:k + 30].replace("1.0", "1.01", 1) + doc[k + 30:]

    r, _ = _run(POINT, "drake", SHORT, corrupt_export=wrong)
    assert r.status == "fail", (r.reason, r.metrics)
    assert "parity_mass" in {b.metric for b in r.breaches} and r.metrics["parity_mass"] > 1e-4


def _deviation(h: float) -> float:
    r = run_check(str(SCENES / "double_pendulum.toml"), "drake", CheckOptions(horizon=1.0, step=h))
    assert "replay_deviation" in r.metrics, r.reason
    return r.metrics["replay_deviation"]


def test_replay_is_fourth_order_with_u_at_every_stage(monkeypatch):
    """Error against step: halving h divides it by about 16 (RK4 on Drake's derivatives, u read at
    every stage time). Negative control: u held at each step's start (a zero-order hold, what a
    replay that ignores the stages does) caps it at order 1."""
    e1, e2 = _deviation(2e-2), _deviation(1e-2)
    assert np.log2(e1 / e2) > 3.6, (e1, e2)
    orig = Reference.force_at

    def held(self, time, q):
        return orig(self, self.t0 + np.floor((time - self.t0) / self.h + 1e-9) * self.h, q)

    monkeypatch.setattr(Reference, "force_at", held)
    c1, c2 = _deviation(2e-2), _deviation(1e-2)
    assert np.log2(c1 / c2) < 1.5 and c2 > 100 * e2, (c1, c2, e2)


@pytest.mark.parametrize("name", ["rolling_disk", "example_3_1_free"])
def test_free_and_ball_joint_conventions(name):
    """Drake's quaternion floating joint (world-frame angular and linear velocity) and BallRpyJoint
    (rpy): q round trip and model parity with our A, G + Q at random states."""
    scene = Scene(str(SCENES / f"{name}.toml"))
    doc, report = scene.export("urdf", supply_reactions=True)
    be = drake_sim.DrakeBackend(doc, report, scene)
    rng = np.random.default_rng(3)
    for _ in range(4):
        q = np.array(scene.q0, float) + 0.3 * rng.standard_normal(len(scene.q0))
        for g in be.cm.quats:
            q[g] /= np.linalg.norm(q[g])
        v = rng.standard_normal(len(scene.v0))
        assert np.allclose(be.cm.q_from_sim(be.cm.q_to_sim(q)), q, atol=1e-14) or \
            np.allclose(-be.cm.q_from_sim(be.cm.q_to_sim(q))[be.cm.quats[0]], q[be.cm.quats[0]], atol=1e-14)
        M, rhs = be.model_terms(0.0, q, v)
        d = scene.dynamics(0.0, q, v)
        A, GQ = np.asarray(d["mass"]), np.asarray(d["velocity_terms"]) + np.asarray(d["applied_forces"])
        assert np.abs(M - A).max() < 1e-12 * np.abs(A).max()
        assert np.abs(rhs - GQ).max() < 1e-12 * max(1.0, np.abs(GQ).max())
        # the velocity map is not the identity here: a wrong convention would show
        assert not np.allclose(be.cm.P(q), np.eye(len(v)))


def test_closures_are_declared_not_checked():
    r = run_check(str(SCENES / "four_bar.toml"), "drake")
    assert r.status == "not_checked"
    assert "Continuous time does not support constraints" in r.reason, r.reason


def test_mimic_is_refused(tmp_path):
    p = tmp_path / "m.urdf"
    p.write_text("""<robot name="m"><link name="world"/><link name="a"><inertial><mass value="1"/>
      <inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial></link>
      <link name="b"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/>
      </inertial></link>
      <joint name="j1" type="revolute"><parent link="world"/><child link="a"/><axis xyz="0 0 1"/></joint>
      <joint name="j2" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
      <mimic joint="j1" multiplier="1"/></joint></robot>""")
    with pytest.raises(Unsupported, match="mimic"):
        drake_sim.user_urdf(RobotFile(p, "urdf"), {})
    assert "mimic" not in drake_sim.user_urdf(RobotFile(p, "urdf"), {"j2": 0.4})


def test_drakes_mjcf_reading_of_mjcf_arm_fails_parity():
    """Negative control of the route Drake does not take: Drake's own MJCF parser misplaces the
    wrist's joints (relative mass-matrix error ~0.3), while the URDF export it reads agrees."""
    scene = Scene(str(SCENES / "mjcf_arm.toml"))
    doc, report = scene.export("urdf", supply_reactions=True)
    q = np.array(scene.q0, float) + 0.2
    A = np.asarray(scene.dynamics(0.0, q, np.zeros(len(q)))["mass"])
    be = drake_sim.DrakeBackend(doc, report, scene)
    M_export = be.model_terms(0.0, q, np.zeros(len(q)))[0]
    assert np.abs(M_export - A).max() < 1e-12 * np.abs(A).max()
    # with or without the file's armature (whether Drake's MJCF parser reads it or not)
    arm = np.diag([a["armature"] for a in report["armature"]])
    M_mjcf = drake_sim.mjcf_parity(str(SCENES / "robots" / "mjcf_arm.xml"), report, q)
    assert min(np.abs(M_mjcf - A).max(), np.abs(M_mjcf - (A - arm)).max()) > 0.1 * np.abs(A).max()


def test_a_missing_drake_is_named_not_dropped(monkeypatch):
    from progmo.cli import default_simulators

    monkeypatch.setattr(checks, "available", lambda m: "No module named 'pydrake' (install: pip install "
                        "'progmo[drake]')" if m == "drake" else None)
    sims, notes = default_simulators(None)
    assert sims == ["mujoco", "pinocchio"]
    assert notes and "drake NOT CHECKED" in notes[0] and "progmo[drake]" in notes[0]
    assert default_simulators(["drake"]) == (["drake"], [])
