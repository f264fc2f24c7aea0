"""The core's one error type (``progmo::Error``) reaches Python through one conversion: each kind
becomes its exception class and carries the same structured attributes (``kind``, ``field``,
``message``, ``file``, ``line``, ``column``, ``excerpt``, ``rows``)."""

import numpy as np
import pytest

import progmo

ATTRS = ("kind", "field", "message", "file", "line", "column", "excerpt", "rows")


def fields(e: BaseException) -> dict:
    missing = [a for a in ATTRS if not hasattr(e, a)]
    assert not missing, f"{type(e).__name__} lacks {missing}"
    return {a: getattr(e, a) for a in ATTRS}


def test_a_scene_error_is_located(tmp_path):
    text = progmo.data.scene_file("appell_hamel").read_text()
    assert "\nmass = 1.0\n" in text
    path = tmp_path / "s.toml"
    path.write_text(text.replace("\nmass = 1.0\n", "\nmass = -1.0\n"))
    line = text.split("\nmass = 1.0\n")[0].count("\n") + 2
    with pytest.raises(progmo.SceneError) as e:
        progmo.load(str(path))
    f = fields(e.value)
    assert (f["kind"], f["file"], f["line"], f["field"]) == ("scene", str(path), line, "model.bodies[0].mass"), f
    assert f["message"] in str(e.value) and f["excerpt"] and f["rows"] is None


def test_a_settings_error_names_the_setting():
    scene = progmo.load("double_pendulum")
    with pytest.raises(progmo.SettingsError) as e:
        scene.solve(rtol=-1.0)
    f = fields(e.value)
    assert (f["kind"], f["field"], f["line"], f["file"]) == ("settings", "rtol", None, None), f
    assert str(e.value) == f"rtol: {f['message']}"
    with pytest.raises(progmo.SettingsError) as e:  # a vocabulary name
        scene.solve(integrator="euler")
    assert (e.value.kind, e.value.field) == ("settings", "integrator")


def test_a_path_rule_refusal_is_a_scene_error_of_kind_input(tmp_path):
    with pytest.raises(progmo.SceneError) as e:
        progmo._core.resolve_file("/etc/passwd", tmp_path)
    f = fields(e.value)
    assert (f["kind"], f["line"], f["field"]) == ("input", None, None), f


def test_a_rank_deficient_programme_names_its_rows():
    # |v|^2 = c at v = 0: the row's gradient 2 v vanishes (the paper's example 2.1 at rest)
    scene = progmo.load("example_2_1")
    with pytest.raises(RuntimeError) as e:
        scene.accelerations(0.0, np.ones(3), np.zeros(3), "null_space")
    f = fields(e.value)
    assert (f["kind"], f["rows"]) == ("formulation", [0]), f
    # negative control: the same call at a moving state succeeds
    scene.accelerations(0.0, np.ones(3), np.array([0.1, 0.2, 0.3]), "null_space")


def test_a_write_failure_is_an_os_error_naming_the_file(tmp_path):
    sol = progmo.load("double_pendulum").solve(t1=0.1, output_dt=0.05)
    target = tmp_path / "dir.csv"
    target.mkdir()
    with pytest.raises(OSError) as e:
        sol.write_csv(target)
    f = fields(e.value)
    assert f["kind"] == "output" and str(target) in f["file"], f


def test_an_unexportable_scene_is_export_unsupported():
    with pytest.raises(progmo.ExportUnsupported) as e:
        progmo.load("rolling_disk").export("mjcf")
    assert fields(e.value)["kind"] == "export"
