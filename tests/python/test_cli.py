"""`progmo check` orchestration with a fake run_check: exit codes, outputs kept on failure and
interruption, baselines (regression, --accept), the process pool, help and the debug hook."""

import importlib.machinery
import json
import pathlib
import subprocess
import sys
import types

import pytest

import fake_checks
from progmo import checks, cli, parallel

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENES = ROOT / "references" / "scenes"
TWO = ["double_pendulum", "heavy_top"]
#: the default set: every installed simulator (harness/setup.sh installs all three)
SIMS = cli.default_simulators(None)[0]
N = len(SIMS)


@pytest.fixture
def env(tmp_path, monkeypatch):
    """A fake run_check (in-process, --jobs 1), empty baselines and an output folder."""
    monkeypatch.delenv(parallel.RUNNER_ENV, raising=False)
    monkeypatch.delenv(fake_checks.PLAN_ENV, raising=False)
    monkeypatch.setattr(checks, "run_check", fake_checks.run_check)
    out, base = tmp_path / "out", tmp_path / "baselines"

    def run(*args, plan=None, jobs="1", plots=False):
        if plan is not None:
            monkeypatch.setenv(fake_checks.PLAN_ENV, json.dumps(plan))
        extra = [] if plots else ["--no-plots"]  # plots cost 0.5 s a result; test_report covers them
        return cli.main(["check", "--out", str(out), "--baselines", str(base), "--jobs", jobs, *extra, *args])

    run.out, run.base = out, base
    return run


def statuses(out):
    return {(r["scene"], r["simulator"]): r["status"] for r in json.loads((out / "results.json").read_text())}


def test_all_pass_exits_0_and_writes_every_output(env, capsys):
    assert env(*TWO, plots=True) == 0
    assert (env.out / "report.html").read_text().count("data:image/png;base64,") == 2 * N
    for f in ("results.json", "run.json", "report.html", "summary.md", "summary.csv"):
        assert (env.out / f).is_file(), f
    assert set(statuses(env.out).values()) == {"pass"} and len(statuses(env.out)) == 2 * N
    err = capsys.readouterr().err
    assert f"[{2 * N}/{2 * N}]" in err and "heavy_top / pinocchio: pass" in err


def test_default_is_every_bundled_scene_in_every_installed_simulator(env):
    """Every bundled scene in every installed simulator, a lagrangian one solver-only instead."""
    assert env() == 0
    st = statuses(env.out)
    files = list(SCENES.glob("*.toml"))
    lagrangian = {f.stem for f in files if 'kind = "lagrangian"' in f.read_text()}
    assert lagrangian, "the catalog has a lagrangian scene"
    assert len(st) == N * (len(files) - len(lagrangian)) + len(lagrangian)
    assert {m for (s, m) in st if s in lagrangian} == {"solver_only"}


def test_declared_not_checked_is_not_a_failure(env):
    assert env(*TWO, plan={"heavy_top/mujoco": "declared"}) == 0
    assert statuses(env.out)[("heavy_top", "mujoco")] == "not_checked"
    assert "1 not checked as declared (heavy_top/mujoco)" in (env.out / "summary.md").read_text()


def test_undeclared_not_checked_fails_the_run(env):
    assert env(*TWO, plan={"heavy_top/mujoco": "not_checked"}) == 1
    md = (env.out / "summary.md").read_text()
    assert md.startswith("# progmo check: FAIL") and "1 not checked" in md


def test_a_run_that_checked_nothing_fails(env):
    assert env(*TWO, plan={"heavy_top": "declared", "double_pendulum": "declared"}) == 1


def test_fail_exits_1(env):
    assert env(*TWO, plan={"heavy_top/pinocchio": "fail"}) == 1
    assert "FAIL" in (env.out / "summary.md").read_text()


def test_error_result_exits_1(env):
    assert env(*TWO, plan={"double_pendulum/mujoco": "error"}) == 1


def test_raising_check_becomes_an_error_result_and_the_rest_runs(env):
    assert env(*TWO, plan={"heavy_top/mujoco": "raise"}) == 1
    res = {(r["scene"], r["simulator"]): r for r in json.loads((env.out / "results.json").read_text())}
    assert len(res) == 2 * N
    bad = res[("heavy_top", "mujoco")]
    assert bad["status"] == "error"
    assert bad["reason"] == "check raised RuntimeError: simulated crash in heavy_top <mujoco>"
    assert res[("heavy_top", "pinocchio")]["status"] == "pass"


