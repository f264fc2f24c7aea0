"""The tolerance report of a check run: ``report.html`` (one self-contained page: inline CSS,
plots as inline base64 PNG, no network), ``summary.md`` and ``summary.csv``.

Everything is rebuilt from plain data (:class:`Run`), which ``run.json`` stores next to
``results.json``, so ``python -m progmo.cli report OUT_DIR`` re-renders a saved run.

Plots group a result's ``series`` by name: names containing ``residual`` (programme residual, log
scale), ``deviation``/``error``/``drift`` (deviation from the solver, log scale), names starting
with ``u`` or containing ``control``/``force``/``torque`` (control forces, linear), anything else
in an "other" panel. Budgets whose metric contains ``residual``/``deviation`` are drawn dashed.
"""

from __future__ import annotations

import base64
import csv
import datetime as _dt
import io
import json
import math
import os
import platform
import re
import subprocess
import sys
from dataclasses import asdict
from importlib import metadata
from pathlib import Path
from typing import Any

from . import baselines as bl
from . import history
from .htmlstyle import CSS, esc
from .results import SOLVER_ONLY, CheckResult
# the run model and its verdicts (re-exported: report.Run, report.label, ...)
from .verdict import LABEL, OK_VERDICTS, RANK, Run, label  # noqa: F401

# --- provenance ----------------------------------------------------------------------------------
def _git(root: Path, *args: str) -> str | None:
    try:
        p = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=10)
        return p.stdout.strip() if p.returncode == 0 else None
    except (OSError, subprocess.SubprocessError):
        return None


def _version(dist: str) -> str:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "not installed"


def provenance(root: Path, command: str) -> dict[str, Any]:
    """What produced this run: revision, versions, host, date and the command that reruns it."""
    rev = _git(root, "rev-parse", "HEAD") or os.environ.get("GITHUB_SHA") or "unknown"
    dirty = _git(root, "status", "--porcelain", "--untracked-files=no")
    try:
        from . import version as progmo_version

        progmo = progmo_version()
    except Exception as e:  # noqa: BLE001 - the extension may be missing; say so
        progmo = f"unavailable ({type(e).__name__})"
    return {
        "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC"),
        "git_revision": rev + (" (with uncommitted changes)" if dirty else ""),
        "progmo": progmo,
        "mujoco": _version("mujoco"),
        "pinocchio": _version("pin"),
        "drake": _version("drake"),
        "numpy": _version("numpy"),
        "matplotlib": _version("matplotlib"),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "cpu_count": os.cpu_count(),
        "command": command,
    }


# --- formatting ----------------------------------------------------------------------------------
def fmt(v: Any) -> str:
    if v is None:
        return "NaN"
    if isinstance(v, float):
        if math.isnan(v):
            return "NaN"
        return f"{v:.3g}" if v != 0 else "0"
    return str(v)


_e = esc


def _anchor(scene: str) -> str:
    return "scene-" + re.sub(r"[^A-Za-z0-9_-]", "_", scene)


def rows_of(run: Run, r: CheckResult) -> list[dict[str, Any]]:
    """One row per metric: value, budget (+reason, verdict), baseline (+threshold, state)."""
    budgets = {b.metric: b for b in r.budgets}
    breaches = {b.metric for b in r.breaches}
    comps = {c["metric"]: c for c in run.comparisons.get((r.scene, r.simulator), [])}
    names = list(r.metrics) + [m for m in budgets if m not in r.metrics]
    names += [m for m in comps if m not in names and m not in r.info]
    out = []
    for m in names:
        b, c = budgets.get(m), comps.get(m, {})
        v = r.metrics.get(m)
        out.append(
            {
                "metric": m,
                "value": v,
                "budget": b.value if b else None,
                "budget_reason": b.reason if b else "",
                "budget_source": b.source if b else "",
                "use": (v / b.value) if (b and v is not None and b.value > 0 and math.isfinite(v)) else None,
                "within_budget": (None if b is None else m not in breaches),
                "baseline": c.get("baseline"),
                "threshold": c.get("threshold"),
                "baseline_state": c.get("state", ""),
            }
        )
    for m, v in r.info.items():
        c = comps.get(m, {})
        out.append({"metric": m, "value": v, "budget": None, "budget_reason": "information, not judged",
                    "budget_source": "", "use": None, "within_budget": None, "baseline": c.get("baseline"),
                    "threshold": None, "baseline_state": "info" if c else ""})
    return out


