"""Tests of `progmo bench` (harness/progmo/bench): fast, smoke-sized; timings are never asserted."""

import csv

import numpy as np
import pytest

from progmo import Scene
from progmo.bench import common, conditioning, scipy_pipeline
from progmo.bench.main import main

pin = pytest.importorskip("pinocchio")


def test_bench_runs_end_to_end_and_every_output_names_its_rerun_command(tmp_path):
    out = tmp_path / "bench"
    assert main(["--smoke", "--out", str(out)]) == 0
    expected = ["workprecision.csv", "residual_double_pendulum.csv", "scipy.csv", "scipy_ratio.csv",
                "conditioning.csv", "scaling.csv", "workprecision_double_pendulum.png",
                "scipy_double_pendulum.png", "conditioning.png", "scaling.png", "index.html",
                "testset.csv", "testset_caraxis.png", "drift.csv"]
    for name in expected:
        assert (out / name).stat().st_size > 0, name
    rerun = f"progmo bench --smoke --out {out}"
    for name in expected:
        if name.endswith((".csv", ".html")):
            text = (out / name).read_text()
            assert rerun in text, name
            assert "versions: progmo" in text and " pin " in text, name
    # the work-precision CSV holds every formulation x integrator x tolerance, all successful,
    # and errors that fall as the tolerance tightens (dop853: 1e-5 -> 1e-8)
    rows = list(csv.DictReader(line for line in open(out / "workprecision.csv") if not line.startswith("#")))
    assert len(rows) == len(common.FORMULATIONS) * 3 * 2
    assert all(r["code"] == "success" for r in rows)
    for f in common.FORMULATIONS:
        e = {float(r["rtol"]): float(r["error"]) for r in rows if r["formulation"] == f and r["integrator"] == "dop853"}
        assert e[1e-8] < 1e-2 * e[1e-5], (f, e)
    html = (out / "index.html").read_text()
    assert "Omissions" in html and "conditioning.png" in html
    # the car axis against the published reference: digits at rtol 1e-6 (the Rust test measured
    # 4.57 for dop853 and 4.74 for radau5 with the same settings)
    ts = list(csv.DictReader(line for line in open(out / "testset.csv") if not line.startswith("#")))
    assert {r["method"] for r in ts} == {"dop853", "radau5"}
    for r in ts:
        assert r["code"] == "success" and 4.0 < float(r["mescd_all"]) < 6.0, r


def test_testset_mescd_is_the_test_sets_formula():
    from progmo.bench import testset

    ref = np.array([1.0, -2.0, 0.0])
    assert testset.mescd(ref + np.array([1e-6, 0.0, 0.0]), ref) == pytest.approx(-np.log10(0.5e-6), rel=1e-9)
    assert testset.mescd(ref + np.array([0.0, 0.0, 1e-4]), ref) == pytest.approx(4.0, rel=1e-9)


def test_unknown_part_is_an_error(tmp_path):
    assert main(["--smoke", "--out", str(tmp_path), "--only", "nonsense"]) == 2


