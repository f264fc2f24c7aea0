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
    out = []
    for p in sorted((ROOT / "references" / "scenes").glob("*.toml")):
        with open(p, "rb") as f:
            if tomllib.load(f)["model"]["kind"] == "urdf":
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
        wf = max(wf, np.abs(-b - fp).max() / scale)
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
    assert {p.stem for p in urdf_scenes()} >= {"panda_circle", "ur5_tool_path"}
