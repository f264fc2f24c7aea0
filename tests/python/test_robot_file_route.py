"""Issue 27: the simulators load the user's robot file, not progmo's export of it.

A scene whose model is a robot file (`kind = "urdf"` / `"mjcf"`) is checked against MuJoCo's and
Pinocchio's own reading of that file (`CheckResult.route == "user's file"`): model parity at random
states with nonzero velocities and along the solution, and `inverse_dynamics` (u from mj_inverse /
pin.rnea on the file against the solver's u). Negative controls (each must fail): progmo's model
read from a doctored copy of the file (armature zeroed; damping dropped) while the simulators load
the original; a frictionloss or a tendon in the file the scene does not declare (not_checked naming
it); a joint range the motion leaves (not_checked naming the joint).
"""

import pathlib
import re

import numpy as np
import pytest

from progmo import checks
from progmo.checks import _run

pytest.importorskip("mujoco")
pytest.importorskip("pinocchio")

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENES = ROOT / "references" / "scenes"
SIMS = ("mujoco", "pinocchio")
#: the whole span of mjcf_arm is not needed to judge parity and inverse dynamics
SHORT = checks.CheckOptions(horizon=0.5)


def arm_scene(tmp: pathlib.Path, xml: str, extra_model: str = "") -> pathlib.Path:
    """mjcf_arm.toml reading `xml` (written to tmp) instead of robots/mjcf_arm.xml."""
    f = tmp / "arm.xml"
    f.write_text(xml)
    text = (SCENES / "mjcf_arm.toml").read_text()
    text = text.replace('file = "robots/mjcf_arm.xml"', f'file = "{f}"' + ("\n" + extra_model if extra_model else ""))
    p = tmp / "arm.toml"
    p.write_text(text)
    return p


def arm_xml() -> str:
    return (SCENES / "robots" / "mjcf_arm.xml").read_text()


@pytest.mark.parametrize("sim", SIMS)
def test_robot_scene_takes_the_users_file_route(sim):
    r = checks.run_check(str(SCENES / "ur5_tool_path.toml"), sim, SHORT)
    assert r.route == "user's file", r.route
    assert r.status == "pass", r.reason
    assert "inverse_dynamics" in r.metrics and r.metrics["inverse_dynamics"] <= 1e-12
    assert any(b.metric == "inverse_dynamics" for b in r.budgets)
    # a scene written in the scene file keeps progmo's export
    t = checks.run_check(str(SCENES / "double_pendulum.toml"), sim, SHORT)
    assert t.route == "progmo export" and "inverse_dynamics" not in t.metrics


@pytest.mark.parametrize("sim", SIMS)
def test_negative_control_armature_zeroed_in_progmos_copy_fails(sim, tmp_path):
    xml = arm_xml()
    assert "armature=" in xml, "mjcf_arm.xml carries armature (issue 27)"
    scene = arm_scene(tmp_path, re.sub(r'armature="[^"]*"', 'armature="0"', xml))
    r, _ = _run(str(scene), sim, SHORT, simulator_file=str(SCENES / "robots" / "mjcf_arm.xml"))
    assert r.status == "fail", r.reason
    assert "parity_mass" in r.reason and "worst joint" in r.reason, r.reason


@pytest.mark.parametrize("sim", SIMS)
def test_negative_control_damping_dropped_in_progmos_copy_fails(sim, tmp_path):
    xml = arm_xml()
    scene = arm_scene(tmp_path, re.sub(r' damping="[^"]*"', "", xml))
    r, _ = _run(str(scene), sim, SHORT, simulator_file=str(SCENES / "robots" / "mjcf_arm.xml"))
    assert r.status == "fail", r.reason
    assert "parity_bias" in r.reason and "inverse_dynamics" in r.reason, r.reason
    assert "worst joint" in r.reason


