"""Issue 13: robots imported from their URDF (model.kind = "urdf") against Pinocchio's own reading of
the same file (`pin.buildModelFromUrdf`, locked joints removed with `pin.buildReducedModel` at q = 0):
A(q) (CRBA) and G + Q (-RNEA(q, v, 0) with the scene's gravity) at random states, relative 1e-12 of
the natural scale (as test_export_parity.py). The MJCF/URDF exports of the same scenes are compared
by test_export_parity.py (they are tree systems). Negative control: a 1 % heavier link in
Pinocchio's model must fail the same comparison."""

import pathlib
import tomllib
import zlib

import numpy as np
import pinocchio as pin
import pytest

import progmo
from progmo import data

ROOT = pathlib.Path(__file__).resolve().parents[2]
TOL = 1e-12


def urdf_scenes() -> list[pathlib.Path]:
    """The catalog's fixed-base URDF scenes (the comparisons below map 1-dof joints by name; the
    free-floating solo12_com_sway is compared through the check's coordinate map:
    test_robot_file_route.py)."""
    out = []
    for p in sorted((ROOT / "references" / "scenes").glob("*.toml")):
        with open(p, "rb") as f:
            m = tomllib.load(f)["model"]
            if m["kind"] == "urdf" and m.get("root_joint", "fixed") == "fixed":
                out.append(p)
    return out


def pin_model(path: pathlib.Path) -> pin.Model:
    """Pinocchio's own model of the scene's URDF (file found by the same package:// rule)."""
    with open(path, "rb") as f:
        m = tomllib.load(f)["model"]
    rest = m["file"].removeprefix("package://")
    urdf = next(d / rest for d in data.robot_path() if (d / rest).is_file())
    model = pin.buildModelFromUrdf(str(urdf))
    locked = [model.getJointId(n) for n in m.get("locked_joints", [])]
    if locked:
        model = pin.buildReducedModel(model, locked, pin.neutral(model))
    model.gravity.linear = np.array(m.get("gravity", [0.0, 0.0, 0.0]))
    return model


def worst(scene, model: pin.Model) -> tuple[float, float]:
    d = model.createData()
    names = [model.names[j] for j in range(1, model.njoints)]
    assert sorted(names) == sorted(scene.q_names), "1-dof joints, same names"
    perm = [scene.q_names.index(n) for n in names]  # pinocchio index -> ours
    rng = np.random.default_rng(zlib.crc32(scene.name.encode()))
    wa = wf = 0.0
    for _ in range(10):
        q = np.array(scene.q0) + rng.uniform(-0.5, 0.5, len(perm))
        v = rng.uniform(-1.0, 1.0, len(perm))
        ours = scene.dynamics(0.0, q, v)
        A, f = ours["mass"], ours["velocity_terms"] + ours["applied_forces"]
        M = pin.crba(model, d, q[perm])
        M = np.triu(M) + np.triu(M, 1).T
        b = pin.rnea(model, d, q[perm], v[perm], np.zeros(len(perm)))
        Ap, fp = A[np.ix_(perm, perm)], f[perm]
        wa = max(wa, np.abs(M - Ap).max() / np.abs(Ap).max())
        scale = max(np.abs(fp).max(), np.abs(Ap).max() * np.abs(v).max() ** 2)
        # joint damping (<dynamics damping>, read by Pinocchio into model.damping) is modelled
        wf = max(wf, np.abs(-b - model.damping * v[perm] - fp).max() / scale)
    return wa, wf


@pytest.mark.parametrize("path", urdf_scenes(), ids=lambda p: p.stem)
def test_imported_robot_matches_pinocchio_urdf(path):
    scene = progmo.load(str(path))
    wa, wf = worst(scene, pin_model(path))
    print(f"{scene.name}: |dA| {wa:.2e}, |d(G + Q)| {wf:.2e}")
    assert wa <= TOL and wf <= TOL, f"{scene.name}: |dA| = {wa:.2e}, |d(G + Q)| = {wf:.2e}"


@pytest.mark.parametrize("path", urdf_scenes(), ids=lambda p: p.stem)
def test_negative_control_heavier_link_fails(path):
    scene = progmo.load(str(path))
    model = pin_model(path)
    j = model.njoints - 1
    model.inertias[j].mass *= 1.01
    wa, wf = worst(scene, model)
    assert wa > 1e3 * TOL and wf > 1e3 * TOL


