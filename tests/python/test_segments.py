"""Full-span replays (checks._probe, checks._segments, the back-ends' replay(start, stop, x0)):
unstable programmes are judged over their whole span in segments that restart from the solver's
state; stable ones stay one segment. Negative controls: a 1 % error in u in the last quarter of the
span fails, on an unstable and on a stable scene.

The three unstable scenes take a few seconds each per simulator (whole span, Lyapunov probe)."""

import math
import pathlib

import numpy as np
import pytest

import progmo as ph
from progmo import checks
from progmo.checks import CheckOptions, Probe, _run, run_check
from progmo.results import CheckResult

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENES = ROOT / "references" / "scenes"
BOTH = ("mujoco", "pinocchio")
UNSTABLE = ("chain_8", "panda_circle", "planar_arm_line")


def scene(name):
    return str(SCENES / f"{name}.toml")


def _span(name):
    s = ph.Scene(scene(name))
    return s.t0, s.t1


@pytest.mark.parametrize("name", UNSTABLE)
@pytest.mark.parametrize("sim", BOTH)
def test_unstable_scenes_are_checked_over_their_whole_span(name, sim):
    """No part of the span goes unjudged: span == the scene's span, several segments (the probe
    finds the growth), each judged, and the continuous open-loop replay kept as information."""
    r = run_check(scene(name), sim)
    t0, t1 = _span(name)
    assert r.status == "pass", (r.reason, r.breaches)
    assert r.span == [t1 - t0, t1 - t0], r.span
    assert r.info["replay_segments"] >= 2
    assert r.info["segment_amplification"] <= checks.SEGMENT_GROWTH
    assert r.info["lyapunov_exponent"] > 3  # 1/s: exp(3 t) at least (measured 5.9 .. 12.4)
    # the open-loop replay grows as the linearized dynamics predict, within a factor 10 either way
    assert abs(r.info["open_loop_growth"] - r.info["lyapunov_growth"]) < math.log(10), r.info
    assert any(n.startswith("segmented replay:") for n in r.notes)
    dev = next(s for s in r.series if s.name == "replay_deviation")
    assert dev.t[0] == pytest.approx(t0) and dev.t[-1] == pytest.approx(t1)


def _last_quarter(name):
    t0, t1 = _span(name)
    start = t0 + 0.75 * (t1 - t0)
    return start, (lambda t, u: 1.01 * u if t >= start else u)


@pytest.mark.parametrize("name,sim", [("chain_8", "mujoco"), ("chain_8", "pinocchio"),
                                      ("double_pendulum", "mujoco"), ("double_pendulum", "pinocchio")])
def test_negative_control_one_percent_in_the_last_quarter_fails(name, sim):
    """u 1 % too large only in the last quarter of the span: the segment that covers it fails, first
    after the corruption starts (the run without it passes: the test above and test_checks.py)."""
    start, corrupt = _last_quarter(name)
    r, _ = _run(scene(name), sim, CheckOptions(), corrupt_u=corrupt)
    assert r.status == "fail", r.metrics
    bad = {b.metric: b for b in r.breaches}
    assert "replay_deviation" in bad and "replay_residual" in bad, r.breaches
    assert bad["replay_deviation"].first_time >= start - 1e-9
    t0, t1 = _span(name)
    assert r.span == [t1 - t0, t1 - t0]
    if name == "double_pendulum":  # stable: one segment, as before
        assert r.info["replay_segments"] == 1
    else:
        assert r.info["replay_segments"] >= 2 and "segment" in r.reason, r.reason


def test_one_percent_in_the_last_quarter_of_a_robot_file_scene_fails_before_the_replay():
    """On a robot-file scene (panda_circle) the same corruption is caught at the first sample of
    the last quarter by the file's own inverse dynamics, which gates the replay."""
    start, corrupt = _last_quarter("panda_circle")
    r, _ = _run(scene("panda_circle"), "pinocchio", CheckOptions(), corrupt_u=corrupt)
    assert r.status == "fail", r.metrics
    bad = {b.metric: b for b in r.breaches}
    assert "inverse_dynamics" in bad and bad["inverse_dynamics"].first_time >= start - 1e-9, r.breaches
    assert bad["inverse_dynamics"].value > 1e-3 and bad["inverse_dynamics"].where.startswith("joint "), r.breaches


