"""`progmo bench [--quick] [--out DIR] [--only workprecision,scipy,conditioning,scaling,anchor,robot,testset,servo,drift,executors,nightly,corpus]`

Speed against error: writes CSV, PNG and index.html to DIR (default out/bench) and prints the key
numbers. The `progmo` binary forwards `progmo bench ...` to `python -m progmo.bench.main ...`.

Run times measured on the shared 2-core x86-64 machine (2026-11-21):
  (full)   172 s wall (10 bundled scenes x 5 formulations (6 since issue 15) x 3 integrators x 9 tolerances, 5
           repeats; scipy sweeps of double_pendulum and chain_8; 15 conditioning scenes up to 128
           links; scaling n = 2 ... 128; the IVP Test Set car axis, 2 integrators x 9 tolerances;
           drift control over 10^4 periods, 7 alternating rounds)
  --quick  about 60 s (2 scenes, 4 tolerances, 3 repeats, chains up to 64 links)
  --smoke  about 10 s (the test's end-to-end run; its numbers mean nothing)
  2026-11-23: full 313 s with the C++ anchor (part `anchor`, bench/anchor.py), the machine shared.
The anchor is compiled on first use and cached: about 5 min of CPU (4-13 min wall on the shared
2-core machine) for g++ on Pinocchio's headers; the part then takes about 20 s in a full run (7
chains, 7 rounds of 5 loops), 7 s with --quick.
  2026-11-24: `--only robot` (bench/robot.py: the Panda of panda_circle beside Pinocchio, issue 13
  item 6) 9 s wall (7 timing rounds, 9 agreement states, 5 whole solves per side); it reuses the
  anchor's binary (built on first use as above).
  Part `nightly` (bench/nightly.py) runs `progmo check` of the whole catalog once (minutes; one
  scene with --smoke) for issue 31's nightly target.
  Part `corpus` runs `progmo corpus` (import and parity of the public robot collections, issue 30)
  on the installed collections and `--corpus-data DIR`: every file in a full run (about 10 s),
  10 per collection with --quick, 2 with --smoke (the targets are then not measured).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable

import argparse
import html as _html
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import cliutil

if TYPE_CHECKING:
    from .common import Provenance
    from .targets import Target

PARTS = ("workprecision", "scipy", "conditioning", "scaling", "anchor", "robot", "testset", "servo", "drift",
         "executors", "nightly", "corpus")

# sweep sizes; --quick is the default a test or a shared 2-core machine can afford
QUICK: dict[str, Any] = dict(servo_tols=[1e-6, 1e-8, 1e-10], scenes=("double_pendulum", "chain_8"), tols=[1e-4, 1e-6, 1e-8, 1e-10], repeats=3,
             scipy_tols=[1e-4, 1e-6, 1e-8, 1e-10], radau_min_tol=1e-8, states=3,
             testset_tols=[1e-4, 1e-6, 1e-8, 1e-10], drift_rounds=3, anchor_rounds=3, anchor_budget=0.02,
             robot=dict(rounds=3, budget_s=0.02, check_states=5, solve_repeats=3, load_repeats=10), corpus_sample=10)
# full: every bundled scene in the work-precision sweep (scipy only where a hand-written pipeline exists)
FULL: dict[str, Any] = dict(servo_tols=[10.0 ** -k for k in range(4, 12)], scenes=("double_pendulum", "chain_8", "example_2_1", "example_2_1_through_rd0", "example_3_1_free",
                    "heavy_top", "planar_arm_line", "knife_edge", "appell_hamel", "slider_crank"),
            tols=[10.0 ** -k for k in range(4, 13)], repeats=5,
            scipy_tols=[10.0 ** -k for k in range(4, 13)], radau_min_tol=1e-10, states=5,
            testset_tols=[10.0 ** -k for k in range(4, 13)], drift_rounds=7, anchor_rounds=7, anchor_budget=0.05,
            robot=dict(rounds=7, budget_s=0.05, check_states=9, solve_repeats=5, load_repeats=20))
# --smoke: the smallest end-to-end run (tests): one scene, two tolerances, two chain lengths
SMOKE: dict[str, Any] = dict(servo_tols=[1e-6], scenes=("double_pendulum",), tols=[1e-5, 1e-8], repeats=1, scipy_tols=[1e-5, 1e-8],
             radau_min_tol=1e-8, states=2, scaling_ns=[2, 7], conditioning="smoke", testset_tols=[1e-6], drift_rounds=1,
             anchor_ns=[2, 7], anchor_rounds=1, anchor_budget=0.002, sweep_samples=2, nightly_scenes=["double_pendulum"], corpus_sample=2,
             robot=dict(rounds=1, budget_s=0.002, check_states=3, solve_repeats=1, load_repeats=2))


def parser() -> argparse.ArgumentParser:
    p = cliutil.parser("progmo bench", description=__doc__ or "")
    p.add_argument("--quick", action="store_true", help="small sweeps (default: full sweeps)")
    p.add_argument("--out", default="out/bench", help="output directory (default out/bench)")
    p.add_argument("--only", default=",".join(PARTS),
                   help=f"comma-separated parts to run (default all: {','.join(PARTS)})")
    p.add_argument("--smoke", action="store_true",
                   help="smallest end-to-end run (for tests; numbers not meaningful)")
    p.add_argument("--accept", action="store_true",
                   help="record this run's small-problem figures (anchor part, n = 2 and 4) as the accepted "
                        "ones (bench/accepted.json) that later runs are judged against")
    p.add_argument("--corpus-data", default=None, metavar="DIR",
                   help="corpus part: folder of unzipped collections, as `progmo corpus --data`")
    p.add_argument("--scenes", default=None,
                   help="comma-separated bundled scene names for workprecision/scipy "
                        "(default double_pendulum,chain_8)")
    return p


# the page's standing omissions (a run adds the skipped parts' reasons)
_OMISSIONS = (
    "No closed-form references: the scenes' free coordinates obey nonlinear ODEs; references are "
    "tight runs of a different integrator (their mutual difference is the floor shown).",
    "Work-precision covers the bundled double_pendulum and chain_8 by default; other bundled scenes "
    "(ball/free joints, lagrangian scenes, velocity/acceleration rows) have no hand-written scipy "
    "pipeline and are not swept.",
    "The scipy pipeline has no drift control (position rows held at acceleration level only); "
    "progmo runs use the scene's drift control (projection); the scipy section adds progmo dop853 "
    "with drift control off for a like-for-like ratio.",
    "progmo RHS timings are wall-clock loops in Rust (GIL released); Pinocchio's are Python loops "
    "including the call overhead (reported, not subtracted). Both on a shared 2-core machine: "
    "best of a few repeats.",
    "The conditioning study isolates the formulations' round-off on identical f64 A, F, B, gamma; "
    "errors in forming A, F, B, gamma are not measured.",
    "rk4 (fixed step) is not part of the sweep.",
    "The hard-case suite (singular programmes, dead points, redundant rows, stiffness, chaos, "
    "inconsistent starts) is a test suite, not a benchmark: `cargo test --release --test integration hard_cases:: "
    "-- --nocapture` prints its tables; expected behaviour and measured values are in "
    "references/hard/README.md.",
)


@dataclass
class _Bench:
    """What the parts of one `progmo bench` run share: the options, where to write, and what the
    page and stdout collect (each part appends to these)."""

    ns: argparse.Namespace
    cfg: dict[str, Any]
    out: Path
    prov: Provenance
    sections: list[tuple[str, str]] = field(default_factory=list)
    omissions: list[str] = field(default_factory=lambda: list(_OMISSIONS))
    summary: list[str] = field(default_factory=list)
    targets: list[Target] = field(default_factory=list)  # the targets, met or missed, with the measured numbers
    failed: list[str] = field(default_factory=list)  # parts that failed (exit code 1)
    scenes: list[Any] = field(default_factory=list)  # the workprecision / scipy scenes
    wp: dict[str, Any] = field(default_factory=dict)  # the workprecision part's results, by scene
    anchor_rows: list[dict] | None = None
    anchor_why: str = "the anchor part did not run (--only)"
    ts: dict | None = None
    testset_why: str = "the testset part did not run (--only)"
    robot_rhs: dict | None = None
    robot_humanoid: dict | None = None
    robot_why: str = "the robot part did not run (--only)"
    servo: dict | None = None
    servo_why: str = "the servo part did not run (--only)"
    nightly: dict | None = None
    nightly_why: str = "the nightly part did not run (--only)"
    corpus: list[dict] | None = None
    corpus_why: str = "the corpus part did not run (--only)"


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    ns = parser().parse_args(argv)
    only = [x.strip() for x in ns.only.split(",") if x.strip()]
    bad = [x for x in only if x not in PARTS]
    if bad:
        print(f"progmo bench: unknown part(s) {bad}; choose from {PARTS}", file=sys.stderr)
        return 2
    cfg = dict(SMOKE if ns.smoke else QUICK if ns.quick else FULL)
    if ns.scenes:
        cfg["scenes"] = tuple(s.strip() for s in ns.scenes.split(",") if s.strip())
    out = Path(ns.out)
    out.mkdir(parents=True, exist_ok=True)

    # the parts' modules are loaded here, before the clock starts
    from .. import Scene
    from . import anchor, conditioning, page, robot, scaling, scipy_pipeline, targets as tg, testset, workprecision  # noqa: F401
    from .common import Provenance, scene_path

    b = _Bench(ns, cfg, out, Provenance(argv))
    t_start = time.perf_counter()
    if "workprecision" in only or "scipy" in only:
        b.scenes = [Scene(str(scene_path(n))) for n in cfg["scenes"]]
    for part in PARTS:
        if part in only:
            _PART_RUNS[part](b)
    return _finish(b, t_start)


def _part_workprecision(b: _Bench) -> None:
    """Part `workprecision`: progmo's error against CPU time over formulations, integrators, tolerances."""
    from . import page, workprecision
    from .common import count_zeros

    b.wp = workprecision.run(b.scenes, b.cfg["tols"], b.out, b.prov, repeats=b.cfg["repeats"])
    inner = ("<p>Final-state error max|(q, v)(t1) - ref| against a tight run of a different integrator "
             "(radau5 runs vs dop853 at 1e-14; dop853/dopri5 runs vs radau5 at 1e-14) against median CPU "
             "time of <code>scene.solve</code> (output at t0 and t1 only) and RHS evaluations; atol = rtol. "
             "Right panel: programme residual of one run. Data: <a href='workprecision.csv'>workprecision.csv</a>.</p>")
    for name, res in list(b.wp.items()):
        if "skipped" in res:
            b.omissions.append(f"work-precision skipped: {res['skipped']}")
            del b.wp[name]
            continue
        ref = res["reference"]
        info = res["residual"][2]
        zeros = count_zeros(r["error"] for r in res["rows"] if np.isfinite(r["error"])) + count_zeros(res["residual"][1])
        inner += (f"<h3>{name}</h3><p>Reference floor |dop853 ref - radau5 ref| = {ref.floor:.1e} "
                  f"(tolerances {page.prose(ref.tol)}). Residual run (right panel): {page.prose(info)}. The plotted "
                  f"residual is sampled at the scene's output_dt (dense output, projected like the step ends when "
                  f"drift control is projection); the reported maximum is {info['max_residual']:.1e}.</p>"
                  + page.img(f"workprecision_{name}.png") + page.zero_note(zeros))
        good = [r for r in res["rows"] if np.isfinite(r["error"]) and r["error"] < 1e-8]
        best = min(good, key=lambda r: r["cpu_s"], default=None)
        if best is not None:
            b.summary.append(f"workprecision {name}: cheapest run with error < 1e-8: {best['integrator']} "
                             f"{best['formulation']} rtol {best['rtol']:.0e}: error {best['error']:.1e} "
                             f"in {best['cpu_s'] * 1e3:.2f} ms CPU (reference floor {ref.floor:.1e})")
    b.sections.append(("1. Work-precision of progmo", inner))


