"""Baselines: the regression margin max(10 x baseline, baseline + floor), metric classes, the
file format and acceptance."""

import json
import math

import pytest

from progmo import baselines as bl
from progmo.results import CheckResult


def result(status="pass", **metrics):
    return CheckResult("scene", "mujoco", status, metrics=metrics)


def states(r, base):
    return {c.metric: c.state for c in bl.compare(r, {"metrics": base} if base is not None else None)}


@pytest.mark.parametrize(
    "metric, cls, floor",
    [
        ("parity_mass", "algebraic", 1e-12),
        ("parity_bias", "algebraic", 1e-12),
        ("instant_u", "algebraic", 1e-12),
        ("inverse_dynamics", "algebraic", 1e-12),
        ("replay_residual", "integrated", 1e-11),
        ("replay_deviation", "integrated", 1e-11),
        ("solver_residual", "integrated", 1e-11),
        ("replay_growth_rate", "info", None),
        ("replay_step", "info", None),
    ],
)
def test_metric_classes(metric, cls, floor):
    assert bl.metric_class(metric) == (cls, floor)


def test_threshold_is_factor_above_the_floor_and_floor_at_round_off():
    assert bl.threshold("replay_residual", 1e-9) == pytest.approx(1e-8)  # 10 x dominates
    assert bl.threshold("replay_residual", 1e-15) == pytest.approx(1e-11 + 1e-15)  # floor dominates
    assert bl.threshold("parity_mass", 0.0) == 1e-12
    assert bl.threshold("replay_growth_rate", 0.3) is None


def test_round_off_jitter_is_no_regression_but_an_order_of_magnitude_is():
    base = {"parity_mass": 2e-16, "replay_residual": 3e-12}
    # 20x growth at round-off level: within the floor.
    assert set(states(result(parity_mass=4e-15, replay_residual=9e-12), base).values()) == {"ok"}
    # Negative control: the same comparison must flag real growth.
    s = states(result(parity_mass=2e-12, replay_residual=5e-11), base)
    assert s == {"parity_mass": "regression", "replay_residual": "regression"}
    # Just below / above the threshold of an integrated metric with a large baseline.
    assert states(result(replay_residual=0.99e-7), {"replay_residual": 1e-8})["replay_residual"] == "ok"
    assert states(result(replay_residual=1.01e-7), {"replay_residual": 1e-8})["replay_residual"] == "regression"


def test_nan_or_missing_metric_with_a_baseline_is_a_regression():
    assert states(result(replay_residual=math.nan), {"replay_residual": 1e-12}) == {"replay_residual": "regression"}
    assert states(result(), {"replay_residual": 1e-12}) == {"replay_residual": "regression"}


def test_new_metric_info_metric_and_improvement():
    s = states(result(replay_residual=1e-12, replay_growth_rate=50.0, replay_deviation=1e-12),
               {"replay_growth_rate": 0.1, "replay_deviation": 1e-9})
    assert s == {"replay_residual": "new", "replay_growth_rate": "info", "replay_deviation": "improved"}
    assert states(result(replay_residual=1e-12), None) == {"replay_residual": "new"}


def test_skipped_and_error_results_are_not_compared():
    assert bl.compare(result("not_checked"), {"metrics": {"replay_residual": 1e-12}}) == []
    assert bl.compare(result("error"), {"metrics": {"replay_residual": 1e-12}}) == []


def test_a_failed_check_is_still_compared():
    assert states(result("fail", replay_residual=1.0), {"replay_residual": 1e-12}) == {"replay_residual": "regression"}


def test_accept_writes_the_documented_format_and_reports_changes(tmp_path):
    prov = {"date": "2026-01-01", "git_revision": "abc", "mujoco": "4.0.0"}
    path, changes = bl.accept(tmp_path, result(replay_residual=2e-12, parity_mass=1e-15), prov)
    assert path == tmp_path / "scene.mujoco.json"
    doc = json.loads(path.read_text())
    assert doc == {
        "format": 1, "scene": "scene", "simulator": "mujoco",
        "metrics": {"parity_mass": 1e-15, "replay_residual": 2e-12},
        "budgets": {}, "accepted": prov,
    }
    assert changes == ["parity_mass: new 1e-15", "replay_residual: new 2e-12"]
    _, changes = bl.accept(tmp_path, result(replay_residual=4e-12), prov)
    assert changes == ["replay_residual: 2e-12 -> 4e-12", "parity_mass: removed (was 1e-15)"]
    assert bl.load(tmp_path, "scene", "mujoco")["metrics"] == {"replay_residual": 4e-12}


def test_only_passing_results_are_accepted(tmp_path):
    for status in ("fail", "error", "not_checked"):
        assert bl.accept(tmp_path, result(status, replay_residual=1.0), {}) is None
    assert list(tmp_path.iterdir()) == []


def test_missing_and_invalid_baselines(tmp_path):
    assert bl.load(tmp_path, "scene", "mujoco") is None
    (tmp_path / "scene.mujoco.json").write_text('{"format": 1}')
    with pytest.raises(ValueError, match="not a valid baseline"):
        bl.load(tmp_path, "scene", "mujoco")


def test_file_names_are_safe():
    assert bl.path_for("b", "a/../x y", "mujoco").name == "a_.._x_y.mujoco.json"
