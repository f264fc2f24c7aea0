"""Verdicts that cannot lie (issue 9): every force of a tree scene reaches both simulators, a
scene without [tolerances] is judged by the documented defaults, an unexpected not_checked fails
the run, the checked span and the solver's conditioning warnings are in the verdict, and a scene
the solver refuses gets the located message of `progmo solve` and exit code 2 on every path.
Negative controls: a force withheld from one simulator, a wrong mass in the exported model."""

import json
import pathlib
import re
import subprocess
import sys

import pytest

from progmo import Scene, SceneError
from progmo.checks import (ACTUATOR_BUDGETED, BUDGETED, CLOSURE_BUDGETED, ROBOT_FILE_BUDGETED, SOLVER_ONLY_BUDGETED, CheckOptions,
                           _run, default_budgets, run_check)

ROOT = pathlib.Path(__file__).resolve().parents[2]
TESTS = ROOT / "tests" / "scenes"
SCENES = ROOT / "references" / "scenes"
BOTH = ("mujoco", "pinocchio")
POINT = str(TESTS / "point_forces.toml")
SHORT = CheckOptions(horizon=0.5, step=1e-3)


def cli(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "progmo.cli", *args], capture_output=True,
                          text=True, timeout=timeout, cwd=ROOT)


@pytest.mark.parametrize("sim", BOTH)
def test_point_and_coordinate_forces_reach_the_simulator(sim):
    """The scene's point forces and coordinate force are applied by the simulator itself; with no
    [tolerances] every metric is judged by its default budget."""
    r = run_check(POINT, sim, SHORT)
    assert r.status == "pass", (r.reason, r.metrics)
    assert {b.metric for b in r.budgets} == set(BUDGETED)
    assert {b.source for b in r.budgets} == {"default"}
    # Round-off agreement: the forces are in the simulator's equations (without them: 1e-1, below).
    assert r.metrics["parity_bias"] < 1e-13 and r.metrics["instant_u"] < 1e-12, r.metrics
    assert r.metrics["replay_residual"] < 1e-10 and r.metrics["replay_deviation"] < 1e-10, r.metrics


@pytest.mark.parametrize("sim", BOTH)
@pytest.mark.parametrize("kind", ["point_force", "coordinate_force"])
def test_a_force_withheld_from_the_simulator_fails(sim, kind):
    """Negative control: the same check with one kind of force not applied in the simulator must
    fail on model parity (the replay is then not blamed)."""
    r, _ = _run(POINT, sim, SHORT, withhold=(kind,))
    assert r.status == "fail", (r.reason, r.metrics)
    assert "parity_bias" in {b.metric for b in r.breaches}
    assert r.metrics["parity_bias"] > 1e-3
    # The failure names the joint and the force the simulator misses (issue 28).
    b = next(b for b in r.breaches if b.metric == "parity_bias")
    force = "the scene's point forces" if kind == "point_force" else "the coordinate force on q1"
    assert re.fullmatch(rf"joint q[12], {force} \(discrepancy = -1 x its force: the simulator misses it\)",
                        b.where), b.where
    assert f"parity_bias {b.value:.3g} > {b.budget:.3g} at {b.where}" in r.reason, r.reason


@pytest.mark.parametrize("sim,pattern", [("mujoco", r'mass="1\.0"'), ("pinocchio", r'<mass value="1\.0"/>')])
def test_budgetless_scene_with_a_wrong_mass_fails(sim, pattern):
    """Negative control: the last body's mass 1.0 -> 1.01 in the exported document of a scene with
    no [tolerances] fails by the default parity budget."""
    def wrong(doc):
        k = [m.start() for m in re.finditer(pattern, doc)][-1]
        return doc[:k] + re.sub(r"1\.0", "1.01", doc[k:k + 30], count=1) + doc[k + 30:]

    r, _ = _run(POINT, sim, SHORT, corrupt_export=wrong)
    assert r.status == "fail", (r.reason, r.metrics)
    assert "parity_mass" in {b.metric for b in r.breaches}
    # The failure names the worst entry's joints; no harness force explains a wrong mass.
    b = next(b for b in r.breaches if b.metric == "parity_mass")
    assert re.fullmatch(r"joints? q[12](, q[12])?", b.where), b.where
    assert f"at {b.where}" in r.reason and "force" not in r.reason, r.reason
    assert next(b for b in r.budgets if b.metric == "parity_mass").source == "default"