def _part_scipy(b: _Bench) -> None:
    """Part `scipy`: what a user would pick instead (scipy solve_ivp + Pinocchio), CPU ratios at equal error."""
    from . import page, scipy_pipeline
    from .common import write_csv

    inner = (page.doc(scipy_pipeline.__doc__)
             + "<p>CPU(scipy) / CPU(progmo) at equal error: each method's (error, CPU time) points reduced to "
             "their Pareto front and interpolated in log-log at decades both fronts cover.</p>")
    ratio_rows_all: list[dict] = []
    scipy_rows_all: list[dict] = []
    for scene in b.scenes:
        done = _scipy_scene(b, scene)
        if done is None:
            continue
        html, srows, rrows = done
        inner += html
        scipy_rows_all += srows
        ratio_rows_all += rrows
    hdr = ["scene", "method", "rtol", "atol", "code", "error", "cpu_s", "rhs_evals", "jacobian_evals", "lu", "reference"]
    write_csv(b.out / "scipy.csv", b.prov, hdr, ([r[h] for h in hdr] for r in scipy_rows_all))
    hdr = ["scene", "comparison", "error", "cpu_scipy", "cpu_progmo", "ratio"]
    write_csv(b.out / "scipy_ratio.csv", b.prov, hdr, ([r[h] for h in hdr] for r in ratio_rows_all))
    inner += "<p>Data: <a href='scipy.csv'>scipy.csv</a>, <a href='scipy_ratio.csv'>scipy_ratio.csv</a>.</p>"
    b.sections.append(("2. What a user would pick instead: scipy solve_ivp + Pinocchio", inner))