def test_urdf_scenes_are_present():
    assert {p.stem for p in urdf_scenes()} >= {"panda_circle", "ur5_tool_path", "xarm7_elbow_height"}


def frame_worst(scene, model: pin.Model) -> tuple[float, int]:
    """Largest |position difference| (m) and |rotation-matrix difference| over every link of ours
    that Pinocchio's model also names (`Scene.body_poses` vs `pin.framesForwardKinematics`), at
    random states; and how many links were compared."""
    d = model.createData()
    names = [model.names[j] for j in range(1, model.njoints)]
    perm = [scene.q_names.index(n) for n in names]
    rng = np.random.default_rng(zlib.crc32(scene.name.encode()) + 1)
    w, count = 0.0, 0
    for _ in range(10):
        q = np.array(scene.q0) + rng.uniform(-0.5, 0.5, len(perm))
        pin.framesForwardKinematics(model, d, q[perm])
        count = 0
        for name, pos, quat in scene.body_poses(q):
            if not model.existFrame(name):
                continue
            f = d.oMf[model.getFrameId(name)]
            wq, x, y, z = quat
            R = pin.Quaternion(wq, x, y, z).normalized().toRotationMatrix()
            w = max(w, np.abs(np.array(pos) - f.translation).max(), np.abs(R - f.rotation).max())
            count += 1
    return w, count


@pytest.mark.parametrize("path", urdf_scenes(), ids=lambda p: p.stem)
def test_imported_link_frames_match_pinocchio(path):
    """Issue 13 item 3: link positions and orientations of the imported robot agree with
    Pinocchio's frames of the same URDF (robots are about 1 m: 1e-12 m and 1e-12 in R)."""
    scene = progmo.load(str(path))
    w, count = frame_worst(scene, pin_model(path))
    print(f"{scene.name}: {count} links, max |dp|, |dR| = {w:.2e}")
    assert count >= scene.q0.size, "every moving link compared"
    assert w <= TOL, f"{scene.name}: link frames differ by {w:.2e}"


@pytest.mark.parametrize("path", urdf_scenes(), ids=lambda p: p.stem)
def test_negative_control_moved_joint_origin_fails_frames(path):
    """A joint origin 1 mm off in Pinocchio's model must fail the frame comparison."""
    scene = progmo.load(str(path))
    model = pin_model(path)
    model.jointPlacements[2].translation += np.array([1e-3, 0.0, 0.0])
    w, _ = frame_worst(scene, model)
    assert w > 1e-4


JAC_LINK = {"panda_circle": "panda_hand_tcp", "ur5_tool_path": "tool0", "xarm7_elbow_height": "link_eef"}


def jacobian_scene(path: pathlib.Path, tmp: pathlib.Path, link: str) -> "progmo.Scene":
    """The robot of `path` with six velocity rows reading `link`'s world linear velocity (`x'`) and
    angular velocity (`wx`): at v = e_k its residuals are column k of the link's Jacobian."""
    with open(path, "rb") as f:
        m = tomllib.load(f)["model"]
    locked = ", ".join(f'"{j}"' for j in m.get("locked_joints", []))
    rows = [f"{link}.{c}'" for c in "xyz"] + [f"{link}.w{c}" for c in "xyz"]
    text = f'name = "jac"\ndescription = "jacobian probe"\npurpose = "test"\n[model]\nkind = "urdf"\n' \
           f'file = "{m["file"]}"\nlocked_joints = [{locked}]\n' + \
           "".join(f'[[programme]]\nname = "r{k}"\nexpr = "{e}"\n' for k, e in enumerate(rows)) + \
           '[initial]\nassemble = false\n[time]\nt1 = 1.0\n'
    p = tmp / "jac.toml"
    p.write_text(text)
    return progmo.load(str(p))