@pytest.mark.parametrize("sim", SIMS)
def test_undeclared_frictionloss_is_not_checked(sim, tmp_path):
    scene = arm_scene(tmp_path, arm_xml().replace('<joint name="elbow"/>', '<joint name="elbow" frictionloss="0.2"/>'))
    r = checks.run_check(str(scene), sim, SHORT)
    assert r.status == "not_checked" and not r.expected, r.reason
    assert "frictionloss" in r.reason and "elbow" in r.reason, r.reason
    assert not r.ok()


@pytest.mark.parametrize("sim", SIMS)
def test_undeclared_tendon_is_not_checked(sim, tmp_path):
    tendon = ('  <tendon>\n    <fixed name="coupling"><joint joint="shoulder" coef="1"/>'
              '<joint joint="elbow" coef="-1"/></fixed>\n  </tendon>\n</mujoco>')
    scene = arm_scene(tmp_path, arm_xml().replace("</mujoco>", tendon))
    r = checks.run_check(str(scene), sim, SHORT)
    assert r.status == "not_checked" and not r.expected, r.reason
    assert "tendon" in r.reason and "coupling" in r.reason, r.reason


@pytest.mark.parametrize("sim", SIMS)
def test_a_joint_range_the_motion_leaves_is_not_checked(sim, tmp_path):
    # the yaw joint turns by a few degrees along the line; a 0.5 degree range is left at once
    scene = arm_scene(tmp_path, arm_xml().replace('<joint name="yaw" class="yaw"/>',
                                                  '<joint name="yaw" class="yaw" range="-0.5 0.5"/>'))
    r = checks.run_check(str(scene), sim, SHORT)
    assert r.status == "not_checked" and not r.expected, r.reason
    assert "yaw" in r.reason and "range" in r.reason, r.reason


ROBOT_SCENES = ("mjcf_arm", "spring_arm", "panda_circle", "ur5_tool_path", "xarm7_elbow_height", "solo12_com_sway")


def backends(name: str, drop_gravcomp: bool = False):
    """Both back-ends on the scene's robot file (the route of the check)."""
    import progmo
    from progmo.simulators.mujoco_sim import MujocoBackend
    from progmo.simulators.pinocchio_sim import PinocchioBackend
    from progmo.simulators.robot_file import robot_file

    scene = progmo.load(str(SCENES / f"{name}.toml"))
    rf = robot_file(scene)
    mj = MujocoBackend(*scene.export("mjcf"), scene, robot=rf)
    pb = PinocchioBackend(*scene.export("urdf"), scene, robot=rf)
    if drop_gravcomp:
        pb.file.gravcomp = []
    return scene, mj, pb


def sim_vs_sim(scene, mj, pb) -> tuple[float, float, float]:
    """Largest relative difference of M, the field forces and the inverse-dynamics force between
    MuJoCo's and Pinocchio's readings of the same file (with the harness's additions), at 10 random
    states near q0 (inside the joint ranges) with random velocities and accelerations."""
    rng = np.random.default_rng(5)
    wm = wf = wi = 0.0
    for _ in range(10):
        q = np.array(scene.q0) + rng.uniform(-0.05, 0.05, len(scene.q0))
        for g in mj.cm.quats:  # a free base's quaternion stays a unit one
            q[g] /= np.linalg.norm(q[g])
        v, a = rng.uniform(-2, 2, (2, len(scene.v0)))
        M1, f1 = mj.model_terms(0.0, q, v)
        M2, f2 = pb.model_terms(0.0, q, v)
        i1, i2 = mj.inverse_force(0.0, q, v, a), pb.inverse_force(0.0, q, v, a)
        wm = max(wm, np.abs(M1 - M2).max() / np.abs(M1).max())
        wf = max(wf, np.abs(f1 - f2).max() / np.abs(f1).max())
        wi = max(wi, np.abs(i1 - i2).max() / np.abs(i1).max())
    return wm, wf, wi