def _scipy_scene(b: _Bench, scene: Any) -> tuple[str, list[dict], list[dict]] | None:
    """The scipy part on one scene: its HTML, scipy rows and ratio rows (None when skipped, the
    reason in the omissions); the key numbers and the target into `b`."""
    from . import page, scipy_pipeline, workprecision
    from .common import count_zeros, log

    name = scene.name
    try:
        scipy_pipeline.pipeline_for(scene)
    except NotImplementedError as e:
        b.omissions.append(f"scipy comparison skipped: {e}")
        return None
    if name in b.wp:
        ref, prog_rows = b.wp[name]["reference"], b.wp[name]["rows"]
    else:
        log(f"[scipy] {name}: progmo references and null_space sweep")
        try:
            ref = workprecision.reference(scene)
        except RuntimeError as e:
            b.omissions.append(f"scipy comparison skipped: {e}")
            return None
        prog_rows = workprecision.sweep(scene, ref, b.cfg["tols"], formulations=("null_space",),
                                        repeats=b.cfg["repeats"])
    log(f"[scipy] {name}: solve_ivp sweep")
    srows = scipy_pipeline.sweep(scene, ref, b.cfg["scipy_tols"], repeats=b.cfg["repeats"],
                                 radau_min_tol=b.cfg["radau_min_tol"])
    log(f"[scipy] {name}: progmo dop853 without drift control (the scipy pipeline has none)")
    nodrift = workprecision.sweep(scene, ref, b.cfg["tols"], formulations=("null_space",),
                                  integrators=("dop853",), repeats=b.cfg["repeats"], drift="none")
    rrows = scipy_pipeline.ratios(name, prog_rows, srows, nodrift)
    agree = scipy_pipeline.agreement(scene, ref)
    scipy_pipeline.plot(name, prog_rows, srows, rrows, ref, b.out, b.prov, nodrift)
    html = (f"<h3>{name}</h3><p>Independent agreement: scipy DOP853 + Pinocchio at rtol = atol = 1e-12 vs "
            f"progmo's dop853 reference: max |d(q, v)| = {agree:.1e}.</p>"
            + page.table(["comparison", "error", "CPU scipy (s)", "CPU progmo (s)", "ratio"],
                         [[r["comparison"], f"{r['error']:.0e}", page.num(r["cpu_scipy"]),
                           page.num(r["cpu_progmo"]), page.num(r["ratio"], "{:.1f}")] for r in rrows])
            + page.img(f"scipy_{name}.png")
            + page.zero_note(count_zeros(r["error"] for r in [*prog_rows, *srows, *nodrift]
                                         if np.isfinite(r["error"]))))
    _scipy_numbers(b, name, rrows, agree)
    return html, srows, rrows


def _scipy_numbers(b: _Bench, name: str, rrows: list[dict], agree: float) -> None:
    """The scipy part's key numbers and its 100x target for one scene."""
    from . import targets as tg

    for label, key in (("CPU(best scipy+Pinocchio)/CPU(best progmo)", "best"),
                       ("CPU(scipy DOP853)/CPU(progmo dop853, drift control off too)", "scipy DOP853 / progmo dop853 null_space drift")):
        sel = [r for r in rrows if r["comparison"].startswith(key)]
        b.summary.append(f"scipy {name}: {label} = "
                         + (", ".join(f"{r['ratio']:.1f}x at {r['error']:.0e}" for r in sel) or "n/a (no common error range)"))
    b.summary.append(f"scipy {name}: scipy DOP853 + Pinocchio at 1e-12 vs progmo's dop853 reference: {agree:.1e}")
    best = [r["ratio"] for r in rrows if r["comparison"].startswith("best")]
    if best:
        lo, hi = min(best), max(best)
        far = f"{100 / hi:.0f}" if round(100 / hi) == round(100 / lo) else f"{100 / hi:.0f}-{100 / lo:.0f}"
        verdict = "met" if lo >= 100 else f"MISSED by {far}x"
        b.targets.append(tg.Target(f"whole solve >= 100x faster than scipy + Pinocchio at equal error, {name}",
                                   f"{lo:.1f}x" if f"{lo:.1f}" == f"{hi:.1f}" else f"{lo:.1f}-{hi:.1f}x",
                                   verdict))


