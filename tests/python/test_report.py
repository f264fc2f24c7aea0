"""The tolerance report: content for a mix of verdicts, provenance and rerun command, HTML
escaping, self-containment, Markdown and CSV, and a render in a real headless Chromium."""

import csv
import pathlib
import re
import subprocess

import pytest

from browser import find_browser
from fake_checks import make_result
from progmo import baselines as bl
from progmo import report as rp

ROOT = pathlib.Path(__file__).resolve().parents[2]
EVIL = "<script>alert('x')</script>"


def mixed_run(plots=True) -> rp.Run:
    results = [
        make_result("calm", "mujoco"),
        make_result("calm", "pinocchio"),
        make_result("broken", "mujoco", "fail"),
        make_result("broken", "pinocchio", "declared"),
        make_result("drifting", "mujoco", "regress"),
        make_result(EVIL, "pinocchio", "error"),
    ]
    results[-1].reason = f"crashed near {EVIL} & friends"
    run = rp.Run(
        results=results,
        simulators=["mujoco", "pinocchio"],
        provenance=rp.provenance(ROOT, "progmo check --jobs 2 calm broken"),
        scenes={"calm": {"path": "references/scenes/calm.toml", "description": "a quiet scene"}},
        notes=["a note about <this> run"],
        plots=plots,
    )
    base = {"metrics": {"replay_residual": 3.3e-11, "replay_deviation": 1e-10, "parity_mass": 2e-15}}
    for r in results:
        run.comparisons[(r.scene, r.simulator)] = rp.comparisons_as_dicts(bl.compare(r, base))
    return run


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """The mixed run written once, with plots (0.5 s each): shared by the tests that need them."""
    d = tmp_path_factory.mktemp("report")
    return rp.write(mixed_run(), d)


def test_verdicts_and_failures_first():
    run = mixed_run(plots=False)
    assert run.verdict(run.result("drifting", "mujoco")) == "regression"
    assert run.verdict(run.result("drifting", "pinocchio")) == "not run"
    assert run.scene_names() == [EVIL, "broken", "drifting", "calm"]
    assert not run.ok()
    t = run.totals()
    assert (t["pass"], t["fail"], t["error"], t["declared"], t["regression"], t["not run"]) == (2, 1, 1, 1, 1, 2)


def test_html_content_escaping_and_self_containment(written):
    html = written["html"].read_text()
    assert "<table id='verdicts'>" in html and "id='attention'" in html
    for v in ("pass", "fail", "error", "declared", "regression", "not-run"):
        assert f"v-{v}" in html, v
    # Escaped, never raw.
    assert EVIL not in html and "&lt;script&gt;alert(&#x27;x&#x27;)&lt;/script&gt;" in html
    assert "a note about &lt;this&gt; run" in html and "&amp; friends" in html
    # Budget reasons and baselines are shown with the values.
    assert "RK4 at h = 1e-3 with per-stage u" in html and "regression above" in html
    # Failures first: the failing scene's section comes before the passing one.
    assert html.index("id='scene-broken'") < html.index("id='scene-calm'")
    # Plots are inline PNG; nothing is fetched from the network.
    assert html.count("data:image/png;base64,") == 4
    assert not re.search(r"""(src|href)\s*=\s*['"](https?:)?//""", html)
    assert "@import" not in html and "url(" not in html
    # Provenance footer and rerun command.
    foot = html[html.index("<footer id='provenance'>"):]
    assert "progmo check --jobs 2 calm broken" in foot
    for label in ("git revision", "progmo", "MuJoCo", "Pinocchio", "numpy", "Python", "host CPUs", "date"):
        assert f"<th>{label}</th>" in foot, label


def test_a_passing_run_says_pass():
    run = rp.Run([make_result("calm", "mujoco")], ["mujoco"], {"command": "progmo check calm"}, plots=False)
    assert run.ok() and "PASS: 1 of 1 (scene x simulator) passed" in rp.render_html(run)
    assert rp.render_markdown(run).startswith("# progmo check: PASS")


def test_markdown_and_csv(tmp_path):
    run = mixed_run(plots=False)
    paths = rp.write(run, tmp_path)
    md = paths["md"].read_text()
    assert md.startswith("# progmo check: FAIL")
    assert "| broken | ❌ fail | ⏭️ not checked (declared) |" in md and "progmo check --jobs 2 calm broken" in md
    assert "<script>alert('x')</script>" in md  # Markdown escaping is about | and newlines only
    rows = list(csv.DictReader(paths["csv"].open()))
    assert list(rows[0]) == rp.CSV_FIELDS
    by = {(r["scene"], r["simulator"], r["metric"]): r for r in rows}
    assert by[("broken", "mujoco", "replay_residual")]["within_budget"] == "false"
    assert by[("drifting", "mujoco", "replay_residual")]["vs_baseline"] == "regression"
    assert by[("broken", "pinocchio", "")]["reason"].startswith("the simulator cannot represent")
    assert by[("drifting", "pinocchio", "")]["verdict"] == "not run"


def test_plot_handles_zeros_nans_and_long_series():
    r = make_result("calm", "mujoco")
    r.series[0].values[:10] = [0.0] * 5 + [None] * 5
    r.series[0].t = list(r.series[0].t) * 10
    r.series[0].values = list(r.series[0].values) * 10  # 5010 points: downsampled
    assert rp.plot(r).startswith("data:image/png;base64,")
    r.series = []
    assert rp.plot(r) is None