def _prepared(name, sim, horizon=None):
    """A check up to its reference solve: scene, back-end, budgets, reference."""
    c = checks._Check(scene(name), sim, CheckOptions(horizon=horizon),
                      CheckResult(scene=name, simulator=sim, status="error"))
    for step in (checks._scene, checks._export, checks._budgets, checks._reference):
        step(c)
    return c


@pytest.mark.parametrize("sim", BOTH)
def test_a_segment_restarts_from_the_solvers_state(sim):
    """replay(ref, start=k, stop=k2) begins at the reference's (q, v) at step k, whatever happened
    before: moving the reference's state at k moves the segment's first sample, not the replay from 0."""
    c = _prepared("planar_arm_line", sim, horizon=0.5)
    ref, be = c.ref, c.backend
    k, k2 = 600, 1200
    whole = be.replay(ref)
    seg = be.replay(ref, 0, k, k2)
    assert len(seg.t) == k2 - k + 1 and seg.t[0] == ref.t[2 * k] and seg.t[-1] == ref.t[2 * k2]
    np.testing.assert_allclose(seg.q[0], ref.q[2 * k], rtol=0, atol=1e-15)
    np.testing.assert_allclose(seg.v[0], ref.v[2 * k], rtol=0, atol=1e-15)
    # the continuous replay has drifted from the solver by step k; the segment has not
    assert np.abs(whole.q[k] - ref.q[2 * k]).max() > 0
    ref.q = np.array(ref.q)  # a writable copy (the solver's arrays are read-only)
    ref.q[2 * k] += 1e-3
    moved = be.replay(ref, 0, k, k2)
    np.testing.assert_allclose(moved.q[0], ref.q[2 * k], rtol=0, atol=1e-15)
    assert np.array_equal(be.replay(ref).q[:k], whole.q[:k])  # the replay from 0 never reads it
    # x0 overrides the start (the Lyapunov probe)
    q0, v0 = ref.q[2 * k] + 1e-7, ref.v[2 * k] - 1e-7
    probe = be.replay(ref, 0, k, k2, x0=(q0, v0))
    np.testing.assert_allclose(probe.q[0], q0, rtol=0, atol=1e-15)
    # the default arguments are the whole span from the start
    assert np.array_equal(be.replay(ref, 0, 0, ref.steps).q, be.replay(ref).q)


def test_segments_follow_the_predicted_growth():
    """_segments on synthetic probes: a third of the limit's ln (and 1 %) per chunk cuts every 2
    chunks; a decaying or mildly growing span stays one segment; a chunk that blew up is alone; an
    unmeasured chunk (nan: the unperturbed run blew up) does not cut."""
    k = np.arange(0, 170, 10)
    t = k * 0.01

    def segs(inc):
        return checks._segments(Probe(k, t, np.asarray(inc, float)))

    lim = checks.SEGMENT_GROWTH
    per = 1.01 * math.log(lim) / 3  # three chunks pass the limit, two do not
    s, most = segs([per] * 16)
    n = 2
    assert all(b - a == 10 * n for a, b in s[:-1]) and s[0][0] == 0 and s[-1][1] == 160
    assert math.exp(most) <= lim * (1 + 1e-9)
    assert segs([-0.5] * 16)[0] == [(0, 160)]
    assert segs([0.9 * math.log(lim) / 16] * 16)[0] == [(0, 160)]
    up_down = [2.0, -2.0] * 8  # never more than e^2 from any earlier point
    assert segs(up_down)[0] == [(0, 160)]
    s, _ = segs([0.1] * 5 + [math.inf] + [0.1] * 10)
    assert (50, 60) in s
    assert segs([0.1] * 5 + [math.nan] + [0.1] * 10)[0] == [(0, 160)]


def test_replay_horizon_is_refused_with_its_location(tmp_path):
    """A scene that still sets [tolerances] replay_horizon is refused at load (the core's
    vocabulary, check::RETIRED), naming file and line."""
    text = (SCENES / "double_pendulum.toml").read_text()
    text = text.replace("[tolerances]\n", "[tolerances]\nreplay_horizon = { value = 1.0, reason = \"old\" }\n")
    p = tmp_path / "dp.toml"
    p.write_text(text)
    line = text.splitlines().index('replay_horizon = { value = 1.0, reason = "old" }') + 1
    r = run_check(str(p), "mujoco")
    assert r.status == "error" and not r.ok()
    assert f"{p}:{line}:" in r.reason and "tolerances.replay_horizon" in r.reason, r.reason
    assert "whole span" in r.reason, r.reason