def _part_conditioning(b: _Bench) -> None:
    """Part `conditioning`: the formulations' round-off on identical A, F, B, gamma (the paper's claim)."""
    from . import conditioning, page
    from .common import count_zeros

    rows = conditioning.run(b.out, b.prov, quick=b.ns.quick, states=b.cfg["states"],
                            smoke=b.cfg.get("conditioning") == "smoke")
    table_rows = []
    scenes_c = list(dict.fromkeys(r["scene"] for r in rows))
    for sc in scenes_c:
        rs = {r["formulation"]: r for r in rows if r["scene"] == sc}
        any_r = next(iter(rs.values()))
        table_rows.append([any_r["family"], sc, any_r["n"], f"{any_r['cond_A']:.1e}"]
                          + [f"{page.num(rs[f]['rel_err_a'], '{:.1e}')} / {page.num(rs[f]['rel_err_u'], '{:.1e}')}"
                             for f in conditioning.FORMULATIONS])
    hdr = ["family", "scene", "n", "cond(A)"] + [f"{f}: dv/dt / u" for f in conditioning.FORMULATIONS]
    inner = (page.doc(conditioning.__doc__)
             + page.table(hdr, table_rows) + page.img("conditioning.png")
             + page.zero_note(count_zeros(r[k] for r in rows for k in ("rel_err_a", "rel_err_u")))
             + "<p>Data: <a href='conditioning.csv'>conditioning.csv</a>.</p>")
    b.sections.append(("3. The paper's claim: avoiding A^-1 reduces error?", inner))
    b.summary.append("conditioning (relative error dv/dt / u, max over states):")
    b.summary.append("  " + " | ".join(["cond(A)".rjust(8), "scene".ljust(22)] + [f.ljust(19) for f in conditioning.FORMULATIONS]))
    for r in table_rows:
        b.summary.append("  " + " | ".join([r[3].rjust(8), r[1].ljust(22)] + [c.ljust(19) for c in r[4:]]))


def _part_scaling(b: _Bench) -> None:
    """Part `scaling`: one RHS against chain length, progmo beside Pinocchio through the Python binding."""
    from . import page, scaling, targets as tg

    sc = scaling.run(b.out, b.prov, quick=b.ns.quick or b.ns.smoke, ns=b.cfg.get("scaling_ns"))
    rows = sc["rows"]
    trs = [[r["n"], f"{r['progmo_null_space_s'] * 1e6:.2f}", f"{r['progmo_kkt_s'] * 1e6:.2f}",
            f"{r['progmo_articulated_body_s'] * 1e6:.2f}", f"{r['pin_fd_only_s'] * 1e6:.2f}", f"{r['pin_fd_u_s'] * 1e6:.2f}", f"{r['pin_pipeline_s'] * 1e6:.2f}",
            f"{r['progmo_null_space_s'] / r['pin_fd_u_s']:.2f}", f"{r['max_abs_da']:.1e}"] for r in rows]
    hdr = ["n", "progmo null_space (us)", "progmo kkt (us)", "progmo articulated_body (us)", "pin.forwardDynamics (us)",
           "pin fd + u (us)", "user pipeline (us)", "progmo null_space / pin fd+u", "max|da| pin vs progmo"]
    inner = (page.doc(scaling.__doc__)
             + f"<p>Python loop + call overhead (no-op Python function, 7 arguments): "
             f"{sc['python_overhead_s'] * 1e6:.3f} us per call; it excludes the binding's own argument "
             "conversion (simulators.md: 0.1-0.3 us).</p>"
             + page.table(hdr, trs) + page.img("scaling.png") + "<p>Data: <a href='scaling.csv'>scaling.csv</a>.</p>")
    b.sections.append(("4. Scaling: one RHS vs chain length", inner))
    for n in scaling.MARK:
        at_n = scaling.at(rows, n)
        if at_n:
            ratio = at_n["progmo_null_space_s"] / at_n["pin_fd_u_s"]
            b.targets.append(tg.Target(f"one RHS <= Pinocchio forwardDynamics (+u) through the Python binding at n = {n}",
                                       f"progmo null_space / pin = {ratio:.2f}",
                                       "met" if ratio <= 1 else f"MISSED by {ratio:.2f}x"))
            b.summary.append(f"scaling n = {n}: progmo null_space {at_n['progmo_null_space_s'] * 1e6:.1f} us, kkt "
                             f"{at_n['progmo_kkt_s'] * 1e6:.1f} us; pin.forwardDynamics + u "
                             f"{at_n['pin_fd_u_s'] * 1e6:.1f} us (Python loop); ratio progmo/pin = {ratio:.2f}")
    b.summary.append(f"scaling: Python call overhead {sc['python_overhead_s'] * 1e6:.3f} us per call (not subtracted)")


def _part_anchor(b: _Bench) -> None:
    """Part `anchor`: Pinocchio's C++ on the same chains and rows (skipped when it cannot be built)."""
    from . import anchor

    title = "4b. The C++ anchor: Pinocchio's C++ on the same chains and rows"
    try:
        an = anchor.run(b.out, b.prov, ns=b.cfg.get("anchor_ns", anchor.NS), rounds=b.cfg["anchor_rounds"],
                        budget_s=b.cfg["anchor_budget"])
    except anchor.Unavailable as e:
        b.anchor_why = f"C++ anchor skipped: {e}"
        b.omissions.append(b.anchor_why)
        b.sections.append((title, f"<p><b>SKIPPED</b>: {_html.escape(str(e))}</p>"))
        b.summary.append(f"anchor: SKIPPED: {e}")
    except (anchor.AnchorFailed, NotImplementedError) as e:
        b.anchor_why = "the C++ anchor FAILED (section 4b)"
        b.failed.append(f"anchor: {e}")
        b.sections.append((title, f"<p><b>FAILED</b>:</p><pre>{_html.escape(str(e))}</pre>"))
        b.summary.append(f"anchor: FAILED: {e}")
    else:
        b.anchor_rows = an["rows"]
        _anchor_section(b, title, an)
        if b.ns.accept:
            _accept(b, an["rows"])


