"""Servo-constraints in the check (issue 17): a programme realized by given actuators is replayed as
u = H tau, and ``replay_unactuated`` judges that the force on joints no actuator drives is zero."""

from __future__ import annotations

import numpy as np
import pytest

from progmo import Scene
from progmo.checks import CheckOptions, _run, run_check, unactuated_force
from progmo.data import scene_file

BOTH = ("mujoco", "pinocchio")


def test_the_scene_lists_its_actuators():
    s = Scene(str(scene_file("two_car_chain")))
    assert s.actuators == [("push", s.v_names.index("x1"))]
    assert Scene(str(scene_file("double_pendulum"))).actuators == []


def test_unactuated_force_is_relative_to_the_largest_force():
    u = np.array([[2.0, 0.0], [-4.0, 1e-3]])
    assert unactuated_force(u, [0]) == pytest.approx(2.5e-4)
    assert unactuated_force(u, [0, 1]) == 0.0
    assert unactuated_force(np.zeros((3, 2)), [0]) == 0.0


@pytest.mark.parametrize("sim", BOTH)
def test_two_car_chain_passes_with_its_force_on_car_1_only(sim):
    r = run_check(str(scene_file("two_car_chain")), sim)
    assert r.status == "pass", (r.reason, r.metrics)
    assert r.metrics["replay_unactuated"] == 0.0
    assert any(b.metric == "replay_unactuated" for b in r.budgets)


@pytest.mark.parametrize("sim", BOTH)
def test_a_force_on_the_unactuated_joint_fails_the_check(sim):
    # Negative control: 1e-6 N on the spring joint d (no actuator there) must breach the budget.
    d = Scene(str(scene_file("two_car_chain"))).v_names.index("d")
    push = np.zeros(2)
    push[d] = 1e-6
    r, _ = _run(str(scene_file("two_car_chain")), sim, CheckOptions(horizon=1.0, step=1e-3),
                corrupt_u=lambda t, u: u + push)
    assert r.status == "fail", (r.reason, r.metrics)
    assert r.metrics["replay_unactuated"] > 1e-7
    assert "replay_unactuated" in r.reason


@pytest.mark.parametrize("sim", BOTH)
def test_the_overhead_crane_passes_with_trolley_and_hoist_forces_only(sim):
    # Rank-deficient decoupling (structure algorithm): over 1 s the swing angle passes through
    # zero (t = pi/4), where p_x's own tau gradient vanishes; the replay must stay on the path.
    r, _ = _run(str(scene_file("overhead_crane")), sim, CheckOptions(horizon=1.0))
    assert r.status == "pass", (r.reason, r.metrics)
    assert r.metrics["replay_unactuated"] == 0.0
    assert r.metrics["replay_deviation"] < 1e-9