@pytest.mark.parametrize("name", ROBOT_SCENES)
def test_mujoco_and_pinocchio_read_the_same_file_alike(name):
    """The two readings of one file, with what the harness adds to Pinocchio's (damping, and the
    springs and gravcomp its MJCF reader skips), agree: M, field forces and inverse dynamics."""
    scene, mj, pb = backends(name)
    wm, wf, wi = sim_vs_sim(scene, mj, pb)
    print(f"{name}: MuJoCo vs Pinocchio on the file: M {wm:.1e}, field forces {wf:.1e}, inverse {wi:.1e}")
    assert max(wm, wf, wi) <= 1e-13


def test_negative_control_pinocchio_without_the_gravcomp_the_harness_adds_differs():
    scene, mj, pb = backends("spring_arm", drop_gravcomp=True)
    wm, wf, wi = sim_vs_sim(scene, mj, pb)
    assert wm <= 1e-13 and wf > 1e-3 and wi > 1e-3


def test_centroidal_angular_momentum_matches_pinocchio(tmp_path):
    """Issue 30 item 4: `com.hx` ... (the angular momentum about the centre of mass, world frame),
    its rate `com.hx'` and its Jacobian equal Pinocchio's computeCentroidalMomentum (hg),
    computeCentroidalMomentumTimeVariation (dhg) and ccrba (Ag, through the check's coordinate
    map) on the free-floating Solo-12 at random states; one link 10 % heavier in Pinocchio's model
    must fail the same comparison."""
    import pinocchio as pin

    import progmo

    rows = "".join(f'[[programme]]\nname = "h{c}{len(d)}"\nexpr = "com.h{c}{d}"\n' for d in ("", "'") for c in "xyz")
    scene_file = tmp_path / "h.toml"
    scene_file.write_text(
        'name = "h"\n[model]\nkind = "urdf"\n'
        'file = "package://example-robot-data/robots/solo_description/robots/solo12.urdf"\n'
        'root_joint = "free"\ngravity = [0.0, 0.0, -9.81]\n' + rows
        + '[initial]\nassemble = false\nq = { root = [0.0, 0.0, 0.25, 1.0, 0.0, 0.0, 0.0], FL_KFE = -1.0 }\n'
        '[time]\nt1 = 1.0\n')
    scene = progmo.load(str(scene_file))
    from progmo.simulators.pinocchio_sim import PinocchioBackend
    from progmo.simulators.robot_file import robot_file

    pb = PinocchioBackend(*scene.export("urdf"), scene, robot=robot_file(scene))
    cm, n = pb.cm, len(scene.v_names)

    def worst(model) -> float:
        d = model.createData()
        rng = np.random.default_rng(9)
        w = 0.0
        for _ in range(5):
            q = np.array(scene.q0) + rng.uniform(-0.5, 0.5, len(scene.q0))
            for g in cm.quats:
                q[g] /= np.linalg.norm(q[g])
            v, a = rng.uniform(-1.0, 1.0, (2, n))
            qs, vs, as_ = cm.q_to_sim(q), cm.v_to_sim(q, v), cm.a_to_sim(q, v, a)
            hg = pin.computeCentroidalMomentum(model, d, qs, vs).angular.copy()
            dhg = pin.computeCentroidalMomentumTimeVariation(model, d, qs, vs, as_).angular.copy()
            ours = np.asarray(scene.residuals(np.zeros(1), q[None, :], v[None, :], a[None, :]))[0]
            w = max(w, np.abs(ours[:3] - hg).max(), np.abs(ours[3:] - dhg).max())
            Ag = pin.ccrba(model, d, qs, vs)[3:6]
            J = np.asarray(scene.residuals(np.zeros(n), np.tile(q, (n, 1)), np.eye(n), np.zeros((n, n)))).T[:3]
            w = max(w, np.abs(Ag @ cm.P(q) - J).max())
        return w

    w = worst(pb.model)
    print(f"solo12: angular momentum about the centre of mass vs Pinocchio: {w:.1e}")
    assert w <= 1e-12
    heavy = pb.model.copy()
    heavy.inertias[3].mass *= 1.1
    assert worst(heavy) > 1e-4