def _anchor_section(b: _Bench, title: str, an: dict) -> None:
    """The anchor part's section (tables, build) and key numbers from its results `an`."""
    from . import anchor, page

    anchor_rows = an["rows"]
    bd = an["build"]
    us = lambda x: f"{x * 1e6:.2f}"  # noqa: E731
    trs = [[r["n"], us(r["aba_s"]), us(r["kkt_s"]), f"{us(r['same_best_s'])} ({r['same_best']})",
            us(r["progmo_null_space_s"]), us(r["progmo_kkt_s"]), us(r["progmo_articulated_body_s"]),
            us(r["progmo_auto_s"]), f"{r['ratio_null_space']:.2f}", f"{r['ratio_articulated_body']:.2f}",
            f"{r['ratio_auto']:.2f}", f"{r['ratio_auto_kkt']:.2f}",
            f"{r['agreement']:.1e} ({r['agreement_tol']:.0e})"] for r in anchor_rows]
    hdr = ["n", "C++ ABA (us)", "C++ KKT forwardDynamics, J and gamma given (us)",
           "C++ same work, best (us)", "progmo null_space (us)", "progmo kkt (us)",
           "progmo articulated_body (us)", "progmo auto, the default (us)",
           "progmo null_space / C++ same work", "progmo articulated_body / C++ same work",
           "progmo auto / C++ same work", "progmo auto / C++ KKT", "max rel. disagreement (tolerance)"]
    vrs = [[r["n"]] + [us(r[f"{v}_s"]) for v in anchor.SAME] for r in anchor_rows]
    inner = (page.doc(anchor.__doc__) + page.table(hdr, trs)
             + "<p>Every same-work variant (us per call):</p>" + page.table(["n", *anchor.SAME], vrs)
             + f"<p>Build ({'cached' if bd['cached'] else 'built in this run'}): <code>{_html.escape(bd['command'])}</code>; "
             f"{_html.escape(bd['compiler'])}, Pinocchio {bd['pin']}, Eigen {bd['eigen']}.</p>"
             "<p>Data: <a href='anchor.csv'>anchor.csv</a>.</p>")
    b.sections.append((title, inner))
    for r in anchor_rows:
        b.summary.append(f"anchor n = {r['n']}: C++ ABA {us(r['aba_s'])} us, KKT (J, gamma given) {us(r['kkt_s'])} us, "
                         f"same work {us(r['same_best_s'])} us ({r['same_best']}); progmo null_space "
                         f"{us(r['progmo_null_space_s'])} us, kkt {us(r['progmo_kkt_s'])} us, articulated_body "
                         f"{us(r['progmo_articulated_body_s'])} us, auto {us(r['progmo_auto_s'])} us; progmo/C++ "
                         f"same work {r['ratio_null_space']:.2f} (null_space), {r['ratio_kkt']:.2f} (kkt), "
                         f"{r['ratio_articulated_body']:.2f} (articulated_body), {r['ratio_auto']:.2f} (auto)")


def _accept(b: _Bench, anchor_rows: list[dict]) -> None:
    """`--accept`: record this run's small-problem figures as the accepted ones (bench/accepted.json)."""
    import json as _json

    from . import targets as tg

    rec = tg.accepted_record(anchor_rows, dict(command=b.prov.command, date=time.strftime("%Y-%m-%d"),
                                               commit=b.prov.versions.get("commit", "unknown"),
                                               machine=b.prov.versions.get("machine", "unknown")))
    tg.ACCEPTED.write_text(_json.dumps(rec, indent=1) + "\n")
    b.summary.append(f"anchor: accepted the small-problem figures into {tg.ACCEPTED}")


def _part_robot(b: _Bench) -> None:
    """Part `robot`: the Panda beside Pinocchio on the same URDF (RHS, whole solve, load)."""
    from . import anchor, page, robot

    title = f"4c. A real robot: the Panda ({robot.SCENE}) beside Pinocchio on the same URDF"
    try:
        rb = robot.run(b.out, b.prov, **b.cfg["robot"])
    except (anchor.AnchorFailed, NotImplementedError, FileNotFoundError) as e:
        b.failed.append(f"robot: {e}")
        b.robot_why = f"the robot part failed: {e}"
        b.sections.append((title, f"<p><b>FAILED</b>:</p><pre>{_html.escape(str(e))}</pre>"))
        b.summary.append(f"robot: FAILED: {e}")
    else:
        inner, lines = _robot_section(rb, page, anchor)
        b.sections.append((title, page.doc(robot.__doc__) + inner))
        b.summary += lines
        b.robot_rhs = rb["rhs"]
        b.robot_humanoid = rb.get("humanoid")
        if "rhs_skipped" in rb:
            b.omissions.append(f"robot: the C++ RHS comparison skipped: {rb['rhs_skipped']}")
            b.robot_why = f"the C++ RHS comparison skipped: {rb['rhs_skipped']}"
    b.omissions.append("robot: the whole solve is compared with scipy + Pinocchio's Python binding; the C++ anchor "
                       "has no integrator, so there is no C++ whole solve (its per-RHS time x progmo's RHS count is "
                       "shown as the RHS share one would pay).")


def _part_testset(b: _Bench) -> None:
    """Part `testset`: the IVP Test Set's car axis, digits against CPU time."""
    from . import page, testset

    try:
        b.ts = testset.run(b.out, b.prov, b.cfg["testset_tols"], b.cfg["repeats"])
    except (FileNotFoundError, ValueError) as e:
        b.omissions.append(f"IVP Test Set skipped: {e}")
        b.testset_why = f"IVP Test Set skipped: {e}"
        b.ts = None
    if b.ts is not None:
        trs = [[r["method"], f"{r['rtol']:.0e}", r["code"], f"{r['mescd_states']:.2f}", f"{r['mescd_all']:.2f}",
                page.num(r["cpu_s"]), r["rhs_evals"], r["steps"], r["rejected"]] for r in b.ts["rows"]]
        hdr = ["method", "rtol = atol", "code", "mescd y(1:8)", "mescd y(1:10)", "CPU (s)", "RHS", "steps", "rejected"]
        inner = (page.doc(testset.__doc__) + page.table(hdr, trs) + page.img("testset_caraxis.png")
                 + "<p>Data: <a href='testset.csv'>testset.csv</a>.</p>")
        b.sections.append(("5. IVP Test Set: car axis digits against CPU time", inner))
        for r in b.ts["rows"]:
            b.summary.append(f"testset caraxis {r['method']} rtol {r['rtol']:.0e}: mescd {r['mescd_all']:.2f} "
                             f"(states {r['mescd_states']:.2f}) in {r['cpu_s'] * 1e3:.1f} ms CPU, {r['rhs_evals']} RHS")