def test_default_budgets_follow_the_solver_settings():
    proj = default_budgets({"drift": {"kind": "projection", "tol": 1e-11, "max_iter": 8}})
    none = default_budgets({"drift": {"kind": "none"}})
    assert proj["solver_residual"][0] == pytest.approx(1e-9)
    assert none["solver_residual"][0] == pytest.approx(1e-8)
    assert set(proj) == (set(BUDGETED) | set(CLOSURE_BUDGETED) | set(ACTUATOR_BUDGETED)
                         | set(ROBOT_FILE_BUDGETED) | set(SOLVER_ONLY_BUDGETED))
    assert all(why.startswith("default") for _, why in proj.values())


@pytest.mark.parametrize("sim", BOTH)
def test_a_scene_without_programme_is_checked_against_the_free_motion(sim):
    r = run_check(str(TESTS / "no_programme.toml"), sim, CheckOptions(horizon=1.0, step=1e-3))
    assert r.status == "pass", (r.reason, r.metrics)
    assert r.metrics["replay_deviation"] < 1e-10 and r.metrics["parity_bias"] < 1e-13


SYSTEM_ROW = """name = "{name}"
description = "A double pendulum whose elbow angle is held by a system constraint (a joint lock)."
purpose = "test: system constraints are not exported; their reactions are supplied by progmo"
[model]
kind = "tree"
gravity = [0.0, 0.0, -9.81]
[[model.bodies]]
name = "upper"
mass = 1.0
com = [0.0, 0.0, -1.0]
inertia = [0.01, 0.01, 0.01]
joints = [{{ name = "q1", type = "hinge", axis = [0.0, 1.0, 0.0] }}]
[[model.bodies]]
name = "lower"
parent = "upper"
pos = [0.0, 0.0, -1.0]
mass = 1.0
com = [0.0, 0.0, -1.0]
inertia = [0.01, 0.01, 0.01]
joints = [{{ name = "q2", type = "hinge", axis = [0.0, 1.0, 0.0] }}]
[[constraints]]
name = "lock"
expr = "q2"
[[programme]]
name = "shoulder"
expr = "q1 - 0.3*sin(t)"
[initial]
v = {{ q1 = 0.3 }}
[time]
t1 = 0.5
output_dt = 0.01
{checks}"""


BALL_ROW = """name = "{name}"
description = "Two links, a ball joint below the root: no URDF element for it."
purpose = "test: an element a simulator cannot reproduce"
[model]
kind = "tree"
gravity = [0.0, 0.0, -9.81]
[[model.bodies]]
name = "a"
mass = 1.0
com = [0.0, 0.0, -0.5]
inertia = [0.02, 0.02, 0.01]
joints = [{{ name = "q1", type = "hinge", axis = [0.0, 1.0, 0.0] }}]
[[model.bodies]]
name = "b"
parent = "a"
pos = [0.0, 0.0, -1.0]
mass = 1.0
com = [0.0, 0.0, -0.5]
inertia = [0.02, 0.02, 0.01]
joints = [{{ name = "ball", type = "ball" }}]
[[programme]]
name = "elbow"
expr = "ball.wz - 0.1"
[initial]
q = {{ q1 = 0.3 }}
v = {{ ball = [0.1, 0.0, 0.1] }}
[time]
t1 = 0.5
output_dt = 0.01
{checks}"""


def test_unexpected_not_checked_fails_the_run_and_a_declared_one_does_not(tmp_path):
    plain = tmp_path / "ball.toml"
    plain.write_text(BALL_ROW.format(name="ball", checks=""))
    r = run_check(str(plain), "pinocchio")
    assert r.status == "not_checked" and not r.expected and "ball" in r.reason, r.reason
    args = ["check", "-s", "pinocchio", "--horizon", "0.5", "--no-plots", "-j", "1"]
    p = cli(*args, "-o", str(tmp_path / "a"), "double_pendulum", str(plain))
    assert p.returncode == 1, p.stdout + p.stderr
    assert "FAIL: 1 of 2 (scene x simulator) passed; 1 not checked" in p.stdout
    declared = tmp_path / "declared.toml"
    declared.write_text(BALL_ROW.format(
        name="declared", checks='[checks]\nnot_checked = { pinocchio = "URDF has no ball joint below the root" }\n'))
    p = cli(*args, "-o", str(tmp_path / "b"), "double_pendulum", str(declared))
    assert p.returncode == 0, p.stdout + p.stderr
    assert "PASS: 1 of 2 (scene x simulator) passed; 1 not checked as declared (declared/pinocchio)" in p.stdout
    md = (tmp_path / "b" / "summary.md").read_text()
    assert "URDF has no ball joint below the root" in md