def max_residual(r: CheckResult) -> float | None:
    vals = [v for k, v in r.metrics.items() if "residual" in k and v is not None and math.isfinite(v)]
    return max(vals) if vals else None


def budget_use(r: CheckResult) -> float | None:
    """Largest value/budget over the budgets (1 = at the budget); inf for a NaN metric."""
    uses = []
    for b in r.budgets:
        v = r.metrics.get(b.metric)
        if v is None or not math.isfinite(v):
            uses.append(math.inf)
        elif b.value > 0:
            uses.append(v / b.value)
    return max(uses) if uses else None


# --- plots ---------------------------------------------------------------------------------------
GROUPS = [
    ("programme residual", re.compile(r"residual", re.I), True),
    ("deviation from the solver", re.compile(r"deviation|error|drift", re.I), True),
    ("control forces u", re.compile(r"^u\b|^u[_\[(\d]|control|force|torque", re.I), False),
    ("q(t): solver (solid), replay (dashed)", re.compile(r"^q\."), False),
    ("other", re.compile(r""), False),
]
MAX_POINTS = 2000


def _groups(r: CheckResult):
    out: dict[str, list] = {}
    for s in r.series:
        for title, pat, _ in GROUPS:
            if pat.search(s.name):
                out.setdefault(title, []).append(s)
                break
    return [(t, out[t], log) for t, _, log in GROUPS if t in out]