def _part_servo(b: _Bench) -> None:
    """Part `servo`: the overhead crane, servo against ideal realization (a failure is reported, the rest stands)."""
    from . import page, servo as sv

    try:
        res = sv.run(b.out, b.prov, b.cfg["servo_tols"], b.cfg["repeats"])
        b.servo = res
        trs = [[r["realization"], f"{r['rtol']:.0e}", r["code"], f"{r['error']:.1e}", page.num(r["cpu_s"]),
                r["rhs_evals"], r["steps"], f"{r['us_per_rhs']:.0f}"] for r in res["rows"]]
        hdr = ["realization", "rtol = atol", "code", "max |q - q_ref|", "CPU (s)", "RHS", "steps", "us per RHS"]
        lines = sv.lines(res)
        b.summary += lines
        b.sections.append(("5b. Servo-constraints: the overhead crane, servo against ideal realization",
                           page.doc(sv.__doc__) + page.table(hdr, trs) + page.img("servo_crane.png")
                           + "<p>" + "<br>".join(lines) + "</p><p>Data: <a href='servo.csv'>servo.csv</a>.</p>"))
    except Exception as e:  # noqa: BLE001 - a part that fails is reported, the rest stands
        b.failed.append(f"servo: {e}")
        b.servo_why = f"the servo part failed: {e}"
        b.sections.append(("5b. Servo-constraints", f"<p>FAILED: {e}</p>"))


def _part_drift(b: _Bench) -> None:
    """Part `drift`: the cost of drift control (projection) over 10^4 periods, and its target."""
    from .._core import drift_cost
    from . import targets as tg
    from .common import log, write_csv

    log(f"[drift] 10^4 periods, projection on/off, {b.cfg['drift_rounds']} alternating rounds")
    d = drift_cost(b.cfg["drift_rounds"])
    extra = d["projection_s"] / d["none_s"] - 1.0
    line = (f"drift 10^4 periods ({d['steps']} steps): projection {d['projection_s'] * 1e3:.0f} ms vs none "
            f"{d['none_s'] * 1e3:.0f} ms = {extra * 100:+.1f} % CPU; max residual {d['residual_projection']:.1e} "
            f"with projection, {d['residual_none']:.1e} without (min of {d['rounds']} alternating rounds)")
    b.summary.append(line)
    over = [f"{d['residual_projection'] / 1e-12:.2g}x the residual"] if d["residual_projection"] >= 1e-12 else []
    over += [f"{(1 + extra) / 1.15:.2f}x the CPU ({extra * 100:+.1f} % vs +15 %)"] if extra > 0.15 else []
    b.targets.append(tg.Target("projection over 10^4 periods: residual < 1e-12 for <= 15 % more CPU",
                               f"residual {d['residual_projection']:.1e} for {extra * 100:+.1f} % CPU",
                               "met" if not over else f"MISSED: {', '.join(over)} allowed"))
    write_csv(b.out / "drift.csv", b.prov, ["rounds", "projection_s", "none_s", "residual_projection",
                                            "residual_none", "steps"],
              [[d["rounds"], d["projection_s"], d["none_s"], d["residual_projection"], d["residual_none"],
                d["steps"]]])
    b.sections.append(("6. Drift control over 10^4 periods",
                       "<p>Double pendulum with the elbow programmed at period 0.01 s for 100 s "
                       "(progmo::problems::hard::ten_thousand_periods), DOP853 rtol 1e-8: projection (tol 1e-12) "
                       "on and off alternate; the minimum wall time of each is compared.</p><p>"
                       + line + "</p><p>Data: <a href='drift.csv'>drift.csv</a>.</p>"))


def _part_executors(b: _Bench) -> None:
    """Part `executors`: the sweep executors, local pool and Ray (a failure is reported, the rest stands)."""
    from . import executors as ex, page

    try:
        exr = ex.run(b.out, samples=b.cfg.get("sweep_samples", 8))
        text, lines = ex.html(exr)
        b.summary += lines
        b.sections.append(("7. Sweep executors: local pool and Ray", page.doc(ex.__doc__) + text))
    except Exception as e:  # noqa: BLE001 - a part that fails is reported, the rest stands
        b.failed.append(f"executors: {e}")
        b.sections.append(("7. Sweep executors: local pool and Ray", f"<p>FAILED: {e}</p>"))


def _part_nightly(b: _Bench) -> None:
    """Part `nightly`: one `progmo check` of the catalog, timed (issue 31's target)."""
    from . import nightly as nt, page

    title = "8. The nightly check, timed"
    try:
        b.nightly = nt.run(b.out, b.cfg.get("nightly_scenes"))
    except RuntimeError as e:
        b.failed.append(f"nightly: {e}")
        b.nightly_why = f"the nightly part failed: {e}"
        b.sections.append((title, f"<p><b>FAILED</b>: {_html.escape(str(e))}</p>"))
        return
    lines = nt.lines(b.nightly)
    b.summary += lines
    if not b.nightly["whole_catalog"]:
        b.nightly_why = f"this run checked {', '.join(b.cfg['nightly_scenes'])} only (--smoke), not the whole catalog"
    b.sections.append((title, page.doc(nt.__doc__) + "<p>" + "<br>".join(_html.escape(x) for x in lines)
                       + "</p><p>Its report: <a href='nightly/report.html'>nightly/report.html</a>.</p>"))