def test_scene_that_does_not_load_exits_2_and_the_rest_runs(env, tmp_path):
    bad = tmp_path / "broken.toml"
    bad.write_text("name = 'broken'\n[model\n")
    assert env(str(bad), "heavy_top") == 2
    st = statuses(env.out)
    assert st[("heavy_top", "mujoco")] == st[("heavy_top", "pinocchio")] == "pass"
    assert st[("broken", "mujoco")] == "error"
    assert "does not load" in (env.out / "report.html").read_text()


@pytest.mark.parametrize("args", [["no_such_scene"], ["--jobs", "0", "heavy_top"], ["--samples", "0"]])
def test_bad_usage_exits_2(env, args):
    assert cli.main(["check", "--out", str(env.out), "--baselines", str(env.base), *args]) == 2


def test_unknown_simulator_is_a_usage_error(env):
    with pytest.raises(SystemExit) as e:
        env("-s", "bullet", "heavy_top")
    assert e.value.code == 2


def test_one_simulator(env):
    assert env("-s", "pinocchio", "heavy_top") == 0
    assert list(statuses(env.out)) == [("heavy_top", "pinocchio")]


def test_accept_writes_baselines_for_passing_checks_only(env, capsys):
    assert env("--accept", *TWO, plan={"heavy_top/mujoco": "fail"}) == 1
    names = sorted(p.name for p in env.base.iterdir())
    assert names == sorted(f"{s}.{m}.json" for s in TWO for m in SIMS if (s, m) != ("heavy_top", "mujoco"))
    doc = json.loads((env.base / "heavy_top.pinocchio.json").read_text())
    assert doc["scene"] == "heavy_top" and doc["metrics"]["replay_residual"] > 0
    assert {"date", "git_revision", "mujoco", "pinocchio", "numpy", "python"} <= set(doc["accepted"])
    out = capsys.readouterr().out
    assert "replay_residual: new" in out and "heavy_top / mujoco: fail, baseline not updated" in out


def test_regression_against_baseline_is_flagged_and_accept_clears_it(env, capsys):
    assert env("--accept", *TWO) == 0
    capsys.readouterr()
    # Negative control: the same metrics again are no regression.
    assert env(*TWO) == 0
    assert env(*TWO, plan={"heavy_top/mujoco": "regress"}) == 1
    assert statuses(env.out)[("heavy_top", "mujoco")] == "pass"  # within budget ...
    run = json.loads((env.out / "run.json").read_text())
    states = {
        (c["scene"], c["simulator"], m["metric"]): m["state"] for c in run["comparisons"] for m in c["metrics"]
    }
    assert states[("heavy_top", "mujoco", "replay_residual")] == "regression"  # ... but regressed
    assert states[("heavy_top", "pinocchio", "replay_residual")] == "ok"
    assert "heavy_top / mujoco: regression" in capsys.readouterr().err
    assert "regression" in (env.out / "summary.md").read_text()
    # Deliberate acceptance: exit 0, the baseline moves, the next run is clean.
    assert env("--accept", *TWO, plan={"heavy_top/mujoco": "regress"}) == 0
    assert "replay_residual: 3.29e-11 -> 6.58e-10" in capsys.readouterr().out
    assert env(*TWO, plan={"heavy_top/mujoco": "regress"}) == 0


def test_corrupt_baseline_is_reported(env):
    env.base.mkdir()
    (env.base / "heavy_top.mujoco.json").write_text("{not json")
    assert env("heavy_top") == 2
    assert "not a valid baseline" in (env.out / "report.html").read_text()


def test_interrupt_keeps_results_and_report(env):
    assert env(*TWO, plan={"heavy_top/mujoco": "interrupt"}) == 130
    st = statuses(env.out)
    assert st == {("double_pendulum", m): "pass" for m in SIMS}
    html = (env.out / "report.html").read_text()
    assert "INTERRUPTED" in html and "not run" in html


def test_process_pool_with_a_fake_module(env, monkeypatch):
    # The pool path: workers are spawned, so the fake is named by PROGMO_CHECK_RUNNER.
    monkeypatch.setenv(parallel.RUNNER_ENV, "fake_checks:run_check")
    assert env(*TWO, plan={"double_pendulum/pinocchio": "raise"}, jobs="2") == 1
    st = statuses(env.out)
    assert st[("double_pendulum", "pinocchio")] == "error" and st[("heavy_top", "mujoco")] == "pass"
    # Results come back in task order whatever order they finished in.
    assert list(st) == [(s, m) for s in TWO for m in SIMS]


