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
    H = np.zeros((len(s.v_names), 1))
    H[s.v_names.index("x1"), 0] = 1.0
    assert np.array_equal(s.actuation_map, H)
    assert Scene(str(scene_file("double_pendulum"))).actuators == []
    assert Scene(str(scene_file("double_pendulum"))).actuation_map is None


def test_unactuated_force_is_relative_to_the_largest_force():
    u = np.array([[2.0, 0.0], [-4.0, 1e-3]])
    e0, e01 = np.array([[1.0], [0.0]]), np.eye(2)
    assert unactuated_force(u, e0) == pytest.approx(2.5e-4)
    assert unactuated_force(u, e01) == 0.0
    assert unactuated_force(np.zeros((3, 2)), e0) == 0.0
    # a direction: the part of u off the line (1, -1), relative to max |u|
    d = np.array([[1.0], [-1.0]])
    assert unactuated_force(np.array([[1.0, -1.0], [-3.0, 3.0]]), d) == pytest.approx(0.0, abs=1e-15)
    assert unactuated_force(np.array([[1.0, 0.0]]), d) == pytest.approx(0.5)


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
def test_a_thruster_along_a_direction_replays_and_a_force_off_it_fails(sim):
    # thruster_cars: u = F (1, 1) over (x1, d) (a world force on car 2). The replay passes with u on
    # the direction; 1e-6 N added on d alone (off the direction) must breach replay_unactuated.
    path = str(scene_file("thruster_cars"))
    r, _ = _run(path, sim, CheckOptions(horizon=1.0, step=1e-3))
    assert r.status == "pass", (r.reason, r.metrics)
    assert r.metrics["replay_unactuated"] < 1e-14 and r.metrics["replay_deviation"] < 1e-10
    d = Scene(path).v_names.index("d")
    push = np.zeros(2)
    push[d] = 1e-6
    r, _ = _run(path, sim, CheckOptions(horizon=1.0, step=1e-3), corrupt_u=lambda t, u: u + push)
    assert r.status == "fail", (r.reason, r.metrics)
    assert "replay_unactuated" in r.reason


@pytest.mark.parametrize("sim", BOTH)
def test_the_overhead_crane_passes_with_trolley_and_hoist_forces_only(sim):
    # Rank-deficient decoupling (structure algorithm): over 1 s the swing angle passes through
    # zero (t = pi/4), where p_x's own tau gradient vanishes; the replay must stay on the path.
    r, _ = _run(str(scene_file("overhead_crane")), sim, CheckOptions(horizon=1.0))
    assert r.status == "pass", (r.reason, r.metrics)
    assert r.metrics["replay_unactuated"] == 0.0
    assert r.metrics["replay_deviation"] < 1e-9
