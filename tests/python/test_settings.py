"""One definition of the solver settings (``progmo::solve::Overrides``) at the Python door:
``Scene.solve(**settings)`` takes exactly the names of ``_core.SETTINGS`` (the scene file's keys and
``progmo solve``'s flags, which tests/schema.rs compares with the same list), refuses others by
name, type and range with ``SettingsError.field``, and ``_core.pyi``'s ``SolveSettings`` is generated
from the list (``PROGMO_BLESS=1 pytest tests/python/test_settings.py`` rewrites it).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

import progmo
from progmo import _core

PYI = Path(_core.__file__).with_name("_core.pyi") if Path(_core.__file__).with_name("_core.pyi").exists() \
    else Path(__file__).resolve().parents[2] / "harness" / "progmo" / "_core.pyi"
BEGIN = "class SolveSettings(TypedDict, total=False):\n"
END = "# end generated\n"


def _python_type(s: dict) -> str:
    if s["choices"]:
        return "Literal[" + ", ".join(f'"{c}"' for c in s["choices"]) + "] | None"
    return {"number": "float", "integer": "int", "boolean": "bool", "string": "str"}[s["kind"]] + " | None"


def generated_block() -> str:
    doc = '    """The settings of ``Scene.solve`` (``progmo::solve::Overrides``); None keeps the scene\'s."""\n'
    return BEGIN + doc + "".join(f"    {s['name']}: {_python_type(s)}\n" for s in _core.SETTINGS)


def test_the_stub_lists_the_settings():
    text = PYI.read_text()
    a = text.index(BEGIN)
    b = text.index(END, a)
    want = text[:a] + generated_block() + text[b:]
    if os.environ.get("PROGMO_BLESS"):
        PYI.write_text(want)
        return
    assert text == want, ("_core.pyi's SolveSettings differs from _core.SETTINGS: regenerate it with "
                          "`PROGMO_BLESS=1 .venv/bin/python -m pytest tests/python/test_settings.py`")
    names = re.findall(r"^    (\w+): ", text[a:b], flags=re.M)
    assert names == [s["name"] for s in _core.SETTINGS]


def test_settings_are_described_and_placed():
    names = [s["name"] for s in _core.SETTINGS]
    assert len(names) == len(set(names)) and "max_step" in names and "h_max" not in names
    for s in _core.SETTINGS:
        assert s["table"] in ("solver", "time", "initial") and s["description"], s
    # the numeric [solver] ones are what a sweep may vary
    assert set(_core.SOLVER_NUMBERS) == {s["name"] for s in _core.SETTINGS
                                        if s["table"] == "solver" and s["kind"] == "number"}


@pytest.fixture(scope="module")
def scene() -> progmo.Scene:
    return progmo.load("double_pendulum")


def test_every_setting_is_a_keyword_of_solve(scene):
    t1 = scene.t0 + 0.02
    value = {"t1": t1, "output_dt": 0.01, "step": 1e-3, "max_step": 0.005, "max_drift": 1.0,
             "max_samples": 100, "formulation": "kkt", "integrator": "dopri5", "drift": "projection",
             "rtol": 1e-9, "atol": 1e-11, "projection_tol": 1e-11}
    kw = {s["name"]: value.get(s["name"], s["default"]) for s in _core.SETTINGS}
    assert all(v is not None for v in kw.values()), kw
    sol = scene.solve(**kw).raise_if_stopped()
    got = sol.settings
    assert got["max_step"] == 0.005 and got["rtol"] == 1e-9 and got["formulation"] == "kkt"
    assert got["integrator"] == "dopri5" and got["max_samples"] == 100
    assert got["output"] == {"every": 0.01} and got["drift"]["tol"] == 1e-11
    assert sol.t[-1] == pytest.approx(t1)


@pytest.mark.parametrize("kw, field, words", [
    ({"h_max": 0.1}, "h_max", "unknown setting `h_max`: expected one of assemble, atol,"),
    ({"max_stp": 0.1}, "max_stp", "did you mean `max_step`"),
    ({"rtl": 1e-8}, "rtl", "did you mean `rtol`"),
    ({"rtol": "tight"}, "rtol", "expected number"),
    ({"rtol": -1.0}, "rtol", "must be positive"),
    ({"max_samples": 1}, "max_samples", "must be at least 2"),
    ({"max_step": [0.1]}, "max_step", "expected number, got list"),
    ({"drift": "stabilize"}, "drift", "expected one of projection, baumgarte, none"),
    ({"t1": float("inf")}, "t1", "must be a finite number"),
])
def test_bad_settings_are_refused_by_name(scene, kw, field, words):
    with pytest.raises(progmo.SettingsError) as e:
        scene.solve(**kw)
    assert e.value.field == field and words in str(e.value), str(e.value)
    assert str(e.value).startswith(f"{field}: ")


def test_progmo_references_is_the_one_name_rule_at_both_doors(tmp_path, monkeypatch):
    """With $PROGMO_REFERENCES set, a bundled name resolves there only: the Python resolver and the
    package's ``progmo`` command (the Rust CLI in-process) refuse the same name the same way."""
    import subprocess
    import sys

    from progmo import data

    (tmp_path / "scenes").mkdir()
    monkeypatch.setenv("PROGMO_REFERENCES", str(tmp_path))
    with pytest.raises(progmo.SceneError, match="no such scene file or bundled scene"):
        data.scene_file("double_pendulum")
    r = subprocess.run([sys.executable, "-m", "progmo.command", "validate", "double_pendulum"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    assert "no such scene file or bundled scene" in r.stderr and str(tmp_path / "scenes") in r.stderr
    shipped = Path(progmo.__file__).parent / "references" / "scenes" / "double_pendulum.toml"
    (tmp_path / "scenes" / "double_pendulum.toml").write_text(shipped.read_text())
    assert data.scene_file("double_pendulum") == tmp_path / "scenes" / "double_pendulum.toml"
    r = subprocess.run([sys.executable, "-m", "progmo.command", "validate", "double_pendulum"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
