"""The check's vocabulary is the core's (issue 28): the metric names, their default budgets and
reasons are defined once (`progmo::check`), the harness reads them through the binding, FORMAT.md's
table is generated from them, and a name outside the vocabulary is refused where it stands, with
the nearest valid one."""

import pathlib
import re

import pytest

from progmo import Scene, SceneError, _core
from progmo.checks import (ACTUATOR_BUDGETED, BUDGETED, CLOSURE_BUDGETED, ROBOT_FILE_BUDGETED, SOLVER_ONLY_BUDGETED,
                           TABLE_NAME,
                           budgets_for, default_budgets)
from progmo.results import SOLVER_ONLY

ROOT = pathlib.Path(__file__).resolve().parents[2]
FORMAT = ROOT / "src" / "scene" / "FORMAT.md"
SCENES = ROOT / "references" / "scenes"


def format_md_defaults() -> dict[str, str]:
    """metric -> the default column of FORMAT.md's "Default budgets" table (read as text)."""
    page = FORMAT.read_text()
    table = page.split("<!-- generated: progmo::check::default_budget_table -->", 1)[1]
    out = {}
    for line in table.strip().splitlines()[2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split(" | ")]
        out[re.match(r"`(\w+)`", cells[0]).group(1)] = cells[1]
    return out


def test_the_harness_budgets_are_the_cores_table():
    """Every metric the harness judges is the core's, with the core's default and reason, and the
    default values are the ones FORMAT.md documents."""
    core = {m["name"]: m for m in _core.check_metrics()}
    judged = (set(BUDGETED) | set(CLOSURE_BUDGETED) | set(ACTUATOR_BUDGETED) | set(ROBOT_FILE_BUDGETED)
              | set(SOLVER_ONLY_BUDGETED))
    assert judged == set(core)
    assert ROBOT_FILE_BUDGETED == ("inverse_dynamics",)
    assert BUDGETED == ("solver_residual", "parity_mass", "parity_bias", "instant_u", "replay_residual",
                        "replay_deviation")
    assert SOLVER_ONLY_BUDGETED[-1] == "reference_error" and SOLVER_ONLY == _core.SOLVER_ONLY
    none = default_budgets({"drift": {"kind": "none"}})
    proj = default_budgets({"drift": {"kind": "projection", "tol": 1e-10, "max_iter": 8}})
    assert none == {k: (float(v), w) for k, (v, w) in _core.default_budgets({"kind": "none"}).items()}
    documented = format_md_defaults()
    assert set(documented) == set(core)
    for m, text in documented.items():
        if m == "solver_residual":
            assert "1e-10 by default" in text and text.endswith("else 1e-8"), text
            assert proj[m][0] == pytest.approx(1e-8) and none[m][0] == pytest.approx(1e-8)
        else:
            assert float(text) == none[m][0] == proj[m][0], (m, text)
        assert none[m][1].startswith(f"default ({core[m]['class']}): ")
        if m != "solver_residual":  # its reason names the drift control in force
            assert none[m][1].endswith(core[m]["reason"])
    # A scene's entry wins over the default, under the table name, per simulator first.
    tol = {"programme_residual": (1e-9, "a"), "replay_residual_mujoco": (2e-9, "b"), "replay_residual": (3e-9, "c")}
    got = {b.metric: (b.value, b.source) for b in budgets_for(tol, {"drift": {"kind": "none"}}, "mujoco")}
    assert got["solver_residual"] == (1e-9, "scene") and got["replay_residual"] == (2e-9, "scene")
    assert got["parity_mass"] == (1e-11, "default")
    assert TABLE_NAME == {"solver_residual": "programme_residual"}


def test_every_name_the_harness_reads_is_in_the_loaders_vocabulary():
    keys = set(_core.tolerance_keys())
    for m in {*BUDGETED, *CLOSURE_BUDGETED, *ACTUATOR_BUDGETED}:
        name = TABLE_NAME.get(m, m)
        assert {name, f"{name}_mujoco", f"{name}_pinocchio"} <= keys, m
    for m in SOLVER_ONLY_BUDGETED:
        assert f"{TABLE_NAME.get(m, m)}_solver_only" in keys
    # the check's options are not budgets: they live in [checks] (Scene.replay_step), not here
    assert "replay_step" not in keys and "replay_horizon" not in keys
    assert _core.CHECK_OPTIONS == ["replay_step"] and not set(_core.CHECK_OPTIONS) & keys
    assert all(hasattr(_core.Scene, o) for o in _core.CHECK_OPTIONS)
    assert "parity_mass_solver_only" not in keys and "formulation_deviation_mujoco" not in keys


def test_an_unknown_drift_kind_is_refused():
    with pytest.raises(ValueError, match="did you mean `projection`"):
        _core.default_budgets({"kind": "projektion"})


@pytest.mark.parametrize("entry,phrase", [
    ('[tolerances]\nreplay_residul = { value = 3e-11, reason = "r" }\n',
     r"tolerances\.replay_residul: unknown tolerance `replay_residul` \(did you mean `replay_residual`\?\)"),
    ('[checks]\nnot_checked = { pinochio = "r" }\n',
     r"checks\.not_checked\.pinochio: unknown simulator `pinochio` \(did you mean `pinocchio`\?\)"),
])
def test_a_misspelt_name_is_refused_through_the_binding(tmp_path, entry, phrase):
    """The Python door gets the loader's located error (file:line:column, field, suggestion)."""
    text = (SCENES / "double_pendulum.toml").read_text()
    table, line_text = entry.splitlines()
    assert text.count(f"\n{table}\n") == 1  # the scene has both tables ([checks]: its replay_step)
    text = text.replace(f"\n{table}\n", f"\n{table}\n{line_text}\n")  # the misspelt entry first
    p = tmp_path / "s.toml"
    p.write_text(text)
    line = text.splitlines().index(line_text) + 1
    with pytest.raises(SceneError, match=re.escape(f"{p}:{line}:") + r"\d+: error: " + phrase):
        Scene(str(p))