def test_a_system_row_is_checked_with_its_reaction_supplied_and_says_so(tmp_path):
    """An expression system constraint (a joint lock) no simulator holds: the model leaves it out,
    progmo supplies its reaction, the check passes and the progress line, the summary line and
    summary.md name the row; withheld, the replay leaves the row (negative control)."""
    plain = tmp_path / "locked.toml"
    plain.write_text(SYSTEM_ROW.format(name="locked", checks=""))
    for sim in BOTH:
        r = run_check(str(plain), sim)
        assert r.status == "pass" and r.supplied == ["lock"], (sim, r.reason, r.metrics)
        assert any("reactions of rows lock supplied by progmo: system constraints `lock`" in n
                   for n in r.notes), r.notes
    r, _ = _run(str(plain), "mujoco", withhold=("supplied_reaction",))
    assert r.status == "fail" and "replay_residual" in {b.metric for b in r.breaches}, (r.reason, r.metrics)
    args = ["check", "-s", "mujoco", "--horizon", "0.5", "--no-plots", "-j", "1"]
    p = cli(*args, "-o", str(tmp_path / "a"), "double_pendulum", str(plain))
    assert p.returncode == 0, p.stdout + p.stderr
    assert "locked / mujoco: pass (" in p.stderr and "[reactions of lock supplied by progmo]" in p.stderr
    assert "PASS: 2 of 2 (scene x simulator) passed;" in p.stdout
    assert "reactions supplied by progmo for rows no simulator holds: locked (lock)" in p.stdout
    md = (tmp_path / "a" / "summary.md").read_text()
    assert "locked (reactions of lock supplied by progmo)" in md


def test_refused_scene_gets_the_solve_diagnosis_and_exit_2_in_check_and_debug(tmp_path):
    text = (SCENES / "double_pendulum.toml").read_text().replace('q2 = "amp*w"', "q2 = 0.7")
    bad = tmp_path / "off.toml"
    bad.write_text(text)
    with pytest.raises(SceneError) as e:
        Scene(str(bad)).check_initial()
    located = str(e.value)  # what `progmo solve` prints (Scene::initial_error, one place)
    line = next(i + 1 for i, l in enumerate(text.splitlines()) if l.startswith('expr = "q2'))
    assert f"off.toml:{line}:" in located and "initial state violates" in located
    p = cli("check", "-s", "mujoco", "--no-plots", "-o", str(tmp_path / "o"), str(bad))
    assert p.returncode == 2, p.stdout + p.stderr
    assert located.splitlines()[0] in p.stderr
    p = cli("debug", str(bad), "--out", str(tmp_path / "d"))
    assert p.returncode == 2, p.stdout + p.stderr
    assert located.splitlines()[0] in p.stderr


def test_conditioning_warnings_and_checked_span_reach_the_report(tmp_path):
    """The precession programme through its degenerate point: the solver's row_gradient warning
    is in the result, the report and summary.md; chain_8's whole span, replayed in segments, is in
    the verdict table and the overall line (no shortened span)."""
    p = cli("check", "-s", "pinocchio", "--no-plots", "-o", str(tmp_path / "o"),
            str(TESTS / "precession_degenerate.toml"), "chain_8")
    res = {r["scene"]: r for r in json.loads((tmp_path / "o" / "results.json").read_text())}
    w = res["precession_degenerate"]["warnings"]
    assert w and "`precession`" in w[0] and "initial norm" in w[0], w
    assert res["chain_8"]["span"] == [2.0, 2.0]
    md = (tmp_path / "o" / "summary.md").read_text()
    assert "## Solver conditioning warnings" in md and "`precession`" in md
    assert "| chain_8 |" in md and "2 s" in md and "of 2 s" not in md
    assert "replayed in segments restarted from the solver (open-loop growth beyond x1000): chain_8 (3)" in p.stdout
    assert "shortened span" not in p.stdout
    assert "solver conditioning warnings: precession_degenerate" in p.stdout
    html = (tmp_path / "o" / "report.html").read_text()
    assert "solver warning:" in html and "checked span" in html