def test_mpmath_reference_reproduces_a_known_2x2_kkt_solution():
    # A a - F = B^T lambda, B a = gamma with A = diag(2, 1), F = (1, 1), B = [1 1], gamma = 3:
    # 2 a1 - 1 = lambda = a2 - 1, a1 + a2 = 3  =>  a = (1, 2), lambda = 1, u = B^T lambda = (1, 1)
    a, lam, u = conditioning.kkt_reference(np.diag([2.0, 1.0]), [1.0, 1.0], [[1.0, 1.0]], [3.0], [0])
    np.testing.assert_allclose(a, [1.0, 2.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(lam, [1.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(u, [1.0, 1.0], rtol=0, atol=1e-15)
    # a row that is not a programme row contributes nothing to u
    _, _, u0 = conditioning.kkt_reference(np.diag([2.0, 1.0]), [1.0, 1.0], [[1.0, 1.0]], [3.0], [])
    assert np.all(u0 == 0.0)


def test_mpmath_reference_beats_f64_on_an_ill_conditioned_system():
    # A = diag(1, d) with d = 1e-12, B = [1 1], F = 0, gamma = 1: a = (d, 1)/(1 + d) exactly.
    d = 1e-12
    a, _, _ = conditioning.kkt_reference(np.diag([1.0, d]), [0.0, 0.0], [[1.0, 1.0]], [1.0], [0])
    np.testing.assert_allclose(a, [d / (1 + d), 1 / (1 + d)], rtol=1e-15)


def test_formulations_agree_with_the_extended_precision_reference_on_a_regular_scene(tmp_path):
    p = tmp_path / "c4.toml"
    p.write_text(common.chain_toml(4, name="c4"))
    scene = Scene(str(p))
    rows = conditioning.measure(scene, conditioning.sample_states(scene, 2))
    for r in rows:
        assert r["rel_err_a"] < 1e-12 and r["rel_err_u"] < 1e-12, r
    # negative control: a wrong reference (gamma sign flipped) is detected
    t, q, v = scene.t0, scene.q0, scene.v0
    d = scene.dynamics(t, q, v)
    a_bad, _, _ = conditioning.kkt_reference(d["mass"], d["velocity_terms"] + d["applied_forces"], d["B"], -d["gamma"], [0, 1])
    a = scene.accelerations(t, q, v, "null_space")["a"]
    assert np.abs(a - a_bad).max() > 1e-3 * np.abs(a).max()


@pytest.mark.parametrize("name", ["double_pendulum", "chain_8"])
def test_scipy_pipeline_accelerations_agree_with_progmo(name):
    scene = Scene(str(common.scene_path(name)))
    pipe = scipy_pipeline.pipeline_for(scene)
    rng = np.random.default_rng(1)
    for _ in range(3):
        t = float(rng.uniform(0, 2))
        q = scene.q0 + rng.uniform(-0.2, 0.2, len(scene.q0))
        v = rng.uniform(-1, 1, len(scene.v0))
        a_pin, u_pin = pipe.accelerations(t, q, v)
        r = scene.accelerations(t, q, v, "kkt")
        scale = max(1.0, np.abs(r["a"]).max())
        assert np.abs(a_pin - r["a"]).max() < 1e-10 * scale
        assert np.abs(u_pin - r["u"]).max() < 1e-10 * max(1.0, np.abs(r["u"]).max())
        # and the hand-written J, gamma equal the core's B, -gamma (Pinocchio's sign convention)
        J, g = pipe.constraints(t, q, v)
        d = scene.dynamics(t, q, v)
        np.testing.assert_allclose(J, d["B"], atol=1e-12)
        np.testing.assert_allclose(g, -d["gamma"], atol=1e-10)


def test_scipy_pipeline_check_fails_with_the_wrong_gamma_sign():
    # negative control: Pinocchio's J a + gamma = 0 fed with progmo's own gamma sign disagrees
    scene = Scene(str(common.scene_path("double_pendulum")))
    pipe = scipy_pipeline.pipeline_for(scene)
    t, q, v = 1.0, np.array([0.3, 0.2]), np.array([0.1, -0.4])
    d = scene.dynamics(t, q, v)
    a_wrong = pin.forwardDynamics(pipe.model, pipe.data, q, v, np.zeros(2), d["B"], d["gamma"])
    a = scene.accelerations(t, q, v, "kkt")["a"]
    assert np.abs(np.asarray(a_wrong) - a).max() > 1e-3


def test_time_at_error_interpolates_log_log_on_the_pareto_front():
    # time = error^-1/4 exactly on a line in log-log; a dominated point is ignored
    errs = [1e-2, 1e-4, 1e-6, 1e-5]
    times = [e ** -0.25 for e in errs[:3]] + [100.0]
    assert common.time_at_error(errs, times, 1e-3) == pytest.approx(1e-3 ** -0.25, rel=1e-12)
    assert np.isnan(common.time_at_error(errs, times, 1e-8))
    assert common.common_error_levels([(errs, times), ([1e-3, 1e-7], [1, 2])]) == [1e-6, 1e-5, 1e-4, 1e-3]
