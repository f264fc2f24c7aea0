"""The per-scene checks (checks.run_check) in MuJoCo and Pinocchio: parity, replay, negative
control, not_checked and errors. Budgets come from the scenes' [tolerances] (defaults:
test_verdicts.py)."""

import pathlib
import sys

import numpy as np
import pytest

import progmo as ph
from progmo import checks
from progmo.checks import CheckOptions, Recording, _run, run_check

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENES = ROOT / "references" / "scenes"
BOTH = ("mujoco", "pinocchio")


def scene(name):
    return str(SCENES / f"{name}.toml")


@pytest.fixture(scope="module")
def full():
    """Full-horizon checks of the double pendulum and the heavy top in both simulators."""
    return {(s, sim): run_check(scene(s), sim) for s in ("double_pendulum", "heavy_top") for sim in BOTH}


@pytest.mark.parametrize("name", ["double_pendulum", "heavy_top"])
@pytest.mark.parametrize("sim", BOTH)
def test_parity(full, name, sim):
    r = full[(name, sim)]
    assert r.metrics["parity_mass"] < 1e-13, r.metrics
    assert r.metrics["parity_bias"] < 1e-13, r.metrics
    assert r.metrics["instant_u"] < 1e-12, r.metrics


@pytest.mark.parametrize("sim", BOTH)
def test_replay_double_pendulum(full, sim):
    r = full[("double_pendulum", sim)]
    assert r.status == "pass", (r.reason, r.breaches)
    assert r.info["replay_step"] == 1e-3
    # simulator notes: ~1e-12..1e-11 at h = 1e-3 over 10 s with u fed at every RK4 stage
    assert 0 < r.metrics["replay_residual"] < 1e-11
    assert r.metrics["replay_deviation"] < 5e-11
    assert np.isfinite(r.info["replay_growth_rate"])
    names = {s.name for s in r.series}
    assert {"replay_residual", "replay_deviation", "u.q1", "u.q2"} <= names
    res = next(s for s in r.series if s.name == "replay_residual")
    assert len(res.t) == len(res.values) and res.t[-1] == pytest.approx(10.0)
    assert {b.metric for b in r.budgets} >= {"replay_residual", "replay_deviation", "parity_mass",
                                            "parity_bias", "instant_u", "solver_residual"}


@pytest.mark.parametrize("sim", BOTH)
def test_replay_heavy_top(full, sim):
    r = full[("heavy_top", sim)]
    assert r.status == "pass", (r.reason, r.breaches)
    assert r.info["replay_step"] == 5e-4
    # RK4 error of an 8 rad/s spin at h = 5e-4: measured 3.4e-10 (5.5e-9 at 1e-3, 16x per halving)
    assert r.metrics["replay_residual"] < 5e-9
    assert r.metrics["replay_deviation"] < 5e-9


def test_mujoco_and_pinocchio_agree(full):
    """Two independent simulators replaying the same u land on the same trajectory."""
    for name in ("double_pendulum", "heavy_top"):
        a, b = full[(name, "mujoco")], full[(name, "pinocchio")]
        assert a.metrics["replay_deviation"] == pytest.approx(b.metrics["replay_deviation"], rel=0.2)


@pytest.mark.parametrize("name", ["double_pendulum", "heavy_top", "knife_edge"])
@pytest.mark.parametrize("sim", BOTH)
def test_negative_control_corrupted_u_fails(name, sim):
    """u scaled by 1.01: the replay leaves the programme and the check fails, with the time of the
    first breach; the uncorrupted run (test_replay_*, and knife_edge here) passes."""
    opts = CheckOptions(horizon=1.0)
    r, _ = _run(scene(name), sim, opts, corrupt_u=lambda t, u: 1.01 * u)
    assert r.status == "fail", r.metrics
    bad = {b.metric: b for b in r.breaches}
    assert "replay_residual" in bad and "replay_deviation" in bad
    assert bad["replay_deviation"].first_time is not None and bad["replay_deviation"].first_time < 0.5
    # The failure names the coordinate that deviates most and the row (issue 28).
    scene_ = ph.Scene(scene(name))
    dev = bad["replay_deviation"].where
    assert dev.split(" ", 1)[0] in ("coordinate", "velocity") and dev.split(" ", 1)[1] in (
        scene_.q_names + scene_.v_names), dev
    assert bad["replay_residual"].where in {f"row {r['name']}" for r in scene_.rows}
    assert f"at {dev}" in r.reason
    if name == "knife_edge":
        ok = run_check(scene(name), sim, opts)
        assert ok.status == "pass", ok.reason


