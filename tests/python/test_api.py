"""The public Python API (`import progmo`) and the `progmo` command of the package: bundled names
from any directory, Solution against the files of `progmo solve` (two doors, one result), typed
errors, check with baselines (a regression must fail), export, `--json` on every subcommand that
has it, version differences of baselines."""

import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import fake_checks
import progmo
from progmo import baselines as bl
from progmo import checks, cli, data, parallel

ROOT = pathlib.Path(__file__).resolve().parents[2]
DEGENERATE = ROOT / "tests" / "scenes" / "precession_degenerate.toml"


def progmo_cmd(*args, cwd=None):
    """The package's `progmo` command, as `pip install` makes it."""
    return subprocess.run([sys.executable, "-m", "progmo.command", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=600)


def test_load_finds_bundled_scenes_by_name_from_any_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert progmo.load("double_pendulum").name == "double_pendulum"
    assert progmo.load("heavy_top.toml").kind == "tree"
    assert "double_pendulum" in data.bundled_scenes()
    with pytest.raises(progmo.SceneError, match=r"nope: no such scene file or bundled scene .*double_pendulum"):
        progmo.load("nope")
    with pytest.raises(progmo.SceneError, match="no such scene file"):
        progmo.load(tmp_path / "missing.toml")


def test_solution_arrays_and_writers_equal_the_files_of_progmo_solve(tmp_path):
    scene = progmo.load("double_pendulum")
    sol = scene.solve(output_dt=0.05)
    n = len(sol)
    assert sol.success and sol.code == "success" and n == 201 and sol.t[-1] == scene.t1
    assert sol.q.shape == (n, len(sol.q_names)) and sol.u.shape == (n, len(sol.v_names))
    assert sol.lambda_.shape == sol.residuals.shape == (n, len(sol.row_names))
    with pytest.raises(ValueError, match="read-only"):
        sol.u[0, 0] = 1.0
    sol.write_csv(tmp_path / "py.csv")
    sol.write_mcap(tmp_path / "py.mcap")
    sol.write_summary(tmp_path / "py.json")
    # The other door: the command line streams the same solve into the same writers.
    r = progmo_cmd("solve", "double_pendulum", "--output-dt", "0.05", "--out", tmp_path / "cli", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "py.csv").read_bytes() == (tmp_path / "cli" / "trajectory.csv").read_bytes()
    a, b = (json.loads(p.read_text()) for p in (tmp_path / "py.json", tmp_path / "cli" / "summary.json"))
    for k in ("wall_seconds", "command_line"):
        a.pop(k, None), b.pop(k, None)
    assert a == b
    from mcap.reader import make_reader

    def messages(p):
        with open(p, "rb") as f:
            return [(c.topic, m.log_time, m.data) for _, c, m in make_reader(f).iter_messages()]

    assert messages(tmp_path / "py.mcap") == messages(tmp_path / "cli" / "recording.mcap")
    # and the CSV holds the arrays, digit for digit
    rows = np.loadtxt(tmp_path / "py.csv", delimiter=",", skiprows=1)
    assert np.array_equal(rows[:, 0], sol.t) and np.array_equal(rows[:, 1:3], sol.q)


def test_a_servo_scenes_summary_carries_the_servo_analysis_through_both_doors(tmp_path):
    # passive_arm (issue 17): the analysis with its internal dynamics along the motion; the summary
    # of Scene.solve equals the one of `progmo solve`, `servo` included
    scene = progmo.load("passive_arm")
    sol = scene.solve(t1=1.0, output_dt=0.05)
    assert sol.success, sol.message
    sol.write_summary(tmp_path / "py.json")
    r = progmo_cmd("solve", "passive_arm", "--t1", "1", "--output-dt", "0.05", "--out", tmp_path / "cli",
                   cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    a, b = (json.loads(p.read_text()) for p in (tmp_path / "py.json", tmp_path / "cli" / "summary.json"))
    for k in ("wall_seconds", "command_line"):
        a.pop(k, None), b.pop(k, None)
    assert a["servo"]["internal"]["dimension"] == 2 and a["servo"]["internal"]["stability"] == "stable"
    assert a == b
    # a scene without actuators has no servo key
    progmo.load("double_pendulum").solve(t1=0.1).write_summary(tmp_path / "plain.json")
    assert "servo" not in json.loads((tmp_path / "plain.json").read_text())


def test_a_stopped_solve_keeps_its_samples_and_can_raise(tmp_path):
    scene = progmo.load(DEGENERATE)
    sol = scene.solve(strict=True)
    assert not sol.success and sol.code == "ill_conditioned" and sol.t_end < scene.t1
    assert len(sol) > 1 and sol.t[-1] == sol.t_end and "t =" in sol.message
    with pytest.raises(progmo.SolveStopped) as e:
        sol.raise_if_stopped()
    assert e.value.code == sol.code and e.value.solution is sol and str(e.value) == sol.message
    ok = progmo.load("double_pendulum").solve(t1=0.1)
    assert ok.raise_if_stopped() is ok


def test_typed_errors():
    scene = progmo.load("double_pendulum")
    with pytest.raises(progmo.SettingsError, match="rtol"):
        scene.solve(rtol=-1.0)
    with pytest.raises(progmo.SettingsError, match="integrator"):
        scene.solve(integrator="euler")  # type: ignore[arg-type]
    assert issubclass(progmo.SettingsError, ValueError) and issubclass(progmo.SceneError, ValueError)
    lagrangian = next(n for n in data.bundled_scenes() if progmo.load(n).kind == "lagrangian")
    with pytest.raises(progmo.ExportUnsupported):
        progmo.export(lagrangian, "mjcf")
    doc, report = progmo.export("heavy_top", "urdf")
    assert doc.lstrip().startswith("<?xml") or "<robot" in doc
    assert report["format"].lower() == "urdf"
    with pytest.raises(ValueError, match="unknown simulator"):
        progmo.check("double_pendulum", "bullet")  # type: ignore[arg-type]


def test_check_judges_and_a_regression_has_one_status_at_both_doors(tmp_path):
    r = progmo.check("double_pendulum", "mujoco")
    assert r.status == "pass" and r.ok(), r.reason
    assert {b.metric for b in r.budgets} >= {"replay_residual", "parity_mass"}
    assert all(r.metrics[b.metric] <= b.value for b in r.budgets)
    # the bundled baseline passes; one holding a metric today's run lost must fail (negative control;
    # double_pendulum's values sit below the absolute floors, so a lowered value could not regress)
    assert progmo.check("double_pendulum", "mujoco", baselines=data.baselines_dir()).status == "pass"
    doc = json.loads(bl.path_for(data.baselines_dir(), "double_pendulum", "mujoco").read_text())
    doc["metrics"]["replay_error_lost"] = 1e-12
    bl.path_for(tmp_path, "double_pendulum", "mujoco").write_text(json.dumps(doc))
    bad = progmo.check("double_pendulum", "mujoco", baselines=tmp_path)
    assert bad.status == "regression" and not bad.ok(), bad.status
    assert "regression" in bad.reason and "replay_error_lost" in bad.reason
    # the command gives the same pair the same status against the same baselines (one verdict)
    r = progmo_cmd("check", "double_pendulum", "-s", "mujoco", "--baselines", tmp_path, "--out", tmp_path / "out",
                   "--no-plots", "--json", cwd=tmp_path)
    assert r.returncode == 1, r.stderr
    (cell,) = json.loads(r.stdout)["results"]
    assert cell["verdict"] == bad.status == "regression"


def test_json_output_of_solve_validate_export_and_check(tmp_path):
    r = progmo_cmd("solve", "double_pendulum", "--t1", "0.5", "--out", tmp_path / "s", "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["code_name"] == "success" and doc["output"] == str(tmp_path / "s") and "success" in r.stderr

    r = progmo_cmd("validate", "double_pendulum", "heavy_top", "nope", "--json", cwd=tmp_path)
    assert r.returncode == 2
    v = json.loads(r.stdout)
    assert [x["ok"] for x in v] == [True, True, False] and v[0]["nq"] == 2 and "nope" in r.stderr

    r = progmo_cmd("export", "heavy_top", "--format", "mjcf", "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    e = json.loads(r.stdout)
    assert e["format"] == "mjcf" and e["document"].startswith("<mujoco") and "q_map" in e["report"]
    r = progmo_cmd("export", "heavy_top", "--format", "mjcf", "--out", tmp_path / "m.xml", cwd=tmp_path)
    assert r.returncode == 0 and "wrote" in r.stdout and (tmp_path / "m.xml.report.json").is_file()

    r = progmo_cmd("check", "double_pendulum", "-s", "pinocchio", "--no-plots", "-j", "1", "--json",
                   "--out", tmp_path / "c", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    c = json.loads(r.stdout)
    assert c["ok"] and c["results"][0]["verdict"] == "pass" and "series" not in c["results"][0]
    assert "PASS" in r.stderr


def test_same_exit_code_for_the_same_bad_scene_in_every_subcommand(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("name = 'x'\n[model]\nkind = 'nonsense'\n")
    for args in (["solve", bad], ["validate", bad], ["export", bad, "--format", "mjcf"],
                 ["check", bad, "--no-plots", "-o", tmp_path / "c"], ["debug", bad, "--out", tmp_path / "d"]):
        r = progmo_cmd(*args, cwd=tmp_path)
        assert r.returncode == 2, (args, r.returncode, r.stderr)
        assert "Traceback" not in r.stderr and "bad.toml" in r.stderr


def test_every_subcommand_help_has_one_style():
    for sub in ("solve", "validate", "export", "check", "debug", "report", "bench", "corpus"):
        r = progmo_cmd(sub, "--help")
        assert r.returncode == 0, (sub, r.stderr)
        lines = r.stdout.splitlines()
        # clap's layout: the description, then "Usage: progmo SUB", "Options:" (and "Arguments:")
        usage = next(i for i, ln in enumerate(lines) if ln.startswith(f"Usage: progmo {sub}"))
        assert usage > 0 and lines[0].strip() and "Options:" in lines[usage:], (sub, r.stdout[:300])
        assert "positional arguments" not in r.stdout and "show this help" not in r.stdout, sub


def test_version_differences_of_a_baseline_are_named():
    prov = {"progmo": "0.2.0", "mujoco": "4.0.0", "pinocchio": "4.1.0"}
    base = {"accepted": {"progmo": "0.1.0", "mujoco": "4.0.0", "pinocchio": "4.1.0"}}
    assert bl.version_differences(base, prov) == ["progmo 0.1.0 (now 0.2.0)"]
    assert bl.version_differences({"accepted": {}}, prov)[0].startswith("progmo not recorded")
    assert bl.version_differences(None, prov) == []


def test_a_check_against_a_baseline_from_other_versions_says_so(tmp_path, monkeypatch):
    monkeypatch.delenv(parallel.RUNNER_ENV, raising=False)
    monkeypatch.delenv(fake_checks.PLAN_ENV, raising=False)
    monkeypatch.setattr(checks, "run_check", fake_checks.run_check)
    base, out = tmp_path / "b", tmp_path / "o"
    args = ["check", "--out", str(out), "--baselines", str(base), "--jobs", "1", "--no-plots", "-s", "mujoco"]
    assert cli.main([*args, "--accept", "heavy_top"]) == 0
    p = bl.path_for(base, "heavy_top", "mujoco")
    doc = json.loads(p.read_text())
    doc["accepted"]["mujoco"] = "3.9.0"
    p.write_text(json.dumps(doc))
    assert cli.main([*args, "heavy_top"]) == 0
    notes = json.loads((out / "run.json").read_text())["notes"]
    assert any("mujoco 3.9.0 (now" in n and "heavy_top/mujoco" in n for n in notes), notes
    assert "mujoco 3.9.0" in (out / "report.html").read_text()


# --- the API checks what the command line checks (issue 29, round two) ----------------------------
BAD_OPTIONS = [
    (dict(step=0), ["--step", "0"], "step: must be a finite number > 0, got 0"),
    (dict(step=-1.0), ["--step", "-1"], "step: must be a finite number > 0, got -1"),
    (dict(step=float("nan")), ["--step", "nan"], "step: must be a finite number > 0, got nan"),
    (dict(horizon=0), ["--horizon", "0"], "horizon: must be a number > 0 (s), got 0"),
    (dict(samples=0), ["--samples", "0"], "samples: must be an integer from 1 to 10000, got 0"),
    (dict(samples=10**9), ["--samples", "1000000000"], "samples: must be an integer from 1 to 10000, got 1000000000"),
]


@pytest.mark.parametrize("kwargs,flags,message", BAD_OPTIONS)
def test_check_options_are_refused_by_the_api_as_by_the_command(kwargs, flags, message, monkeypatch, tmp_path):
    ran = []
    monkeypatch.setattr(checks, "run_check", lambda *a: ran.append(a))
    with pytest.raises(progmo.SettingsError) as e:
        progmo.check("double_pendulum", "mujoco", **kwargs)
    assert str(e.value) == message and not ran
    r = progmo_cmd("check", "double_pendulum", "-s", "mujoco", *flags, "-o", tmp_path / "o")
    assert r.returncode == 2 and r.stderr.splitlines()[-1] == f"progmo check: error: --{message}", r.stderr
    r = progmo_cmd("debug", "double_pendulum", *flags, "--out", tmp_path / "d") if "samples" not in kwargs else r
    assert r.returncode == 2 and r.stderr.splitlines()[-1].endswith(f": error: --{message}"), r.stderr


def test_a_step_that_cannot_advance_time_is_named_as_the_replay_step(tmp_path):
    # --step 1e-300 was reported as the reference solve's output_dt (h/2); the core names it
    r = progmo.check("double_pendulum", "mujoco", step=1e-300)
    assert r.status == "error" and r.reason.startswith("replay_step: ") and "output_dt" not in r.reason, r.reason
    with pytest.raises(progmo.SettingsError, match=r"^replay_step: "):
        progmo.load("double_pendulum").check_replay_step(1e-300)
    progmo.load("double_pendulum").check_replay_step(1e-3)  # a usable step passes


@pytest.mark.parametrize("make", ["fifo", "/dev/zero", "/dev/null"])
def test_scene_files_that_are_not_regular_are_refused_at_once(make, tmp_path):
    import os
    import time

    path = tmp_path / "scene.toml"
    if make == "fifo":
        os.mkfifo(path)  # nobody writes: reading would block forever
    else:
        path = pathlib.Path(make)
    for door in (progmo.load, progmo.Scene):
        start = time.monotonic()
        with pytest.raises(progmo.SceneError, match="not a regular file"):
            door(str(path))
        assert time.monotonic() - start < 1


def test_a_huge_output_request_is_refused_before_allocating():
    import resource
    import time

    scene = progmo.load("double_pendulum")
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    start = time.monotonic()
    for kw in (dict(output_dt=1e-12), dict(t1=1e12, output_dt=1e-3), dict(output_dt=1e-12, max_samples=10**13)):
        with pytest.raises(progmo.SettingsError, match="^output_dt: .* samples over .* more than max_samples"):
            scene.solve(**kw)
    assert time.monotonic() - start < 1
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 50_000  # kB


def test_a_trajectory_over_the_in_memory_limit_is_refused_before_allocating():
    """Within max_samples but over 1 GiB of samples (progmo::solve::IN_MEMORY_LIMIT_BYTES): refused
    naming output_dt before integrating; the same spacing under the limit is not."""
    import resource

    scene = progmo.load("double_pendulum")
    span = scene.t1 - scene.t0
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with pytest.raises(progmo.SettingsError, match=r"^output_dt: .* GiB in memory, over the limit of 1 GiB") as e:
        scene.solve(output_dt=span / 5e7, max_samples=10**8)
    assert e.value.field == "output_dt"
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 50_000  # kB
    sol = scene.solve(output_dt=span / 1000)  # negative control: the same door under the limit
    assert len(sol.t) == 1001