def jacobian_worst(scene, model: pin.Model, link: str) -> float:
    d = model.createData()
    names = [model.names[j] for j in range(1, model.njoints)]
    perm = [scene.q_names.index(n) for n in names]
    n = len(perm)
    fid = model.getFrameId(link)
    rng = np.random.default_rng(zlib.crc32(link.encode()))
    w = 0.0
    for _ in range(5):
        q = np.array(scene.q0) + rng.uniform(-0.5, 0.5, n)
        # residuals are (sample, row); sample k has v = e_k, so its rows are column k of J
        ours = np.asarray(scene.residuals(np.zeros(n), np.tile(q, (n, 1)), np.eye(n))).T
        pin.computeJointJacobians(model, d, q[perm])
        pin.framesForwardKinematics(model, d, q[perm])
        J = pin.getFrameJacobian(model, d, fid, pin.LOCAL_WORLD_ALIGNED)
        w = max(w, np.abs(J - ours[:, perm]).max())
    return w


@pytest.mark.parametrize("path", urdf_scenes(), ids=lambda p: p.stem)
def test_imported_frame_jacobian_matches_pinocchio(path, tmp_path):
    """Issue 13 item 3: the tool link's Jacobian (world linear and angular velocity per joint rate,
    from the exact signal jets) agrees with pin.getFrameJacobian(LOCAL_WORLD_ALIGNED); a joint origin
    moved 1 mm in Pinocchio's model must fail the same comparison."""
    link = JAC_LINK[path.stem]
    scene = jacobian_scene(path, tmp_path, link)
    w = jacobian_worst(scene, pin_model(path), link)
    print(f"{path.stem}: {link} Jacobian max |dJ| = {w:.2e}")
    assert w <= TOL, f"{path.stem}: {link} Jacobians differ by {w:.2e}"
    bad = pin_model(path)
    bad.jointPlacements[2].translation += np.array([1e-3, 0.0, 0.0])
    assert jacobian_worst(scene, bad, link) > 1e-4


DOTTED = """<robot name="dotted">
  <link name="base.0"/>
  <link name="link_1.0">
    <inertial><origin xyz="0.2 0 0"/><mass value="1.5"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial>
  </link>
  <link name="link-2.0">
    <inertial><origin xyz="0 0 -0.15"/><mass value="0.8"/><inertia ixx="0.006" ixy="0" ixz="0" iyy="0.006" iyz="0" izz="0.001"/></inertial>
  </link>
  <joint name="joint_0.0" type="revolute"><parent link="base.0"/><child link="link_1.0"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="100" velocity="10"/></joint>
  <joint name="joint-1.0" type="revolute"><parent link="link_1.0"/><child link="link-2.0"/>
    <origin xyz="0.4 0 0"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="100" velocity="10"/></joint>
</robot>
"""


def test_names_that_are_not_identifiers_are_written_in_backquotes_and_checked(tmp_path):
    """allegro's ``joint_8.0`` and the like: any name of the file works in rows, backquoted
    (``\\`joint_0.0\\`'``, ``\\`link-2.0\\`.z``); the scene is checked open loop in each simulator's
    own reading of the file, whose names are the file's."""
    from progmo import checks

    (tmp_path / "dotted.urdf").write_text(DOTTED)
    p = tmp_path / "dotted.toml"
    p.write_text('name = "dotted"\n[model]\nkind = "urdf"\nfile = "dotted.urdf"\ngravity = [0.0, 0.0, -9.81]\n'
                 '[model.ignore]\njoint_limit = "the motion stays within +-3 rad"\n'
                 'effort_limit = "u is the generalized force the motion needs"\n'
                 'velocity_limit = "not part of the dynamics"\n'
                 '[[programme]]\nname = "turn"\nexpr = "`joint_0.0` - 0.4*(1 - cos(2*t))"\n'
                 '[[programme]]\nname = "tilt"\nexpr = "`link-2.0`.qw - cos(0.25)*cos(`joint_0.0`/2)"\n'
                 '[initial]\nq = { "joint-1.0" = 0.5 }\n[time]\nt1 = 1.0\n')
    scene = progmo.load(str(p))
    assert scene.q_names == ["joint_0.0", "joint-1.0"]
    sol = scene.solve()
    q = np.asarray(sol.q)
    assert sol.success, sol.message
    assert np.abs(q[:, 0] - 0.4 * (1 - np.cos(2 * np.asarray(sol.t)))).max() < 1e-8
    assert np.abs(q[:, 1] - 0.5).max() < 1e-8  # qw = cos(q0/2) cos(q1/2) holds q1 at 0.5
    for sim in ("mujoco", "pinocchio"):
        r = checks.run_check(str(p), sim)
        assert r.status == "pass", (sim, r.status, r.reason, r.metrics)
        assert r.metrics["parity_mass"] <= 1e-12 and r.metrics["replay_residual"] <= 1e-6, (sim, r.metrics)
    # unquoted, the dot reads as a signal's: the error says how to write the name
    p.write_text(p.read_text().replace("`joint_0.0`", "joint_0.0"))
    with pytest.raises(progmo.SceneError, match=r"backquotes"):
        progmo.load(str(p))
    # a misspelt name is suggested as it must be written
    p.write_text(p.read_text().replace("joint_0.0 -", "`joint_0.1` -"))
    with pytest.raises(progmo.SceneError, match=r"did you mean `` `joint_0.0` ``"):
        progmo.load(str(p))