def _part_corpus(b: _Bench) -> None:
    """Part `corpus`: `progmo corpus` on the installed collections (and --corpus-data), its table."""
    from .. import corpus as cp

    title = "9. Robot files of public collections: import rate and parity"
    n = b.cfg.get("corpus_sample")
    data = Path(b.ns.corpus_data) if b.ns.corpus_data else None
    try:
        rows, records = cp.run(list(cp.COLLECTIONS), data, True, n, cp.STATES, lambda s: None)
    except Exception as e:  # a bug of the harness: the part fails, the page says so
        b.failed.append(f"corpus: {e}")
        b.corpus_why = f"the corpus part failed: {e}"
        b.sections.append((title, f"<p><b>FAILED</b>: {_html.escape(str(e))}</p>"))
        return
    b.corpus = rows
    if n is not None:
        b.corpus_why = f"this run took a sample of {n} files per collection, not every file"
    (b.out / "corpus").mkdir(exist_ok=True)
    md = cp.table(rows)
    (b.out / "corpus" / "corpus.md").write_text("# progmo corpus\n\n" + md)
    (b.out / "corpus" / "corpus.json").write_text(json.dumps(
        {"tolerance": cp.PARITY_TOL, "states": cp.STATES, "sample": n, "collections": rows, "files": records}, indent=1))
    for r in rows:
        if r["status"] == "ok":
            b.summary.append(f"corpus {r['collection']}: {r['imported']}/{r['imports']} imports "
                             f"({r['import_rate']:.0%}; {r['import_rate_mujoco_compiles']:.0%} where MuJoCo compiles), "
                             f"within 1e-12 MuJoCo {r['mujoco_within']}/{r['mujoco_compared']}, "
                             f"Pinocchio {r['pinocchio_within']}/{r['pinocchio_compared']}")
    rerun = "progmo corpus" + (f" --data {data}" if data else "") + (f" --sample {n}" if n else "")
    b.sections.append((title, f"<p>{_html.escape(cp.__doc__.split(chr(10) + chr(10))[0])}</p>"
                       f"<pre>{_html.escape(md)}</pre><p>Rerun: <code>{_html.escape(rerun)}</code>; every file's "
                       "result: <a href='corpus/corpus.json'>corpus/corpus.json</a>.</p>"))


# each part's step, run in the order of PARTS
_PART_RUNS: dict[str, Callable[[_Bench], None]] = dict(
    workprecision=_part_workprecision, scipy=_part_scipy, conditioning=_part_conditioning, scaling=_part_scaling,
    anchor=_part_anchor, robot=_part_robot, testset=_part_testset, servo=_part_servo, drift=_part_drift,
    executors=_part_executors, nightly=_part_nightly, corpus=_part_corpus)


def _finish(b: _Bench, t_start: float) -> int:
    """The targets (always listed, measured or not), the page and stdout; the exit code (1 when a part failed)."""
    from . import page, targets as tg

    if b.ns.accept and b.anchor_rows is None:
        b.summary.append(f"--accept: nothing accepted ({b.anchor_why})")
    # issue 15's targets: always listed, measured or not (and then why not)
    b.targets += tg.anchor_targets(b.anchor_rows, b.anchor_why)
    b.targets.append(tg.caraxis_target(b.ts["rows"] if b.ts else None, b.testset_why))
    b.targets.append(tg.small_problem_target(b.anchor_rows, b.anchor_why))
    # issue 31's targets
    b.targets += tg.robot_targets(b.robot_rhs, b.robot_why)
    b.targets.append(tg.humanoid_target(b.robot_humanoid, b.robot_why))
    b.targets.append(tg.servo_target(b.servo, b.servo_why))
    b.targets.append(tg.nightly_target(b.nightly if b.nightly and b.nightly["whole_catalog"] else None,
                                       b.nightly_why))
    b.targets += tg.corpus_targets(b.corpus, b.corpus_why if b.corpus is None or b.cfg.get("corpus_sample") else "")
    b.targets.append(tg.ci_target())

    elapsed = time.perf_counter() - t_start
    if b.summary or b.targets:
        head = ""
        if b.targets:
            head += "<h3>Targets</h3>" + page.targets_table(b.targets)
            head += ("<p>Why the scipy ratio stays near 10x: per RHS the scipy pipeline costs Pinocchio's "
                     "forwardDynamics plus numpy J, gamma plus solve_ivp's Python step code (section 4, 'user "
                     "pipeline'); progmo's RHS costs about what Pinocchio's own C++ KKT call costs (section 4b) and "
                     "less than forwardDynamics called from Python, so at equal RHS counts the ratio is bounded by "
                     "(pipeline + scipy overhead) / progmo RHS.</p>")
        head += "<h3>Key numbers</h3>" + page.key_numbers(b.summary)
        b.sections.insert(0, ("Summary", head))
    page.write(b.out, b.prov, b.sections, b.omissions, elapsed)
    print(f"progmo bench: wrote {b.out}/index.html in {elapsed:.0f} s")
    for line in b.summary:
        print(line)
    print(_targets_text(b.targets))
    for line in b.prov.lines():
        print(line)
    for f in b.failed:
        print(f"progmo bench: FAILED: {f}", file=sys.stderr)
    return 1 if b.failed else 0