@pytest.mark.parametrize("sim", BOTH)
def test_negative_control_bias(sim):
    """A constant 1e-6 N m added to the elbow torque is caught too."""
    r, _ = _run(scene("double_pendulum"), sim, CheckOptions(horizon=1.0),
                corrupt_u=lambda t, u: u + np.array([0.0, 1e-6]))
    assert r.status == "fail"
    assert "replay_residual" in {b.metric for b in r.breaches}


@pytest.mark.parametrize("sim", BOTH)
def test_lagrangian_scene_cannot_be_replayed_in_a_simulator(sim):
    """Asked directly, a simulator check of a lagrangian scene is an (undeclared, failing)
    not_checked naming the model; `progmo check` checks such scenes solver-only instead
    (test_solver_only.py)."""
    r = run_check(scene("slider_crank"), sim)
    assert r.status == "not_checked" and not r.expected and not r.ok()
    assert "lagrangian" in r.reason


@pytest.mark.parametrize("sim,pkg", [("mujoco", "mujoco"), ("pinocchio", "pinocchio")])
def test_missing_package_is_an_error(monkeypatch, sim, pkg):
    monkeypatch.setitem(sys.modules, pkg, None)  # import raises ImportError
    r = run_check(scene("double_pendulum"), sim)
    assert r.status == "error" and not r.ok()
    assert pkg in r.reason


def test_blow_up_at_the_start_is_a_failure_naming_it():
    r, _ = _run(scene("double_pendulum"), "mujoco", CheckOptions(horizon=0.1),
                corrupt_u=lambda t, u: 1e12 * u + 1e12)
    assert r.status == "fail" and "blew up" in r.reason, r.reason
    assert r.breaches[0].metric == "replay_blowup" and r.breaches[0].first_time == 0.0


@pytest.mark.parametrize("sim", ["mujoco", "pinocchio"])
def test_blow_up_keeps_the_evidence_up_to_the_last_finite_state(sim):
    """Forces that explode at t = 0.3: the replay up to there is judged and recorded, the blow-up
    is the first breach with its time and quantity, and the span says what was replayed."""
    rec = Recording()
    r, _ = _run(scene("double_pendulum"), sim, CheckOptions(horizon=1.0, step=1e-3),
                corrupt_u=lambda t, u: u if t < 0.3 else 1e14 * (u + 1.0), record=rec)
    assert r.status == "fail" and "blew up" in r.reason, r.reason
    b = r.breaches[0]
    assert b.metric == "replay_blowup" and 0.3 <= b.first_time <= 0.31 and b.value > b.budget
    assert rec.replay is not None and 250 < len(rec.replay.t) and rec.replay.t[-1] < b.first_time
    assert np.all(np.isfinite(rec.replay.q)) and np.all(np.isfinite(rec.deviation))
    full = ph.Scene(scene("double_pendulum"))
    assert r.span is not None and abs(r.span[0] - rec.replay.t[-1]) < 1e-12 and r.span[1] == full.t1 - full.t0
    assert np.isfinite(r.metrics["replay_residual"]) and r.series  # plots have data


def test_bad_inputs_are_errors(tmp_path):
    assert run_check(scene("double_pendulum"), "gazebo").status == "error"
    assert run_check(str(tmp_path / "nope.toml"), "mujoco").status == "error"


def _variant(tmp_path, name, drop=(), t1=None):
    text = (SCENES / f"{name}.toml").read_text()
    lines = [l for l in text.splitlines() if not any(l.startswith(d) for d in drop)]
    if t1 is not None:
        lines = [f"t1 = {t1}" if l.startswith("t1 =") else l for l in lines]
    p = tmp_path / f"{name}.toml"
    p.write_text("\n".join(lines) + "\n")
    return str(p)


def test_step_by_convergence_check(tmp_path):
    """Without replay_step the step is halved until the residual stops improving 16x."""
    p = _variant(tmp_path, "double_pendulum", drop=("replay_step",), t1=1.0)
    r = run_check(p, "mujoco")
    assert r.status == "pass", r.reason
    assert any("convergence check" in n for n in r.notes)
    assert r.info["replay_step"] < 1e-2