def com_scene(path: pathlib.Path, tmp: pathlib.Path, order: str) -> "progmo.Scene":
    """The robot of `path` with three rows reading the centre of mass at one derivative `order`
    ("", "'" or "''")."""
    with open(path, "rb") as f:
        m = tomllib.load(f)["model"]
    locked = ", ".join(f'"{j}"' for j in m.get("locked_joints", []))
    rows = [f"com.{c}{order}" for c in "xyz"]
    text = f'name = "com"\n[model]\nkind = "urdf"\nfile = "{m["file"]}"\nlocked_joints = [{locked}]\n' + \
           "".join(f'[[programme]]\nname = "r{k}"\nexpr = "{e}"\n' for k, e in enumerate(rows)) + \
           '[initial]\nassemble = false\n[time]\nt1 = 1.0\n'
    p = tmp / f"com{len(order)}.toml"
    p.write_text(text)
    return progmo.load(str(p))


def com_worst(scenes: list, model: pin.Model) -> float:
    """Largest |ours - Pinocchio| of c, c' and c'' (pin.centerOfMass) and of the Jacobian
    (pin.jacobianCenterOfMass, from c' at v = e_k) at random states."""
    d = model.createData()
    names = [model.names[j] for j in range(1, model.njoints)]
    perm = [scenes[0].q_names.index(n) for n in names]
    n = len(perm)
    rng = np.random.default_rng(7)
    w = 0.0
    for _ in range(5):
        q = np.array(scenes[0].q0) + rng.uniform(-0.5, 0.5, n)
        v, a = rng.uniform(-1.0, 1.0, n), rng.uniform(-1.0, 1.0, n)
        pin.centerOfMass(model, d, q[perm], v[perm], a[perm])
        # Pinocchio's covers the bodies its joints move; progmo's, like MuJoCo's subtree_com of the
        # world, every body of the file: the universe's inertia (the fixed root link) is a constant
        # point mass in the world frame
        m0, c0 = model.inertias[0].mass, model.inertias[0].lever
        k = d.mass[0] / (d.mass[0] + m0)
        wants = (k * d.com[0] + (1 - k) * c0, k * d.vcom[0], k * d.acom[0])
        for s, want in zip(scenes, wants):
            ours = np.asarray(s.residuals(np.zeros(1), q[None, :], v[None, :], a[None, :]))[0]
            w = max(w, np.abs(ours - want).max())
        rates = np.asarray(scenes[1].residuals(np.zeros(n), np.tile(q, (n, 1)), np.eye(n), np.zeros((n, n)))).T
        J = k * pin.jacobianCenterOfMass(model, d, q[perm])
        w = max(w, np.abs(J - rates[:, perm]).max())
    return w


@pytest.mark.parametrize("path", urdf_scenes(), ids=lambda p: p.stem)
def test_centre_of_mass_signals_match_pinocchio(path, tmp_path):
    """Issue 30 item 4: `com.x`, `com.x'`, `com.x''` (the system's centre of mass from the tree's
    point kinematics, weighted by m_i / M over every body) equal Pinocchio's centerOfMass and
    jacobianCenterOfMass with the universe's (fixed) inertia added;
    one link 10 % heavier in Pinocchio's model must fail the same comparison."""
    scenes = [com_scene(path, tmp_path, o) for o in ("", "'", "''")]
    w = com_worst(scenes, pin_model(path))
    print(f"{path.stem}: centre of mass max |d| = {w:.2e}")
    assert w <= TOL, f"{path.stem}: centre of mass differs by {w:.2e}"
    bad = pin_model(path)
    bad.inertias[3].mass *= 1.1
    assert com_worst(scenes, bad) > 1e-5