_browser = find_browser


def test_report_renders_in_headless_chromium(tmp_path, written):
    browser = _browser()
    if browser is None:
        pytest.skip("SKIPPED: no Chromium and harness/install_chromium.sh could not install one; "
                    "the browser render of report.html was NOT checked")
    url = written["html"].resolve().as_uri()
    flags = ["--headless", "--disable-gpu", "--no-sandbox", "--hide-scrollbars", f"--user-data-dir={tmp_path / 'profile'}"]
    shot = tmp_path / "report.png"
    # One browser start for both the DOM and the screenshot.
    dom = subprocess.run([browser, *flags, "--dump-dom", f"--screenshot={shot}", "--window-size=1200,2000", url],
                         capture_output=True, text=True, timeout=60).stdout
    assert '<table id="verdicts">' in dom
    assert dom.count('<span class="v v-') > 10 and 'id="provenance"' in dom
    assert "progmo check --jobs 2 calm broken" in dom
    assert shot.is_file() and shot.stat().st_size > 30_000
    import numpy as np
    from PIL import Image

    px = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    assert px.shape == (2000, 1200, 3)
    packed = (px[..., 0] << 16) | (px[..., 1] << 8) | px[..., 2]
    assert len(np.unique(packed)) > 200, "screenshot is (nearly) blank"
    assert (np.abs(px - px[5, 5]).sum(axis=2) > 30).mean() > 0.05, "screenshot is mostly background"
    # The red FAIL banner and the green pass badges are painted.
    r, g, b = px[..., 0], px[..., 1], px[..., 2]
    assert ((r > 170) & (g < 80) & (b < 70)).sum() > 20_000  # #c0392b banner (~1100 x 45 px)
    assert ((g > 110) & (r < 60) & (b < 100)).sum() > 500  # #1e8449 pass badges


ARTIFACTS = ROOT / "out" / "test-artifacts"


def _blowup_run() -> rp.Run:
    from progmo.results import Breach

    r = make_result("exploding", "mujoco")
    r.status, r.span = "fail", [2.94, 10.0]
    r.breaches = [Breach("replay_blowup", 2.6e26, 1e10, 2.94)]
    r.reason = "mujoco replay: simulator blew up at t = 2.94: |qacc| = 2.6e+26 > 1e+10"
    return rp.Run(results=[r, make_result("exploding", "pinocchio")], simulators=["mujoco", "pinocchio"],
                  provenance=rp.provenance(ROOT, "progmo check exploding"))


def _history_run() -> rp.Run:
    from progmo import history

    run = mixed_run(plots=False)
    recs = []
    for night, kind in enumerate(["pass", "pass", "fail", "fail"]):
        past = rp.Run(results=[make_result("broken", "mujoco", kind)], simulators=["mujoco"],
                      provenance={"date": f"2026-11-{11 + night} 02:00:00 UTC", "git_revision": f"r{night}"})
        recs.append(history.record(past))
    run.history, run.plots = recs, True
    return run


@pytest.mark.parametrize("page", ["passing", "failing", "blowup", "history"])
def test_pages_render_in_headless_chromium_and_keep_screenshots(tmp_path, page):
    """Each kind of page a person reads, rendered by a real browser: DOM checks, and the screenshot
    kept as a test artifact in out/test-artifacts/report-<page>.png (what it shows: the banner,
    the coloured grid, and for failing pages the open sections of the failing scenes)."""
    browser = _browser()
    if browser is None:
        pytest.skip("SKIPPED: no Chromium and harness/install_chromium.sh could not install one; "
                    "the browser render of report.html was NOT checked")
    run = {
        "passing": lambda: rp.Run(results=[make_result("calm", "mujoco"), make_result("calm", "pinocchio")],
                                  simulators=["mujoco", "pinocchio"], provenance=rp.provenance(ROOT, "progmo check calm")),
        "failing": mixed_run,
        "blowup": _blowup_run,
        "history": _history_run,
    }[page]()
    paths = rp.write(run, tmp_path / page)
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    shot = ARTIFACTS / f"report-{page}.png"
    flags = ["--headless", "--disable-gpu", "--no-sandbox", "--hide-scrollbars", f"--user-data-dir={tmp_path / 'profile'}"]
    dom = subprocess.run([browser, *flags, "--dump-dom", f"--screenshot={shot}", "--window-size=1200,1400",
                          paths["html"].resolve().as_uri()], capture_output=True, text=True, timeout=60).stdout
    assert '<table id="verdicts">' in dom and shot.stat().st_size > 20_000
    details = re.findall(r'<details class="scene( attn)?"[^>]*?( open="")?>', dom)
    if page == "passing":
        assert 'class="banner b-ok"' in dom and "c-pass" in dom
        assert details and all(not attn and not is_open for attn, is_open in details)  # folded
    else:
        assert 'class="banner b-bad"' in dom and 'id="attention"' in dom
        assert any(attn and is_open for attn, is_open in details)  # failing scenes open
    if page == "blowup":
        assert "replay_blowup" in dom and "blew up at t = 2.94" in dom and "2.94 of 10 s" in dom
    if page == "history":
        assert "failing since the run of 2026-11-13 02:00:00 UTC (revision r2)" in dom
        assert "alt=\"broken history\"" in dom
