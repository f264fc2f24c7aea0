"""The speed targets of `progmo bench` (issue 15, item 5), judged on one run's figures.

Each target is a row: what it asks, the figure this run measured, and the verdict: "met",
"MISSED by ..." (how far off), or "not measured: <why>". main.py collects the rows (with the older
targets of the scipy and drift parts), puts them in a table at the top of the page and prints them.

- RHS <= 0.7x the leanest Pinocchio C++ same-work sequence at n = 7 and n = 30 (anchor part):
  progmo's default formulation (`auto`: null_space below AUTO_ARTICULATED_NV velocities,
  articulated_body from there on) against the fastest C++ same-work variant, minima of the same
  alternating rounds;
- growth exponent log(t128 / t30) / log(128 / 30) <= 1.2 (issue 15 also asked RHS at n = 128 <=
  60 us: replaced by issue 31's ratio below);
- the IVP Test Set car axis: 8 significant digits (mescd of y(1:10)) in <= 2 ms CPU (issue 31; issue
  15 asked 5 ms): the CPU time at
  8 digits interpolated in log-log on each method's digits-vs-CPU front (the cheapest run reaching
  8 digits when the front does not bracket 8), best method;
- no regression of the small-problem cost (n = 2 and 4): the ratio progmo / C++ same work of this
  run against the accepted ratio in bench/accepted.json (which names its command, date and commit;
  `progmo bench --accept` records one run, the shipped file the median of ten), met while no more
  than ACCEPTED_SLACK above it. The ratio, not the absolute time, is judged: both
  sides are measured in the same rounds, so machine speed and load largely cancel; the absolute
  times are shown beside it.
Issue 31 (speed on real robots and in servo-constraints) adds, each from this run's figures:
- the Panda of panda_circle (robot part): RHS <= 0.7x Pinocchio's C++ same work, and <= 1.0x the
  faster of Pinocchio's C++ constraintDynamics / lcaba on the TCP welded (the anchor's weld_*);
- the humanoid (TALOS of talos_com_shift, both soles welded, no programme; robot part,
  bench/humanoid.py): progmo's RHS <= 1.0x the faster of Pinocchio's C++ constraintDynamics / lcaba
  (issue 31 item 3 asks these anchors on the targets table; the bound is the Panda's);
- the n = 128 chain's RHS <= 1.2x C++ ABA alone (anchor part; it replaces issue 15's 60 us);
- the servo crane's RHS <= 20x its ideal realization (servo part: CPU per RHS, median over tolerances);
- the car axis at 8 digits in <= 2 ms CPU (issue 15 asked 5 ms);
- the nightly check of the whole catalog <= 60 s wall on 2 cores (nightly part: `progmo check`
  timed once, with this machine's core count said);
- CI on a fresh clone <= 20 min: not measurable inside a benchmark run (it is the fresh-clone
  `.ci/run`), listed as not measured with where its figure comes from.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

ACCEPTED = Path(__file__).resolve().parent / "accepted.json"
RATIO_MAX = 0.7
RATIO_NS = (7, 30)
N_BIG, BIG_ABA_MAX = 128, 1.2  # RHS at n = 128 over C++ ABA alone (issue 31)
GROWTH_FROM, GROWTH_MAX = 30, 1.2
DIGITS, DIGITS_CPU_MAX = 8.0, 2e-3
PANDA_SAME_MAX, PANDA_WELD_MAX = 0.7, 1.0
SERVO_MAX = 20.0
NIGHTLY_MAX_S, CI_MAX_S = 60.0, 20 * 60.0
SMALL_NS = (2, 4)
#: relative rise of the small-problem ratio over the accepted one that counts as a regression: ten
#: back-to-back runs of one build (2026-11-23, accepted.json's note) put the n = 2 ratio at 1.19-1.40
#: (median 1.25; bimodal from one process to the next), n = 4 at 1.01-1.26 (median 1.17)
ACCEPTED_SLACK = 0.15


@dataclass
class Target:
    target: str
    measured: str
    verdict: str

    @property
    def met(self) -> bool:
        return self.verdict == "met"

    @property
    def status(self) -> str:
        """met, missed or not measured (the page's colour)."""
        if self.met:
            return "met"
        return "not measured" if self.verdict.startswith("not measured") else "missed"

    @property
    def how_far(self) -> str:
        """The verdict's detail as the page shows it: "2.86x over target" for "MISSED by 2.86x"."""
        m = re.match(r"MISSED by ([0-9.]+(?:-[0-9.]+)?)x(.*)$", self.verdict)
        if m:
            return f"{m.group(1)}x over target{m.group(2)}"
        for prefix in ("MISSED by ", "MISSED: ", "MISSED", "not measured: ", "met"):
            if self.verdict.startswith(prefix):
                return self.verdict[len(prefix):]
        return self.verdict

    def line(self) -> str:
        return f"target: {self.target}: {self.measured}: {self.verdict}"


def not_measured(target: str, why: str) -> Target:
    return Target(target, "-", f"not measured: {why}")


def _at(rows, n: int) -> dict | None:
    return next((r for r in rows if r["n"] == n), None)


def _us(x: float) -> str:
    return f"{x * 1e6:.3g} us"


#: the formulation the RHS targets judge: the default
DEFAULT = "auto"


def anchor_targets(rows: Sequence[dict] | None, why: str = "") -> list[Target]:
    """The RHS targets from the anchor part's rows (None: the part did not run; `why` says so), on
    the default formulation (DEFAULT)."""
    out: list[Target] = []
    key, ratio_key = f"progmo_{DEFAULT}_s", f"ratio_{DEFAULT}"
    rows = rows or []
    for n in RATIO_NS:
        name = f"RHS <= {RATIO_MAX}x the leanest Pinocchio C++ same-work sequence at n = {n}"
        r = _at(rows, n)
        if r is None:
            out.append(not_measured(name, why or f"n = {n} not in this run's chains"))
            continue
        ratio = r[ratio_key]
        out.append(Target(name, f"progmo {DEFAULT} {_us(r[key])} / C++ {r['same_best']} "
                                f"{_us(r['same_best_s'])} = {ratio:.2f}x",
                          "met" if ratio <= RATIO_MAX else f"MISSED by {ratio / RATIO_MAX:.2f}x"))
    name = f"RHS at n = {N_BIG} <= {BIG_ABA_MAX}x Pinocchio's C++ ABA alone"
    big = _at(rows, N_BIG)
    if big is None:
        out.append(not_measured(name, why or f"n = {N_BIG} not in this run's chains"))
    else:
        out.append(_ratio_target(name, big[key], big["aba_s"], BIG_ABA_MAX, f"progmo {DEFAULT}", "C++ ABA"))
    name = f"growth exponent of the RHS between n = {GROWTH_FROM} and {N_BIG} <= {GROWTH_MAX}"
    lo = _at(rows, GROWTH_FROM)
    if big is None or lo is None:
        out.append(not_measured(name, why or f"n = {GROWTH_FROM} and {N_BIG} not both in this run's chains"))
    else:
        e = growth_exponent(lo[key], big[key], GROWTH_FROM, N_BIG)
        excess = (N_BIG / GROWTH_FROM) ** (e - GROWTH_MAX)
        out.append(Target(name, f"{e:.2f} ({DEFAULT}: {_us(lo[key])} -> {_us(big[key])})",
                          "met" if e <= GROWTH_MAX else
                          f"MISSED by {e - GROWTH_MAX:.2f} in the exponent ({excess:.1f}x the time at n = {N_BIG})"))
    return out


def _ratio_target(name: str, ours: float, theirs: float, limit: float, who: str, anchor: str) -> Target:
    r = ours / theirs
    return Target(name, f"{who} {_us(ours)} / {anchor} {_us(theirs)} = {r:.2f}x",
                  "met" if r <= limit else f"MISSED by {r / limit:.2f}x")


def robot_targets(rhs: dict | None, why: str = "") -> list[Target]:
    """The Panda's RHS against Pinocchio's C++ same work and its O(n + m) constrained dynamics (the
    robot part's row: anchor.Timing.row plus agreement; None: not measured, `why` says so)."""
    same = f"Panda (panda_circle, n = 7, 6 rows) RHS <= {PANDA_SAME_MAX}x Pinocchio's C++ same work"
    weld = (f"Panda RHS <= {PANDA_WELD_MAX}x the faster of Pinocchio's C++ constraintDynamics / lcaba "
            "(TCP welded)")
    if rhs is None:
        return [not_measured(same, why or "the robot part did not run"),
                not_measured(weld, why or "the robot part did not run")]
    out = [_ratio_target(same, rhs[f"progmo_{DEFAULT}_s"], rhs["same_best_s"], PANDA_SAME_MAX,
                         f"progmo {DEFAULT}", f"C++ {rhs['same_best']}")]
    if "weld_best_s" in rhs:
        out.append(_ratio_target(weld, rhs[f"progmo_{DEFAULT}_s"], rhs["weld_best_s"], PANDA_WELD_MAX,
                                 f"progmo {DEFAULT}", f"C++ {rhs['weld_best']}"))
    else:
        out.append(not_measured(weld, "the anchor did not time a welded frame (rows without a six-row frame task)"))
    return out


def humanoid_target(res: dict | None, why: str = "") -> Target:
    """The humanoid on welded soles against Pinocchio's C++ constrained dynamics (robot part)."""
    name = (f"humanoid (TALOS, n = 18, both soles welded) RHS <= {PANDA_WELD_MAX}x the faster of Pinocchio's "
            "C++ constraintDynamics / lcaba")
    if res is None:
        return not_measured(name, why or "the robot part did not run")
    return _ratio_target(name, res[f"progmo_{DEFAULT}_s"], res["weld_best_s"], PANDA_WELD_MAX,
                         f"progmo {DEFAULT}", f"C++ {res['weld_best']}")


def servo_target(res: dict | None, why: str = "") -> Target:
    """The overhead crane's servo RHS against its ideal realization (servo part)."""
    name = f"servo crane (overhead_crane) RHS <= {SERVO_MAX:.0f}x its ideal realization"
    if res is None or not math.isfinite(res.get("reduction_cost", math.nan)):
        return not_measured(name, why or "the servo part did not run")
    r = res["reduction_cost"]
    per = {x["realization"]: x["us_per_rhs"] for x in res["rows"]}
    return Target(name, f"CPU per RHS servo / ideal, median over tolerances: {r:.0f}x "
                        f"(e.g. {per.get('servo', math.nan):.0f} us vs {per.get('ideal', math.nan):.1f} us)",
                  "met" if r <= SERVO_MAX else f"MISSED by {r / SERVO_MAX:.2f}x")


def nightly_target(res: dict | None, why: str = "") -> Target:
    """The nightly check's wall time (nightly part: one `progmo check` of the catalog)."""
    name = f"nightly check of the whole catalog <= {NIGHTLY_MAX_S:.0f} s wall on 2 cores"
    if res is None:
        return not_measured(name, why or "the nightly part did not run")
    w = res["wall_s"]
    measured = (f"{w:.0f} s wall for {res['checks']} checks ({', '.join(res['simulators'])}) with "
                f"{res['jobs']} jobs on {res['cores']} cores")
    if res["cores"] != 2:
        return Target(name, measured, f"not measured: this machine has {res['cores']} cores, not 2")
    return Target(name, measured, "met" if w <= NIGHTLY_MAX_S else f"MISSED by {w / NIGHTLY_MAX_S:.2f}x")


CORPUS_MIN_RATE = 0.95


def corpus_targets(rows: Sequence[dict] | None, why: str = "") -> list[Target]:
    """Issue 30's corpus targets from the corpus part's rows (``corpus.summarize``): import rate
    >= 95 % per collection found, and every compared import's A and G + Q within 1e-12."""
    rate = f"robot-file corpus: import rate >= {CORPUS_MIN_RATE:.0%} in each collection"
    parity = "robot-file corpus: every compared import within 1e-12 of MuJoCo's and Pinocchio's reading"
    found = [r for r in rows or [] if r["status"] == "ok"]
    if not found:
        w = why or "the corpus part found no collection"
        return [not_measured(rate, w), not_measured(parity, w)]
    low = [r for r in found if r["import_rate"] < CORPUS_MIN_RATE]
    measured = "; ".join(f"{r['collection']} {r['imported']}/{r['imports']} ({r['import_rate']:.0%}; "
                         f"{r['import_rate_mujoco_compiles']:.0%} where MuJoCo compiles)" for r in found)
    out = [Target(rate, measured, why and f"not measured: {why}" or (
        "met" if not low else "MISSED: " + ", ".join(f"{r['collection']} {r['import_rate']:.0%}" for r in low)))]
    compared = sum(r[f"{s}_compared"] for r in found for s in ("mujoco", "pinocchio"))
    within = sum(r[f"{s}_within"] for r in found for s in ("mujoco", "pinocchio"))
    worst = max((r["worst_parity"] for r in found if r["worst_parity"] is not None), default=None)
    pm = f"{within}/{compared} comparisons within, worst {worst:.1e}" if worst is not None else "none compared"
    out.append(Target(parity, pm, why and f"not measured: {why}" or (
        "met" if compared and within == compared else f"MISSED: {compared - within} outside")))
    return out


def ci_target() -> Target:
    return not_measured(f"CI on a fresh clone <= {CI_MAX_S / 60:.0f} min",
                        "the fresh-clone `bash .ci/run` is timed where CI runs (the session note names the figure)")


def growth_exponent(t_lo: float, t_hi: float, n_lo: int, n_hi: int) -> float:
    return math.log(t_hi / t_lo) / math.log(n_hi / n_lo)


def caraxis_target(rows: Sequence[dict] | None, why: str = "") -> Target:
    """8 significant digits in <= DIGITS_CPU_MAX CPU from the testset part's rows (method, mescd_all, cpu_s)."""
    from .common import time_at_error

    name = f"IVP Test Set car axis: {DIGITS:.0f} significant digits in <= {DIGITS_CPU_MAX * 1e3:.0f} ms CPU"
    if not rows:
        return not_measured(name, why or "the testset part did not run")
    best: tuple[float, str] | None = None
    for m in sorted({r["method"] for r in rows}):
        rs = [r for r in rows if r["method"] == m and r["code"] == "success"]
        errs = [10.0 ** -r["mescd_all"] for r in rs]
        t = time_at_error(errs, [r["cpu_s"] for r in rs], 10.0 ** -DIGITS)
        how = "interpolated"
        if not np.isfinite(t):
            reach = [r for r in rs if r["mescd_all"] >= DIGITS]
            if not reach:
                continue
            cheapest = min(reach, key=lambda r: r["cpu_s"])
            t, how = cheapest["cpu_s"], f"run at rtol {cheapest['rtol']:.0e}, {cheapest['mescd_all']:.1f} digits"
        if best is None or t < best[0]:
            best = (t, f"{m}, {how}")
    if best is None:
        top = max((r["mescd_all"] for r in rows), default=float("nan"))
        return not_measured(name, f"no run of this sweep reached {DIGITS:.0f} digits (best {top:.1f})")
    t, how = best
    return Target(name, f"{t * 1e3:.2f} ms ({how})",
                  "met" if t <= DIGITS_CPU_MAX else f"MISSED by {t / DIGITS_CPU_MAX:.2f}x")


def load_accepted(path: Path = ACCEPTED) -> dict[str, Any]:
    return json.loads(path.read_text())


def small_problem_target(rows: Sequence[dict] | None, why: str = "",
                         accepted: dict[str, Any] | None = None) -> Target:
    """The small chains' ratio progmo / C++ same work against the accepted ratios."""
    if accepted is None:
        try:
            accepted = load_accepted()
        except (OSError, ValueError) as e:
            return not_measured("no regression of the small-problem RHS (n = 2, 4)",
                                f"no accepted figures ({e}); record them with `progmo bench --only anchor --accept`")
    small = accepted["small_problem_rhs"]
    prov = small["provenance"]
    name = (f"no regression of the small-problem RHS (n = {', '.join(map(str, SMALL_NS))}): progmo / C++ same "
            f"work <= accepted x {1 + ACCEPTED_SLACK:.2f} (accepted {prov['date']}, commit {prov['commit']}, "
            f"`{prov['command']}`)")
    rows = rows or []
    parts, worst = [], 0.0
    for n in SMALL_NS:
        r = _at(rows, n)
        a = next((x for x in small["rows"] if x["n"] == n), None)
        if r is None or a is None:
            return not_measured(name, why or f"n = {n} not in this run's chains or not accepted")
        rel = r["ratio_null_space"] / a["ratio_null_space"]
        worst = max(worst, rel)
        parts.append(f"n = {n}: {r['ratio_null_space']:.2f} vs accepted {a['ratio_null_space']:.2f} "
                     f"({_us(r['progmo_null_space_s'])} vs {a['progmo_null_space_us']:.3g} us)")
    return Target(name, "; ".join(parts),
                  "met" if worst <= 1 + ACCEPTED_SLACK else f"MISSED by {worst:.2f}x (regression)")


def accepted_record(rows: Sequence[dict], provenance: dict[str, str]) -> dict[str, Any]:
    """The JSON record of this run's small-problem figures (to accept them: write it to ACCEPTED)."""
    keep = []
    for n in SMALL_NS:
        r = _at(rows, n)
        if r is None:
            raise ValueError(f"n = {n} not measured")
        keep.append(dict(n=n, progmo_null_space_us=round(r["progmo_null_space_s"] * 1e6, 4),
                         cpp_same_best=r["same_best"], cpp_same_best_us=round(r["same_best_s"] * 1e6, 4),
                         ratio_null_space=round(r["ratio_null_space"], 4)))
    return dict(small_problem_rhs=dict(provenance=provenance, rows=keep))