def plot(r: CheckResult) -> str | None:
    """The result's series as one PNG (data URI): residual and deviation on log scales with their
    budgets dashed, control forces on a linear scale. None when there are no series."""
    groups = _groups(r)
    if not groups:
        return None
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from matplotlib.ticker import FuncFormatter, LogLocator, NullLocator

    ncol = min(3, len(groups))
    nrow = -(-len(groups) // ncol)
    fig = Figure(figsize=(3.9 * ncol, 2.7 * nrow), dpi=90)
    FigureCanvasAgg(fig)
    # Fixed margins and plain tick labels: constrained layout and mathtext cost ~1 s per figure.
    fig.subplots_adjust(left=0.07 if ncol > 1 else 0.14, right=0.985, bottom=0.17 / nrow, top=1 - 0.1 / nrow,
                        wspace=0.28, hspace=0.45)
    grid = fig.subplots(nrow, ncol, squeeze=False)
    axes = [grid[k // ncol][k % ncol] for k in range(len(groups))]
    for k in range(len(groups), nrow * ncol):
        grid[k // ncol][k % ncol].set_visible(False)
    for ax, (title, series, log) in zip(axes, groups):
        colors: dict[str, str] = {}
        for s in series[:12]:
            t = np.asarray([math.nan if x is None else x for x in s.t], dtype=float)
            y = np.asarray([math.nan if x is None else x for x in s.values], dtype=float)
            n = min(len(t), len(y))
            t, y = t[:n], y[:n]
            if n > MAX_POINTS:
                idx = np.linspace(0, n - 1, MAX_POINTS).astype(int)
                if log:  # keep the peaks visible: max over each window
                    y = np.maximum.reduceat(np.abs(y), idx)
                t, y = t[idx], y[idx] if not log else y
            if log:
                y = np.abs(y)
                y[~(y > 0)] = np.nan
            replay = s.name.endswith(" replay")
            label = None if replay else s.name
            color = colors.get(s.name[: -len(" replay")]) if replay else None
            line = ax.plot(t, y, lw=1.1, label=label, ls="--" if replay else "-", color=color)[0]
            colors[s.name] = line.get_color()
        if log:
            ax.set_yscale("log")
            ax.yaxis.set_major_locator(LogLocator(numticks=6))
            ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:.0e}"))
            ax.yaxis.set_minor_locator(NullLocator())
            key = "residual" if "residual" in title else "deviation"
            for i, b in enumerate(bb for bb in r.budgets if key in bb.metric):
                ax.axhline(b.value, color="#c0392b", ls="--", lw=1)
                ax.annotate(f"budget {b.metric}", (0.01 + 0.34 * i, b.value),  # staggered: no overlap
                            xycoords=("axes fraction", "data"), fontsize=7, color="#c0392b", va="bottom")
            for br in r.breaches:  # where each breach began
                if br.first_time is not None and (key in br.metric or br.metric == "replay_blowup"):
                    ax.axvline(br.first_time, color="#c0392b", ls=":", lw=1.2)
                    ax.annotate(f"first breach: {br.metric}\nt = {br.first_time:.4g}", (br.first_time, 0.97),
                                xycoords=("data", "axes fraction"), fontsize=6.5, color="#c0392b",
                                va="top", ha="left")
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("t [s]", fontsize=8)
        units = list(dict.fromkeys(s.unit for s in series[:12] if s.unit))
        if units:
            ax.set_ylabel("; ".join(units), fontsize=7)
        ax.tick_params(labelsize=7)
        ax.grid(True, which="major", alpha=0.3)
        if len(series) <= 8:
            ax.legend(fontsize=6.5, loc="best", frameon=False)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


# --- HTML ----------------------------------------------------------------------------------------


#: A pass using more than this fraction of a budget is shown amber in the grid ("warn").
WARN_USE = 0.5


def _badge(verdict: str) -> str:
    return f'<span class="v v-{verdict.replace(" ", "-")}">{_e(label(verdict))}</span>'


def _bar(use: float | None) -> str:
    if use is None:
        return ""
    w = 100 if not math.isfinite(use) else max(2, min(100, 100 * use))
    cls = "hot" if not (use <= 1) else ("warm" if use > 0.5 else "")
    return f'<span class="bar"><i class="{cls}" style="width:{w:.0f}%"></i></span>'


def _use_text(use: float | None) -> str:
    if use is None:
        return ""
    if not math.isfinite(use):
        return "NaN"
    return f"{use:.3g}&times;" if use >= 10 else f"{100 * use:.3g}%"


def _na_reason(run: Run, s: str, m: str) -> str:
    why = run.scenes.get(s, {}).get("solver_only")
    if why and m != SOLVER_ONLY:
        return f"not applicable: checked solver-only ({why})"
    return "not applicable: not scheduled for this scene"


def _attention(run: Run) -> list[tuple[str, str, str, str]]:
    """(scene, simulator, verdict, one-line reason) of every cell that fails the job."""
    out = []
    for s in run.scene_names():
        for m in run.cells(s):
            r = run.result(s, m)
            v = run.verdict(r)
            if v in OK_VERDICTS:
                continue
            if r is None:
                why = "this check did not run (interrupted or cancelled)"
            elif v == "regression":
                why = "; ".join(f"{c['metric']} {fmt(c['value'])} > {fmt(c['threshold'])} (baseline {fmt(c['baseline'])})" for c in run.regressed(r))
            elif v == "fail":
                why = "; ".join(f"{b.metric} {fmt(b.value)} > budget {fmt(b.budget)}" + (f" at {b.where}" if b.where else "") + (f" first at t = {b.first_time:.4g}" if b.first_time is not None else "") for b in r.breaches) or r.reason
            else:
                why = r.reason
            since = history.streak_start(run.history, f"{s}/{m}") if run.history else None
            if since is not None and since is not run.history[-1]:
                why += f" [failing since the run of {since.get('date')} (revision {str(since.get('git_revision'))[:12]})]"
            elif since is not None:
                why += " [first failing run in the history]"
            out.append((s, m, v, why))
    return out


def render_html(run: Run) -> str:
    p = run.provenance
    ok = run.ok()
    h: list[str] = []
    a = h.append
    a("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>")
    a("<meta name='viewport' content='width=device-width,initial-scale=1'>")
    a(f"<title>progmo check: {'pass' if ok else 'FAIL'} ({_e(p.get('date', ''))})</title>")
    a(f"<style>{CSS}</style></head><body><main>")
    a("<h1>progmo cross-simulator check</h1>")
    a(f"<p class='sub'>Open-loop replay of the control forces u in {', '.join(_e(m) for m in run.simulators)}; "
      f"{_e(p.get('date', ''))}, revision <code>{_e(str(p.get('git_revision', 'unknown'))[:12])}</code>.</p>")
    a(f"<div class='banner {'b-ok' if ok else 'b-bad'}' id='overall'>{_e(run.coverage())}</div>")
    if run.notes:
        a("<ul class='notes'>" + "".join(f"<li>{_e(n)}</li>" for n in run.notes) + "</ul>")
    _html_verdicts(run, h)
    _html_attention(run, h)
    _html_scenes(run, h)
    _html_provenance(run, h)
    return "\n".join(h)


def _html_verdicts(run: Run, h: list[str]) -> None:
    """The summary matrix: a row per scene, a column per simulator, the totals and the statuses' legend."""
    a = h.append
    a("<h2>Verdicts</h2>")
    a("<table id='verdicts'><thead><tr><th>scene</th>")
    for m in run.simulators:
        a(f"<th>{_e(m)}</th>")
    a("<th>checked span</th><th>max residual</th><th>worst budget use</th><th>warnings</th></tr></thead><tbody>")
    for s in run.scene_names():
        _html_verdict_row(run, s, h)
    a("</tbody><tfoot><tr><th>total</th>")
    for m in run.simulators:
        c: dict[str, int] = {}
        for s in run.scene_names():
            if m in run.cells(s):
                v = run.verdict(run.result(s, m))
                c[v] = c.get(v, 0) + 1
        a("<td class='small'>" + _e(", ".join(f"{n} {label(k)}" for k, n in sorted(c.items(), key=lambda kv: RANK[kv[0]]))) + "</td>")
    a("<td></td><td></td><td></td><td></td></tr></tfoot></table>")
    a("<p class='small'>Statuses: <b>pass</b> every metric within its budget (the cell is amber when a "
      f"metric uses more than {WARN_USE:.0%} of its budget); <b>fail</b> a metric beyond "
      "it; <b>regression</b> a pass worse than its accepted baseline; <b>error</b> the check could not "
      "run; <b>not checked</b> the simulator cannot reproduce an element of the scene (fails the run); "
      "<b>not checked (declared)</b> the scene declares it with a reason (does not fail the run); "
      "<b>solver_only</b>: a scene no simulator document describes (a lagrangian model) is checked "
      "against a second formulation and its reference values, and its simulator cells show &mdash;. "
      "Budgets marked <i>default</i> are the documented defaults for a scene that gives none "
      "(src/scene/FORMAT.md).</p>")


def _html_verdict_row(run: Run, s: str, h: list[str]) -> None:
    """One scene's row of the summary matrix: its verdict per simulator, span, residual, budget use, warnings."""
    a = h.append
    sup = run.supplied().get(s)
    a(f"<tr><td><a href='#{_anchor(s)}'>{_e(s)}</a>"
      + (f" <span class='small'>reactions of {_e(', '.join(sup))} supplied by progmo</span>" if sup else "")
      + "</td>")
    res: list[float] = []
    use: list[float] = []
    spans: list[str] = []
    warns: set[str] = set()
    for m in run.simulators:
        if m not in run.cells(s):
            a(f"<td class='c-na' title='{_e(_na_reason(run, s, m))}'>&mdash;</td>")
            continue
        r = run.result(s, m)
        v = run.verdict(r)
        bu_cell = budget_use(r) if r is not None else None
        cell = "warn" if v == "pass" and bu_cell is not None and bu_cell > WARN_USE else v.replace(" ", "-")
        tip = f" title='worst budget use {_use_text(bu_cell)}'" if bu_cell is not None else ""
        a(f"<td class='c-{cell}'{tip}>{_badge(v)}</td>")
        if r is not None:
            mr, bu = max_residual(r), budget_use(r)
            if mr is not None:
                res.append(mr)
            if bu is not None:
                use.append(bu)
            if r.span_text():
                spans.append(r.span_text())
            warns.update(r.warnings)
    a(f"<td class='num'>{_e(' / '.join(dict.fromkeys(spans)))}</td>")
    a(f"<td class='num'>{fmt(max(res)) if res else ''}</td>")
    u = max(use) if use else None
    a(f"<td class='num'>{_bar(u)}{_use_text(u)}</td>")
    a(f"<td class='num{' warn' if warns else ''}'>{len(warns) or ''}</td></tr>")


def _html_attention(run: Run, h: list[str]) -> None:
    """The history's span (with --history) and the table of the checks that need attention."""
    a = h.append
    if run.history:
        first, last = run.history[0], run.history[-1]
        a(f"<p class='small' id='history'>History: {len(run.history)} run(s) from {_e(first.get('date'))} to "
          f"{_e(last.get('date'))}; each scene shows its metrics' trend, and a failing cell names the run "
          "its failure started.</p>")
    att = _attention(run)
    if att:
        a("<h2 id='attention'>Needs attention</h2><table><tr><th>scene</th><th>simulator</th><th>verdict</th><th>why</th></tr>")
        for s, m, v, why in att:
            a(f"<tr><td><a href='#{_anchor(s)}'>{_e(s)}</a></td><td>{_e(m)}</td><td>{_badge(v)}</td><td class='small'>{_e(why)}</td></tr>")
        a("</table>")


def _html_scenes(run: Run, h: list[str]) -> None:
    """Per scene: a folding block (open when it needs attention) with each simulator's block and the trend plot."""
    a = h.append
    a("<h2>Scenes</h2>")
    for s in run.scene_names():
        worst = RANK[run.worst(s)]
        info = run.scenes.get(s, {})
        attn = worst <= RANK["not run"]
        a(f"<details class='scene{' attn' if attn else ''}' id='{_anchor(s)}'{' open' if attn else ''}>")
        a(f"<summary><h3>{_e(s)} " + " ".join(_badge(run.verdict(run.result(s, m))) for m in run.cells(s))
          + "</h3></summary>")
        if info.get("description"):
            a(f"<p class='small'>{_e(info['description'])}</p>")
        if info.get("path"):
            a(f"<p class='small'>scene file: <code>{_e(info['path'])}</code></p>")
        for m in run.cells(s):
            a(_sim_block(run, s, m))
        if run.history and run.plots:
            budgets = {m: {b.metric: b.value for b in r.budgets}
                       for m in run.simulators if (r := run.result(s, m)) is not None}
            img = history.trend_plot(run.history, s, run.simulators, budgets)
            if img:
                a(f"<img class='plot' alt='{_e(s)} history' src='{img}'>")
        a("</details>")


def _html_provenance(run: Run, h: list[str]) -> None:
    """The footer: the rerun command, the versions and machine, where budgets and regressions come from."""
    p = run.provenance
    a = h.append
    a("<footer id='provenance'><h2>Provenance and how to rerun</h2>")
    a("<p>Rerun this check (from the repository root):</p>")
    a(f"<pre id='rerun'><code>{_e(p.get('command', ''))}</code></pre>")
    a("<table>")
    labels = [("date", "date"), ("git_revision", "git revision"), ("progmo", "progmo"), ("mujoco", "MuJoCo"),
              ("pinocchio", "Pinocchio"), ("drake", "Drake"), ("numpy", "numpy"), ("matplotlib", "matplotlib"), ("python", "Python"),
              ("platform", "platform"), ("cpu_count", "host CPUs"), ("jobs", "parallel jobs"),
              ("wall_seconds", "wall time [s]"), ("baselines", "baselines")]
    for k, name in labels:
        if k in p:
            a(f"<tr><th>{_e(name)}</th><td><code>{_e(p[k])}</code></td></tr>")
    a("</table>")
    a("<p class='small'>Budgets come from each scene's <code>[tolerances]</code> (with their reasons); "
      f"a regression is a value above max({bl.FACTOR:g} &times; baseline, baseline + floor), floor "
      + ", ".join(f"{_e(n)} {f:g}" for n, _, f in bl.CLASSES if f is not None)
      + " (references/baselines/README.md).</p>")
    a("</footer></main></body></html>")


def _sim_block(run: Run, s: str, m: str) -> str:
    r = run.result(s, m)
    v = run.verdict(r)
    h = [f"<div class='sim'><b>{_e(m)}</b> {_badge(v)}"]
    if r is None:
        h.append(" <span class='small'>not run</span></div>")
        return "".join(h)
    h.append(f" <span class='small'>{r.wall_seconds:.2f} s"
             + (f"; checked span {_e(r.span_text())}" if r.span_text() else "")
             + (f"; model: {_e(r.route)}" if r.route else "") + "</span>")
    if (s, m) in run.accepted:
        h.append(" <span class='small good'>baseline accepted by this run</span>")
    if r.reason:
        h.append(f"<div class='reason{' skip' if v == 'declared' else ''}'>{_e(r.reason)}</div>")
    for w in r.warnings:
        h.append(f"<div class='reason warnbox'>solver warning: {_e(w)}</div>")
    rows = rows_of(run, r)
    if rows:
        h.append("<table class='metrics'><tr><th>metric</th><th>value</th><th>budget</th><th>use</th>"
                 "<th>budget reason</th><th>baseline</th><th>regression above</th><th>vs baseline</th></tr>")
        for row in rows:
            wb = row["within_budget"]
            vcls = "bad" if wb is False else ""
            st = row["baseline_state"]
            scls = {"regression": "warn", "improved": "good"}.get(st, "small")
            if st == "regression" and (s, m) in run.accepted:
                st = "regression (accepted)"
            h.append(
                f"<tr><td>{_e(row['metric'])}</td><td class='num {vcls}'>{fmt(row['value'])}</td>"
                f"<td class='num'>{fmt(row['budget']) if row['budget'] is not None else ''}</td>"
                f"<td class='num'>{_bar(row['use'])}{_use_text(row['use'])}</td>"
                f"<td class='small'>{'<i>default</i> ' if row.get('budget_source') == 'default' else ''}{_e(row['budget_reason'])}</td>"
                f"<td class='num'>{fmt(row['baseline']) if row['baseline'] is not None else ''}</td>"
                f"<td class='num'>{fmt(row['threshold']) if row['threshold'] is not None else ''}</td>"
                f"<td class='{scls}'>{_e(st)}</td></tr>"
            )
        h.append("</table>")
    for b in r.breaches:
        when = f" first at t = {b.first_time:.6g} s" if b.first_time is not None else ""
        at = f" at {b.where}" if b.where else ""
        h.append(f"<div class='reason'>{_e(b.metric)} = {fmt(b.value)} exceeds its budget {fmt(b.budget)}{_e(at)}{_e(when)}</div>")
    if r.notes:
        h.append("<ul class='notes'>" + "".join(f"<li>{_e(n)}</li>" for n in r.notes) + "</ul>")
    try:
        img = plot(r) if run.plots else None
    except Exception as e:  # noqa: BLE001 - a bad series must not lose the report
        img = None
        h.append(f"<div class='reason'>plot failed: {_e(type(e).__name__)}: {_e(e)}</div>")
    if img:
        h.append(f"<img class='plot' alt='{_e(s)} / {_e(m)} series' src='{img}'>")
    h.append("</div>")
    return "".join(h)


# --- Markdown and CSV ----------------------------------------------------------------------------
def _md(s: Any) -> str:
    return str(s).replace("\\", "\\\\").replace("|", "\\|").replace("\n", " ")


def render_markdown(run: Run) -> str:
    p = run.provenance
    tot = run.totals()
    lines = [f"# progmo check: {'PASS' if run.ok() else 'FAIL'}", ""]
    lines.append(run.coverage())
    lines.append("")
    for n in run.notes:
        lines.append(f"- {_md(n)}")
    if run.notes:
        lines.append("")
    lines.append("| scene | " + " | ".join(_md(m) for m in run.simulators)
                 + " | checked span | max residual | warnings | simulators' model |")
    lines.append("|---|" + "---|" * len(run.simulators) + "---|---:|---:|---|")
    icons = {"pass": "✅", "fail": "❌", "error": "💥", "not_checked": "🚫", "declared": "⏭️",
             "regression": "📈", "not run": "⬜"}
    for s in run.scene_names():
        cells: list[str] = []
        res: list[float] = []
        spans: list[str] = []
        warns: set[str] = set()
        routes: list[str] = []
        for m in run.simulators:
            if m not in run.cells(s):
                cells.append("—")
                continue
            r = run.result(s, m)
            v = run.verdict(r)
            cells.append(f"{icons[v]} {label(v)}")
            if r is not None:
                mr = max_residual(r)
                if mr is not None:
                    res.append(mr)
                if r.span_text():
                    spans.append(r.span_text())
                warns.update(r.warnings)
                if r.route:
                    routes.append(r.route)
        sup = run.supplied().get(s)
        name = s + (f" (reactions of {', '.join(sup)} supplied by progmo)" if sup else "")
        lines.append(f"| {_md(name)} | " + " | ".join(cells) + f" | {_md(' / '.join(dict.fromkeys(spans)))} | "
                     f"{fmt(max(res)) if res else ''} | {len(warns) or ''} | {_md(' / '.join(dict.fromkeys(routes)))} |")
    declared = [(r.scene, r.simulator, r.reason) for r in run.results if run.verdict(r) == "declared"]
    if declared:
        lines += ["", "## Not checked, as declared by the scene", ""]
        lines += [f"- **{_md(s)} / {_md(m)}**: {_md(why)}" for s, m, why in declared]
    warned = {(r.scene, w) for r in run.results for w in r.warnings}
    if warned:
        lines += ["", "## Solver conditioning warnings", ""]
        lines += [f"- **{_md(s)}**: {_md(w)}" for s, w in sorted(warned)]
    att = _attention(run)
    if att:
        lines += ["", "## Needs attention", ""]
        lines += [f"- **{_md(s)} / {_md(m)}**: {v}: {_md(why)}" for s, m, v, why in att]
    lines += ["", "## Rerun", "", "```", str(p.get("command", "")), "```", "", "## Provenance", ""]
    for k in ("date", "git_revision", "progmo", "mujoco", "pinocchio", "drake", "numpy", "python", "platform", "cpu_count", "jobs"):
        if k in p:
            lines.append(f"- {k}: `{_md(p[k])}`")
    return "\n".join(lines) + "\n"


#: Text documents stay valid UTF-8 when they quote a path that is not (a command line's `--out`):
#: such bytes are written as escapes (`\udcff`).
TEXT_ERRORS = "backslashreplace"

CSV_FIELDS = ["scene", "simulator", "verdict", "status", "metric", "value", "budget", "budget_source",
              "within_budget", "baseline", "regression_above", "vs_baseline", "checked_span", "reason",
              "wall_seconds", "model"]


def write_csv(run: Run, path: Path) -> None:
    """One row per (scene, simulator, metric); a result without metrics gets one row."""
    from ._files import staged

    with staged(path, "w", newline="", encoding="utf-8", errors=TEXT_ERRORS) as f:
        w = csv.writer(f)
        w.writerow(CSV_FIELDS)
        for s in run.scene_names():
            for m in run.cells(s):
                r = run.result(s, m)
                v = run.verdict(r)
                if r is None:
                    w.writerow([s, m, v, "", "", "", "", "", "", "", "", "", "", "not run", "", ""])
                    continue
                base = [s, m, v, r.status]
                tail = [r.span_text(), r.reason, f"{r.wall_seconds:.3f}", r.route]
                rows = rows_of(run, r)
                if not rows:
                    w.writerow(base + [""] * 8 + tail)
                for row in rows:
                    w.writerow(base + [
                        row["metric"], _csvnum(row["value"]), _csvnum(row["budget"]), row["budget_source"],
                        "" if row["within_budget"] is None else str(row["within_budget"]).lower(),
                        _csvnum(row["baseline"]), _csvnum(row["threshold"]), row["baseline_state"],
                    ] + tail)


def _csvnum(v: Any) -> str:
    return "" if v is None else repr(float(v))


def write(run: Run, out_dir: str | os.PathLike) -> dict[str, Path]:
    """Write report.html, summary.md, summary.csv and run.json into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "html": out / "report.html",
        "md": out / "summary.md",
        "csv": out / "summary.csv",
        "run": out / "run.json",
    }
    from ._files import write_text

    # each file whole under its name, or `.partial` and WriteFailed (a full device: exit 3)
    write_text(paths["run"], json.dumps(_jsonable(run.to_json()), indent=1) + "\n")
    write_text(paths["md"], render_markdown(run), errors=TEXT_ERRORS)
    write_csv(run, paths["csv"])
    write_text(paths["html"], render_html(run), errors=TEXT_ERRORS)
    return paths


def _jsonable(x: Any) -> Any:
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    return x


def comparisons_as_dicts(comps: list[bl.Comparison]) -> list[dict[str, Any]]:
    return [asdict(c) for c in comps]


if __name__ == "__main__":  # pragma: no cover
    sys.exit("use: python -m progmo.cli report OUT_DIR")
