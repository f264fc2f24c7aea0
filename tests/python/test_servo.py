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
    assert next(b for b in r.breaches if b.metric == "replay_unactuated").where == "joint d", r.reason


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


def test_a_state_dependent_map_is_evaluated_at_the_state():
    # cylinder_cars: H(q) = (X - x1 - d)/L (1, 1), L = sqrt((X - x1 - d)^2 + h^2), X = 0.4, h = 0.3.
    s = Scene(str(scene_file("cylinder_cars")))
    assert s.actuation_varies and s.actuators == [("cylinder", None)]
    q0 = np.zeros(2)
    assert np.array_equal(s.actuation_map_at(0.0, q0), s.actuation_map)
    assert np.allclose(s.actuation_map, [[0.8], [0.8]], rtol=0, atol=1e-15)
    q = np.array([0.1, 0.05])
    c = (0.4 - 0.15) / np.hypot(0.4 - 0.15, 0.3)
    assert np.allclose(s.actuation_map_at(1.0, q), [[c], [c]], rtol=0, atol=1e-15)
    assert not Scene(str(scene_file("thruster_cars"))).actuation_varies
    assert Scene(str(scene_file("double_pendulum"))).actuation_map_at(0.0, np.zeros(2)) is None
    with pytest.raises(ValueError, match="q needs 2 entries"):
        s.actuation_map_at(0.0, np.zeros(3))


def test_unactuated_force_takes_one_map_per_sample():
    # a direction turning with the samples: on it at every sample is 0, off it at one sample is not
    H = np.array([[[1.0], [0.0]], [[0.0], [1.0]]])
    assert unactuated_force(np.array([[2.0, 0.0], [0.0, -4.0]]), H) == 0.0
    assert unactuated_force(np.array([[2.0, 0.0], [1e-3, -4.0]]), H) == pytest.approx(2.5e-4)


@pytest.mark.parametrize("sim", BOTH)
def test_a_cylinder_map_is_applied_at_the_simulators_own_state(sim, monkeypatch):
    # cylinder_cars: the replay applies H(t, q_sim) tau(t) at every RK4 stage (counted here), stays
    # on the programme, and a force off the cylinder's line (1e-6 N on d alone) fails the check.
    from progmo.simulators import replay

    calls = []
    plain = replay.Reference.force_at

    def counted(self, time, q):
        if self.actuation is not None:
            calls.append(np.array(q))
        return plain(self, time, q)

    monkeypatch.setattr(replay.Reference, "force_at", counted)
    path = str(scene_file("cylinder_cars"))
    r, _ = _run(path, sim, CheckOptions(horizon=1.0, step=1e-3))
    assert r.status == "pass", (r.reason, r.metrics)
    assert r.metrics["replay_unactuated"] < 1e-14 and r.metrics["replay_deviation"] < 1e-10
    assert len(calls) >= 4 * 1000, len(calls)  # every stage of 1000 steps, at the stage's state
    assert len({tuple(q) for q in calls}) > 1000
    calls.clear()
    d = Scene(path).v_names.index("d")
    push = np.zeros(2)
    push[d] = 1e-6
    r, _ = _run(path, sim, CheckOptions(horizon=1.0, step=1e-3), corrupt_u=lambda t, u: u + push)
    assert r.status == "fail", (r.reason, r.metrics)
    assert "replay_unactuated" in r.reason
