"""A scene no simulator document describes (a lagrangian model) is checked solver-only (issue 12,
item 5): a second formulation and the scene's [[reference]] values of independent origin, a verdict
of its own in the report and the summary, never a skip inside a PASS. Negative controls: a wrong
reference value, and a budget below what the two formulations measure, must fail."""

import json
import pathlib
import re
import subprocess
import sys

import pytest

from progmo import Scene
from progmo.checks import SOLVER_ONLY_BUDGETED, run_check, second_formulation

ROOT = pathlib.Path(__file__).resolve().parents[2]
CRANK = ROOT / "references" / "scenes" / "slider_crank.toml"


def cli(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "progmo.cli", *args], capture_output=True,
                          text=True, timeout=timeout, cwd=ROOT)


def doctored(tmp_path, old, new, name="crank.toml"):
    text = CRANK.read_text()
    assert old in text
    p = tmp_path / name
    p.write_text(text.replace(old, new, 1))
    return p


def test_the_slider_crank_passes_solver_only_against_its_closed_form():
    r = run_check(str(CRANK), "solver_only")
    assert r.status == "pass", (r.reason, r.metrics)
    assert {b.metric for b in r.budgets} == set(SOLVER_ONLY_BUDGETED)
    # 9 values of the closed-form loop kinematics (one time off the output grid), to round-off of a
    # solve at rtol 1e-12; the two formulations agree to the integration error.
    assert r.info["reference_values"] == 9
    assert r.metrics["reference_error"] < 1e-10, r.metrics
    assert r.metrics["formulation_deviation"] < 1e-9, r.metrics
    assert any("auto against kkt" in n for n in r.notes), r.notes  # the default formulation


def test_the_references_are_evaluated_from_the_file():
    sc = Scene(str(CRANK))
    refs = sc.references
    assert len(refs) == 9 and {r["quantity"] for r in refs} == {"q", "v"}
    p = dict(sc.parameters)
    x3 = next(r for r in refs if r["name"] == "x3" and r["quantity"] == "q" and r["t"] == 0.1)
    import math

    phi = p["Omega"] * 0.1
    assert x3["value"] == pytest.approx(p["L1"] * math.cos(phi) + math.sqrt(p["L2"] ** 2 - (p["L1"] * math.sin(phi)) ** 2), rel=1e-15)
    assert x3["field"] == "reference[2].q.x3"


def test_a_wrong_reference_value_fails(tmp_path):
    """Negative control: the closed form of x3 shifted by 1e-6 m at one time must fail."""
    p = doctored(tmp_path, 'q = { phi2 = "-asin(L1/L2*sin(Omega*t))", x3 = "L1*cos(Omega*t) + sqrt(L2^2 - L1^2*sin(Omega*t)^2)" }',
                 'q = { phi2 = "-asin(L1/L2*sin(Omega*t))", x3 = "1e-6 + L1*cos(Omega*t) + sqrt(L2^2 - L1^2*sin(Omega*t)^2)" }')
    r = run_check(str(p), "solver_only")
    assert r.status == "fail", (r.reason, r.metrics)
    assert [b.metric for b in r.breaches] == ["reference_error"]
    assert r.metrics["reference_error"] == pytest.approx(1e-6, rel=1e-3)


def test_a_budget_below_the_formulations_difference_fails(tmp_path):
    """Negative control: the formulation metrics are judged (a budget of 1e-16 cannot hold)."""
    p = doctored(tmp_path, "[tolerances]\n",
                 '[tolerances]\nformulation_deviation = { value = 1e-16, reason = "negative control" }\n')
    r = run_check(str(p), "solver_only")
    assert r.status == "fail"
    assert "formulation_deviation" in {b.metric for b in r.breaches}


def test_the_second_formulation_differs_from_the_first():
    assert second_formulation("null_space") == "kkt"
    assert second_formulation("kkt") == "null_space"


def test_check_schedules_lagrangian_scenes_solver_only_and_reports_it(tmp_path):
    """`progmo check` on a lagrangian and a tree scene: the lagrangian one gets one solver_only
    cell (its simulator cells read "-" and do not count), the tree one both simulators; the summary
    line names the scene checked solver-only; exit 0."""
    out = tmp_path / "out"
    p = cli("check", str(CRANK), "double_pendulum", "-s", "mujoco", "-s", "pinocchio", "--horizon", "0.1",
            "--no-plots", "-j", "1", "-o", str(out), "--json")
    assert p.returncode == 0, p.stdout + p.stderr
    doc = json.loads(p.stdout)
    cells = sorted((r["scene"], r["simulator"], r["verdict"]) for r in doc["results"])
    assert cells == [("double_pendulum", "mujoco", "pass"), ("double_pendulum", "pinocchio", "pass"),
                     ("slider_crank", "solver_only", "pass")]
    assert "3 of 3 (scene x simulator) passed" in doc["coverage"]
    assert "1 checked solver-only, no simulator model (slider_crank)" in doc["coverage"]
    html = (out / "report.html").read_text().replace("\n", "")
    header = re.search(r"<table id='verdicts'><thead><tr>(.*?)</tr>", html).group(1)
    assert re.findall(r"<th>(.*?)</th>", header)[1:4] == ["mujoco", "pinocchio", "solver_only"]
    row = re.search(r"<tr><td><a href='#[^']*'>slider_crank</a></td>(.*?)</tr>", html).group(1)
    tds = re.findall(r"<td class='(c-[a-z_-]+)'(?: title='([^']*)')?>", row)
    assert [c for c, _ in tds[:3]] == ["c-na", "c-na", "c-pass"], tds
    assert "checked solver-only" in tds[0][1]
    md = (out / "summary.md").read_text()
    assert re.search(r"\| slider_crank \| — \| — \| ✅ pass \|", md), md


def test_a_failing_solver_only_check_fails_the_run(tmp_path):
    p = doctored(tmp_path, "[tolerances]\n",
                 '[tolerances]\nreference_error = { value = 1e-18, reason = "negative control" }\n')
    r = cli("check", str(p), "--no-plots", "-j", "1", "-o", str(tmp_path / "out"))
    assert r.returncode == 1, r.stdout + r.stderr
    assert "reference_error" in r.stderr + r.stdout
