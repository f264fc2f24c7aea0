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


def test_the_unactuated_part_comes_from_the_core_and_is_relative_to_the_largest_force():
    # joint actuator on x1 (two_car_chain): the part outside range(H) is exactly the other entry
    s = Scene(str(scene_file("two_car_chain")))
    ix1 = s.v_names.index("x1")
    u = np.zeros((2, 2))
    u[:, ix1] = [2.0, -4.0]
    u[1, 1 - ix1] = 1e-3
    t, q = np.zeros(2), np.zeros((2, len(s.q_names)))
    off = np.asarray(s.unactuated_part(t, q, u))
    assert off[:, ix1].tolist() == [0.0, 0.0] and off[:, 1 - ix1].tolist() == [0.0, 1e-3]
    assert unactuated_force(u, off) == pytest.approx(2.5e-4)
    assert unactuated_force(np.zeros((3, 2)), np.zeros((3, 2))) == 0.0
    # a direction (thruster_cars: (1, 1) over (x1, d)): the part of u off that line
    th = Scene(str(scene_file("thruster_cars")))
    on, half = np.array([[1.0, 1.0], [-3.0, -3.0]]), np.array([[1.0, 0.0]])
    assert np.abs(th.unactuated_part(np.zeros(2), np.zeros((2, 2)), on)).max() <= 1e-15
    assert unactuated_force(half, th.unactuated_part(np.zeros(1), np.zeros((1, 2)), half)) == pytest.approx(0.5)
    assert Scene(str(scene_file("double_pendulum"))).unactuated_part(t, q, u) is None
    with pytest.raises(ValueError, match="shapes"):
        s.unactuated_part(t, q, np.zeros((2, 3)))


def test_solution_tau_is_the_actuators_force():
    # u = H(t, q) tau at every sample (cylinder_cars: H depends on q), tau named by [[actuators]]
    s = Scene(str(scene_file("cylinder_cars")))
    sol = s.solve(t1=0.5, output_dt=0.05)
    tau = np.asarray(sol.tau)
    assert tau.shape == (len(sol.t), 1) and np.abs(tau).max() > 0
    Hu = np.array([np.asarray(s.actuation_map_at(tk, qk)) @ tk_tau for tk, qk, tk_tau in zip(sol.t, sol.q, tau)])
    assert np.abs(Hu - np.asarray(sol.u)).max() <= 1e-12 * np.abs(sol.u).max()
    assert np.abs(np.asarray(s.unactuated_part(sol.t, sol.q, sol.u))).max() <= 1e-12 * np.abs(sol.u).max()
    assert Scene(str(scene_file("double_pendulum"))).solve(t1=0.1).tau is None


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
    with pytest.raises(ValueError, match="q: needs 2 entries"):
        s.actuation_map_at(0.0, np.zeros(3))


def test_the_unactuated_part_takes_the_map_at_each_sample(tmp_path):
    # a direction that turns with x1, (cos x1, sin x1) over (x1, d): u along H(q_k) at each sample
    # is on range(H), the same forces at the other sample's state are not
    text = scene_file("cylinder_cars").read_text()
    line = next(ln for ln in text.splitlines() if ln.startswith("direction = "))
    p = tmp_path / "turning.toml"
    p.write_text(text.replace(line, 'direction = { x1 = "cos(x1)", d = "sin(x1)" }'))
    s = Scene(str(p))
    ix1, idd = s.v_names.index("x1"), s.v_names.index("d")
    q = np.zeros((2, len(s.q_names)))
    q[1, s.q_names.index("x1")] = 0.7
    u = np.zeros((2, len(s.v_names)))
    u[:, ix1], u[:, idd] = np.cos(q[:, s.q_names.index("x1")]), np.sin(q[:, s.q_names.index("x1")])
    assert np.abs(s.unactuated_part(np.zeros(2), q, u)).max() <= 1e-15
    assert np.abs(s.unactuated_part(np.zeros(2), q[::-1], u)).max() > 0.1


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