def _robot_section(rb: dict, page, anchor) -> tuple[str, list[str]]:
    """The robot part's HTML (tables) and its key-number lines."""
    from . import targets as tg

    us = lambda x: f"{x * 1e6:.2f}"  # noqa: E731
    name, lines, inner = rb["scene"], [], ""
    r = rb["rhs"]
    if r is None:
        inner += f"<p><b>C++ RHS comparison SKIPPED</b>: {_html.escape(rb['rhs_skipped'])}</p>"
        lines.append(f"robot {name}: C++ RHS comparison SKIPPED: {rb['rhs_skipped']}")
    else:
        hdr = ["n, rows", "C++ ABA (us)", "C++ KKT forwardDynamics, J and gamma given (us)", "C++ same work, best (us)",
               "progmo null_space (us)", "progmo kkt (us)", "progmo null_space / C++ same work",
               "progmo kkt / C++ same work", "progmo null_space / C++ KKT",
               "max rel. disagreement (tolerance, states)"]
        inner += page.table(hdr, [[f"{rb['n']}, {rb['s']}", us(r["aba_s"]), us(r["kkt_s"]),
                                   f"{us(r['same_best_s'])} ({r['same_best']})", us(r["progmo_null_space_s"]),
                                   us(r["progmo_kkt_s"]), f"{r['ratio_null_space']:.2f}", f"{r['ratio_kkt']:.2f}",
                                   f"{r['ratio_null_space_kkt']:.2f}",
                                   f"{r['agreement']:.1e} ({r['agreement_tol']:.0e}, {r['agreement_states']})"]])
        inner += ("<p>Every same-work variant (us per call):</p>"
                  + page.table(list(anchor.SAME), [[us(r[f"{v}_s"]) for v in anchor.SAME]]))
        if "weld_best_s" in r:
            inner += ("<p>Pinocchio's O(n + m) constrained dynamics with the TCP frame welded to the world "
                      "(CONTACT_6D: the six rows' structure without their time law; agreement with the KKT solve "
                      "of the frame's Jacobian and drift checked first), us per call, and progmo's default "
                      "formulation against the faster:</p>"
                      + page.table([*anchor.WELD, f"progmo {tg.DEFAULT} / best"],
                                   [[us(r[f"{v}_s"]) for v in anchor.WELD] + [f"{r[f'ratio_{tg.DEFAULT}_weld']:.2f}"]]))
            lines.append(f"robot {name} RHS: Pinocchio C++ constraintDynamics {us(r['weld_cd_s'])} us, lcaba "
                         f"{us(r['weld_lcaba_s'])} us (TCP welded); progmo {tg.DEFAULT} / best "
                         f"{r[f'ratio_{tg.DEFAULT}_weld']:.2f}")
        lines.append(f"robot {name} RHS: progmo null_space {us(r['progmo_null_space_s'])} us, kkt {us(r['progmo_kkt_s'])} us; "
                     f"C++ same work {us(r['same_best_s'])} us ({r['same_best']}), KKT (J, gamma given) {us(r['kkt_s'])} us, "
                     f"ABA {us(r['aba_s'])} us; progmo/C++ same work {r['ratio_null_space']:.2f} (null_space); "
                     f"agreement {r['agreement']:.1e} at {r['agreement_states']} states")
    h = rb.get("humanoid")
    if h is not None:
        from . import humanoid

        inner += (f"<p>The humanoid ({humanoid.SCENE}: TALOS, n = {h['n']}, free base) standing on both soles welded "
                  f"to the world ({h['closure_rows']} closure rows, no programme) beside Pinocchio's C++ constrained "
                  "dynamics on the check's own model and welds (bench/humanoid.py; agreement with progmo's kkt "
                  "dv/dt checked first), us per call:</p>"
                  + page.table(["C++ ABA", "C++ weld_kkt (dense KKT)", "C++ constraintDynamics", "C++ lcaba",
                                "progmo null_space", "progmo kkt", "progmo articulated_body", f"progmo {tg.DEFAULT}",
                                f"progmo {tg.DEFAULT} / best C++", "programmed motion (s = n), progmo auto",
                                "max rel. disagreement (tolerance, states)"],
                               [[us(h["aba_s"]), us(h["weld_kkt_s"]), us(h["weld_cd_s"]), us(h["weld_lcaba_s"]),
                                 us(h["progmo_null_space_s"]), us(h["progmo_kkt_s"]), us(h["progmo_articulated_body_s"]),
                                 us(h[f"progmo_{tg.DEFAULT}_s"]), f"{h[f'ratio_{tg.DEFAULT}_weld']:.2f}",
                                 us(h["progmo_programmed_s"]),
                                 f"{h['agreement']:.1e} ({h['agreement_tol']:.0e}, {h['agreement_states']})"]])
                  + "<p>Data: <a href='humanoid.csv'>humanoid.csv</a>.</p>")
        lines.append(f"robot {humanoid.SCENE} on welded soles: Pinocchio C++ constraintDynamics {us(h['weld_cd_s'])} us, "
                     f"lcaba {us(h['weld_lcaba_s'])} us, dense KKT {us(h['weld_kkt_s'])} us, ABA {us(h['aba_s'])} us; "
                     f"progmo {tg.DEFAULT} {us(h[f'progmo_{tg.DEFAULT}_s'])} us ({h[f'ratio_{tg.DEFAULT}_weld']:.2f}x the "
                     f"best); agreement {h['agreement']:.1e} at {h['agreement_states']} states")
    s = rb["solve"]
    inner += page.table(
        ["solver", "CPU (s)", "RHS evaluations", "final-state error vs reference"],
        [[f"progmo {s['integrator']}, drift control {s['drift']}", page.num(s["progmo_cpu_s"]), s["progmo_rhs_evals"],
          f"{s['progmo_error']:.1e}"],
         ["scipy solve_ivp DOP853 + Pinocchio's Python binding", page.num(s["scipy_cpu_s"]), s["scipy_rhs_evals"],
          f"{s['scipy_error']:.1e}"]])
    inner += (f"<p>Whole solve at rtol {s['rtol']:.0e}, atol {s['atol']:.0e} (the scene's): CPU(scipy + Pinocchio) / "
              f"CPU(progmo) = {s['ratio']:.1f}; reference floor {s['reference_floor']:.1e}; the C++ same-work RHS times "
              f"progmo's RHS count: {page.num(s['cpp_rhs_share_s'])} s.</p>")
    lines.append(f"robot {name} whole solve: progmo {s['progmo_cpu_s'] * 1e3:.1f} ms CPU (error {s['progmo_error']:.1e}), "
                 f"scipy DOP853 + Pinocchio Python {s['scipy_cpu_s'] * 1e3:.1f} ms (error {s['scipy_error']:.1e}): "
                 f"{s['ratio']:.1f}x")
    ld = rb["load"]
    inner += page.table(["URDF load", "best wall time (ms)"],
                        [["progmo.load of a [model]-only scene (URDF import, tree)", f"{ld['progmo_load_s'] * 1e3:.3f}"],
                         ["pin.buildModelFromUrdf", f"{ld['pin_urdf_s'] * 1e3:.3f}"],
                         ["pin.buildModelFromUrdf + buildReducedModel", f"{ld['pin_urdf_reduced_s'] * 1e3:.3f}"]])
    inner += "<p>Data: <a href='robot.csv'>robot.csv</a>.</p>"
    lines.append(f"robot {name} URDF load: progmo {ld['progmo_load_s'] * 1e3:.3f} ms, pin.buildModelFromUrdf "
                 f"{ld['pin_urdf_s'] * 1e3:.3f} ms (+ buildReducedModel {ld['pin_urdf_reduced_s'] * 1e3:.3f} ms)")
    return inner, lines


def _targets_text(targets) -> str:
    """The targets as a plain-text table (stdout): verdict | target | measured."""
    w = max((len(t.verdict) for t in targets), default=7)
    lines = ["targets (from this run):", f"  {'verdict'.ljust(w)} | target | measured"]
    lines += [f"  {t.verdict.ljust(w)} | {t.target} | {t.measured}" for t in targets]
    return "\n".join(lines)


if __name__ == "__main__":
    from .._stdio import run

    sys.exit(run(main, "progmo bench"))
