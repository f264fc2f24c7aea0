"""--history: each run leaves a record; the report draws trends and names the run a failure
started; a file that is not a record is named, not skipped silently; the grid marks a pass that
uses most of its budget."""

import json

import pytest

import fake_checks
from progmo import checks, cli, history, parallel
from progmo import report as rp


@pytest.fixture
def nightly(tmp_path, monkeypatch):
    monkeypatch.delenv(parallel.RUNNER_ENV, raising=False)
    monkeypatch.setattr(checks, "run_check", fake_checks.run_check)
    real = rp.provenance
    night = {"n": 0}

    def dated(root, command):  # one run per night, each with its own date
        p = real(root, command)
        p["date"] = f"2026-11-{10 + night['n']:02d} 02:00:00 UTC"
        p["git_revision"] = f"rev{night['n']:02d}"
        return p

    monkeypatch.setattr(rp, "provenance", dated)
    hist_dir, out = tmp_path / "history", tmp_path / "out"

    def run(plan):
        night["n"] += 1
        monkeypatch.setenv(fake_checks.PLAN_ENV, json.dumps(plan))
        return cli.main(["check", "--out", str(out), "--baselines", str(tmp_path / "b"), "--jobs", "1",
                         "--history", str(hist_dir), "double_pendulum", "heavy_top"])

    run.out, run.dir = out, hist_dir
    return run


def test_history_names_the_run_a_failure_started(nightly):
    assert nightly({}) == 0
    assert nightly({"heavy_top/mujoco": "fail"}) == 1
    assert nightly({"heavy_top/mujoco": "fail"}) == 1
    recs, problems = history.load(nightly.dir)
    assert len(recs) == 3 and not problems
    assert [r["cells"]["heavy_top/mujoco"]["verdict"] for r in recs] == ["pass", "fail", "fail"]
    assert history.streak_start(recs, "heavy_top/mujoco")["git_revision"] == "rev02"
    assert history.streak_start(recs, "double_pendulum/mujoco") is None
    html = (nightly.out / "report.html").read_text()
    assert "failing since the run of 2026-11-12 02:00:00 UTC (revision rev02)" in html
    assert "History: 3 run(s) from 2026-11-11" in html
    assert html.count("alt='heavy_top history'") == 1  # the trend plot of the scene
    # a recovered cell ends its streak
    assert nightly({}) == 0
    assert history.streak_start(history.load(nightly.dir)[0], "heavy_top/mujoco") is None
    # the history travels with run.json: `progmo report` re-renders it
    assert len(json.loads((nightly.out / "run.json").read_text())["history"]) == 4


def test_a_file_that_is_not_a_record_is_named(nightly):
    nightly.dir.mkdir(parents=True)
    (nightly.dir / "junk.json").write_text("{not json")
    assert nightly({}) == 0
    notes = json.loads((nightly.out / "run.json").read_text())["notes"]
    assert any("junk.json: skipped" in n for n in notes), notes


def test_grid_marks_a_pass_near_its_budget():
    r = fake_checks.make_result("close", "mujoco")
    b = r.budgets[0]
    r.metrics[b.metric] = 0.9 * b.value
    run = rp.Run(results=[r], simulators=["mujoco"], provenance={})
    html = rp.render_html(run)
    assert "<td class='c-warn'" in html
    r.metrics[b.metric] = 0.1 * b.value
    assert "<td class='c-pass'" in rp.render_html(run)