def test_parity_breach_does_not_blame_the_dynamics(tmp_path, monkeypatch):
    """A wrong exported model (mass matrix perturbed) fails parity and the replay is not judged."""
    from progmo.simulators import mujoco_sim

    orig = mujoco_sim.MujocoBackend.model_terms

    def wrong(self, t, q, v):
        M, rhs = orig(self, t, q, v)
        return M * 1.001, rhs

    monkeypatch.setattr(mujoco_sim.MujocoBackend, "model_terms", wrong)
    r = run_check(scene("double_pendulum"), "mujoco", CheckOptions(horizon=0.5))
    assert r.status == "fail"
    assert [b.metric for b in r.breaches] == ["parity_mass"]
    assert "replay_residual" not in r.metrics
    assert any("parity failed" in n for n in r.notes)


FREE = """name = "free_body"
description = "A free body under gravity whose body spin rate and vertical speed are programmed."
purpose = "Test of the checks with a free joint (Pinocchio: body-frame linear velocity)."
[model]
kind = "tree"
gravity = [0.0, 0.0, -9.81]
[[model.bodies]]
name = "body"
mass = 2.0
com = [0.1, 0.0, 0.05]
inertia = [0.1, 0.2, 0.3]
joints = [{ name = "base", type = "free" }]
[[programme]]
name = "spin"
expr = "base.wz - 1"
[[programme]]
name = "height"
expr = "base.vz"
[initial]
v = { base = [0.3, 0.1, 0.0, 0.5, -0.2, 1.0] }
[time]
t1 = 1.0
output_dt = 0.01
[checks]
replay_step = { value = 1e-3, reason = "test" }

[tolerances]
programme_residual = { value = 1e-10, reason = "projection" }
parity_mass = { value = 1e-12, reason = "test" }
parity_bias = { value = 1e-12, reason = "test" }
instant_u = { value = 1e-10, reason = "test" }
replay_residual = { value = 2e-10, reason = "measured 1.2e-11 (Pinocchio's SE3 integrator)" }
replay_deviation = { value = 2e-10, reason = "measured 1.2e-11" }
"""


@pytest.mark.parametrize("sim", BOTH)
def test_free_joint(tmp_path, sim):
    """Free joint: world-frame linear velocity (MuJoCo, ours) vs body frame (Pinocchio) maps."""
    p = tmp_path / "free_body.toml"
    p.write_text(FREE)
    r = run_check(str(p), sim)
    assert r.status == "pass", (r.reason, r.metrics)
    assert r.metrics["parity_bias"] < 1e-14 and r.metrics["instant_u"] < 1e-13


SPRINGS = """name = "spring_chain"
description = "Two links with joint springs and dampers, a ball joint below the root."
purpose = "test"

[model]
kind = "tree"
gravity = [0.0, 0.0, -9.81]

[[model.bodies]]
name = "a"
mass = 1.0
com = [0.0, 0.0, -0.5]
inertia = [0.02, 0.02, 0.01]
joints = [{ name = "q1", type = "hinge", axis = [0.0, 1.0, 0.0], stiffness = 5.0, spring_ref = 0.2, damping = 0.3 }]

[[model.bodies]]
name = "b"
parent = "a"
pos = [0.0, 0.0, -1.0]
mass = 1.0
com = [0.0, 0.0, -0.5]
inertia = [0.02, 0.02, 0.01]
joints = [{ name = "q2", type = "slide", axis = [0.0, 0.0, 1.0], stiffness = 20.0, spring_ref = -0.1, damping = 0.5 }]

[[programme]]
name = "elbow"
expr = "q2 - 0.1*sin(t)"

[initial]
q = { q1 = 0.3, q2 = 0.0 }
v = { q1 = 0.0, q2 = 0.1 }

[time]
t1 = 2.0
output_dt = 0.01

[checks]
replay_step = { value = 1e-3, reason = "test" }

[tolerances]
programme_residual = { value = 1e-10, reason = "test" }
parity_mass = { value = 1e-12, reason = "test" }
parity_bias = { value = 1e-12, reason = "test" }
instant_u = { value = 1e-10, reason = "test" }
replay_residual = { value = 1e-11, reason = "test" }
replay_deviation = { value = 1e-10, reason = "test" }
"""

