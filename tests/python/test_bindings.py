"""The Rust core seen from Python: scenes, solves, errors, the residual evaluator."""

import pathlib

import numpy as np
import pytest

import progmo as ph

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENES = ROOT / "references" / "scenes"


def test_scene_properties_and_solve():
    s = ph.Scene(str(SCENES / "double_pendulum.toml"))
    assert s.kind == "tree" and s.q_names == ["q1", "q2"]
    assert s.rows == [{"name": "elbow", "level": "position", "role": "programme"}]
    r = s.solve(output_dt=0.1)
    assert r.success and r.code == "success"
    n = len(r.t)
    assert r.q.shape == (n, 2) and r.u.shape == (n, 2) and n == 101
    # The programme q2 = 0.5 sin t holds along the solution, by the core's own evaluator.
    res = s.residuals(r.t, r.q, r.v)
    assert np.max(np.abs(res)) <= s.tolerances["programme_residual"][0]
    assert np.allclose(res[:, 0], r.q[:, 1] - 0.5 * np.sin(r.t), atol=1e-15)


def test_residual_evaluator_detects_a_violation():
    # Negative control: a trajectory off the programme must show its residual.
    s = ph.Scene(str(SCENES / "double_pendulum.toml"))
    r = s.solve(output_dt=0.5)
    q = r.q.copy()
    q[:, 1] += 1e-3
    assert np.min(np.abs(s.residuals(r.t, q, r.v))) > 0.9e-3


def test_acceleration_rows_need_accelerations():
    s = ph.Scene(str(SCENES / "heavy_top.toml"))
    r = s.solve(output_dt=0.5)
    assert np.all(np.isnan(s.residuals(r.t, r.q, r.v)))
    assert np.max(np.abs(s.residuals(r.t, r.q, r.v, r.a))) < 1e-10


def test_dynamics_terms():
    s = ph.Scene(str(SCENES / "heavy_top.toml"))
    d = s.dynamics(0.0, s.q0, s.v0)
    assert np.allclose(d["mass"], np.diag([1.5, 1.5, 0.5]))
    p, q, _ = s.v0
    assert np.allclose(d["B"], [[-q, p, 0.0]])


def test_errors_are_python_exceptions_with_the_location(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text((SCENES / "double_pendulum.toml").read_text().replace("amp*sin(w*t)", "amp*sn(w*t)"))
    with pytest.raises(ph.SceneError, match=r"bad\.toml:\d+:\d+: error: .*unknown function `sn`"):
        ph.Scene(str(bad))
    s = ph.Scene(str(SCENES / "double_pendulum.toml"))
    with pytest.raises(ValueError, match="unknown integrator"):
        s.solve(integrator="euler")
    with pytest.raises(ValueError, match="shapes"):
        s.residuals(np.zeros(3), np.zeros((3, 5)), np.zeros((3, 2)))


def test_a_scene_error_carries_its_location_as_attributes(tmp_path):
    # file, line, column and field as attributes (issue 26 item 3), the same numbers as the message
    with pytest.raises(ph.SceneError) as e:
        ph.Scene(str(ROOT / "tests" / "bad_scenes" / "types_wrong_type.toml"))
    err = e.value
    assert (err.line, err.column, err.field) == (10, 8, "model.bodies[0].mass"), vars(err)
    assert err.file.endswith("types_wrong_type.toml") and "expected f64" in err.message
    assert str(err).startswith(f"{err.file}:10:8: error: model.bodies[0].mass: ")
    # a file that cannot be read has no position: line and column are None, not 0
    with pytest.raises(ph.SceneError) as e:
        ph.Scene(str(tmp_path / "missing.toml"))
    assert e.value.line is None and e.value.column is None and e.value.message
    # a path refused by the file rule (no scene position at all)
    from progmo._core import resolve_file
    with pytest.raises(ph.SceneError) as e:
        resolve_file("/etc/passwd", tmp_path)
    assert e.value.file is None and e.value.line is None and "must resolve inside" in e.value.message


def test_stub_literals_spell_the_core_vocabulary():
    """One vocabulary: the names the core parses (progmo::solve) are the names the stub's Literal
    types offer, so `_core.pyi` cannot drift from the binary (null_space_stacked once did)."""
    import pathlib
    import re

    from progmo import _core

    stub = (pathlib.Path(_core.__file__).parent / "_core.pyi").read_text()
    for kw, names in (("formulation", _core.FORMULATIONS), ("integrator", _core.INTEGRATORS),
                      ("drift", _core.DRIFTS)):
        lits = re.findall(rf"\b{kw}: Literal\[([^\]]*)\]", stub)
        assert lits, kw
        for lit in lits:  # every keyword that takes such a name offers exactly the core's names
            assert set(re.findall(r'"([a-z0-9_]+)"', lit)) == set(names), (kw, lit, names)
    for name in _core.FORMULATIONS:
        sol = _core.Scene(str(pathlib.Path(__file__).resolve().parents[2] / "references" / "scenes"
                              / "double_pendulum.toml")).solve(formulation=name, t1=0.05)
        assert sol.success and sol.settings["formulation"] == name