def test_a_dying_worker_is_an_error_of_its_check_only(env, monkeypatch):
    monkeypatch.setenv(parallel.RUNNER_ENV, "fake_checks:run_check")
    assert env(*TWO, plan={"heavy_top/mujoco": "die"}, jobs="2") == 1
    res = {(r["scene"], r["simulator"]): r for r in json.loads((env.out / "results.json").read_text())}
    assert res[("heavy_top", "mujoco")]["status"] == "error"
    assert "worker process running this check died" in res[("heavy_top", "mujoco")]["reason"]
    assert [r["status"] for k, r in res.items() if k != ("heavy_top", "mujoco")] == ["pass"] * (2 * N - 1)


@pytest.mark.timeout(300)
def test_a_dying_worker_never_hangs_the_run(env, monkeypatch):
    # A worker that dies just after reporting a result (os._exit with its last result still being
    # written) once left half a message in a shared multiprocessing.Queue: the parent's read then
    # waited forever, about one run in four. Five runs, each must end (pytest-timeout fails it).
    monkeypatch.setenv(parallel.RUNNER_ENV, "fake_checks:run_check")
    for _ in range(5):
        assert env(*TWO, plan={"heavy_top/mujoco": "die"}, jobs="2") == 1
        assert statuses(env.out)[("double_pendulum", SIMS[-1])] == "pass"


def test_rerun_command_is_exact_without_accept(env):
    assert env("--accept", "-s", "mujoco", "heavy_top") == 0
    cmd = json.loads((env.out / "run.json").read_text())["provenance"]["command"]
    first = [line for line in cmd.splitlines() if line.startswith("progmo check")][0]
    assert first == f"progmo check --out {env.out} --baselines {env.base} --jobs 1 --no-plots -s mujoco heavy_top"


def test_report_subcommand_rebuilds_the_report(env):
    assert env(*TWO, plan={"heavy_top/mujoco": "fail"}) == 1
    (env.out / "report.html").unlink()
    assert cli.main(["report", str(env.out)]) == 1
    assert "heavy_top" in (env.out / "report.html").read_text()


def test_debug_not_available(monkeypatch, capsys):
    real = cli.importlib.util.find_spec
    monkeypatch.setattr(cli.importlib.util, "find_spec", lambda n, *a: None if n == "progmo.debug" else real(n, *a))
    assert cli.main(["debug", "heavy_top"]) == 2
    assert "not available" in capsys.readouterr().err


def test_debug_forwards_its_arguments(monkeypatch):
    seen = []
    mod = types.ModuleType("progmo.debug")
    mod.__spec__ = importlib.machinery.ModuleSpec("progmo.debug", None)
    mod.main = lambda args: seen.append(args) or 3
    monkeypatch.setitem(sys.modules, "progmo.debug", mod)
    assert cli.main(["debug", "--help", "x.toml"]) == 3
    assert seen == [["--help", "x.toml"]]


def test_module_entry_point_and_help():
    for args in (["--help"], ["check", "--help"]):
        p = subprocess.run([sys.executable, "-m", "progmo.cli", *args], capture_output=True, text=True, timeout=60)
        assert p.returncode == 0, p.stderr
    assert "exit codes" in p.stdout and "--accept" in p.stdout and "--jobs" in p.stdout


def test_results_json_saved_incrementally_is_json_dumps_text(tmp_path):
    """The save after every check reuses each result's text: the file stays byte for byte what
    json.dump(indent=1) writes, for an empty, a one-element and a growing list (NaN as null)."""
    from progmo import results

    rs = [fake_checks.run_check(str(SCENES / f"{s}.toml"), m) for s in TWO for m in ("mujoco", "pinocchio")]
    rs[0].metrics["replay_residual"] = float("nan")
    encoded: dict[int, str] = {}
    for k in range(len(rs) + 1):
        a, b = tmp_path / f"a{k}.json", tmp_path / f"b{k}.json"
        results.save(rs[:k], str(a), encoded)
        b.write_text(json.dumps([r.to_json() for r in rs[:k]], indent=1) + "\n")
        assert a.read_bytes() == b.read_bytes(), k
    assert len(encoded) == len(rs)