BALL_BELOW_ROOT = """name = "spring_chain"
description = "Two links with joint springs and dampers, a ball joint below the root."
purpose = "test"

[model]
kind = "tree"
gravity = [0.0, 0.0, -9.81]

[[model.bodies]]
name = "a"
mass = 1.0
com = [0.0, 0.0, -0.5]
inertia = [0.02, 0.02, 0.01]
joints = [{ name = "q1", type = "hinge", axis = [0.0, 1.0, 0.0] }]

[[model.bodies]]
name = "b"
parent = "a"
pos = [0.0, 0.0, -1.0]
mass = 1.0
com = [0.0, 0.0, -0.5]
inertia = [0.02, 0.02, 0.01]
joints = [{ name = "ball", type = "ball" }]

[[programme]]
name = "elbow"
expr = "ball.wz - 0.1"

[initial]
q = { q1 = 0.3 }
v = { ball = [0.1, 0.0, 0.1] }

[time]
t1 = 2.0
output_dt = 0.01

[checks]
replay_step = { value = 1e-3, reason = "test" }

[tolerances]
programme_residual = { value = 1e-10, reason = "test" }
parity_mass = { value = 1e-12, reason = "test" }
parity_bias = { value = 1e-12, reason = "test" }
instant_u = { value = 1e-10, reason = "test" }
replay_residual = { value = 1e-10, reason = "test" }
replay_deviation = { value = 1e-10, reason = "test" }
"""


@pytest.mark.parametrize("sim", BOTH)
def test_springs_and_dampers(tmp_path, sim):
    """Joint springs/dampers: in the MJCF (qfrc_passive) for MuJoCo, applied by the harness from the
    report for Pinocchio (URDF has none)."""
    p = tmp_path / "springs.toml"
    p.write_text(SPRINGS)
    r = run_check(str(p), sim)
    assert r.status == "pass", (r.reason, r.metrics)
    assert r.metrics["parity_bias"] < 1e-14  # measured 1.2e-16: springs and dampers included


def test_ball_below_root_not_checked_in_pinocchio(tmp_path):
    p = tmp_path / "ball.toml"
    p.write_text(BALL_BELOW_ROOT)
    r = run_check(str(p), "pinocchio")
    assert r.status == "not_checked" and not r.expected and not r.ok()
    assert "URDF" in r.reason and "ball" in r.reason
    assert run_check(str(p), "mujoco").status in ("pass", "fail")  # MuJoCo can represent it


def _comparable(r) -> dict:
    """A result without what differs between two runs of the same check: wall times (also the
    seconds the notes give) and the note that the solve was shared."""
    import re

    d = r.to_json()
    d.pop("wall_seconds")
    d["notes"] = [re.sub(r"\b\d+(?:\.\d+)? s\b", "T s", n.replace(", shared with an earlier check of this scene file", ""))
                  for n in d["notes"]]
    return d


def test_checks_of_one_scene_share_the_reference_solve(tmp_path):
    # parallel.run_group runs a scene's simulators in one worker: the later checks reuse the first
    # one's reference solve and judge exactly as checks run alone do.
    from progmo import parallel

    p = str(SCENES / "double_pendulum.toml")
    sims = ("mujoco", "pinocchio")
    opts = CheckOptions(horizon=0.5)
    grouped = [r for _, r in parallel.run_group([(i, parallel.Task(p, "dp", s)) for i, s in enumerate(sims)],
                                                opts, parallel.DEFAULT_RUNNER)]
    alone = [run_check(p, s, opts) for s in sims]
    assert [_comparable(r) for r in grouped] == [_comparable(r) for r in alone]
    shared = [any("shared with an earlier check" in n for n in r.notes) for r in grouped]
    assert shared == [False, True]
    assert not any("shared with" in n for r in alone for n in r.notes)
    # the memo is keyed on the file's bytes: an edited file is solved afresh within the block
    f = tmp_path / "dp.toml"
    text = (SCENES / "double_pendulum.toml").read_text()
    with checks.shared_solves():
        f.write_text(text)
        a = run_check(str(f), "mujoco", opts)
        f.write_text(text + "\n# edited\n")
        b = run_check(str(f), "pinocchio", opts)
    assert a.status == b.status == "pass"
    assert not any("shared with" in n for r in (a, b) for n in r.notes)
