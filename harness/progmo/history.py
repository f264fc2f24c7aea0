"""Nightly history: ``progmo check --history DIR`` keeps one record per run, and the report draws
each metric's trend over the nights and names the night a failure or regression started.

A record is ``DIR/<UTC date>_<revision>.json`` (format 1)::

    {"format": 1, "date": "2026-11-23 02:00:11 UTC", "git_revision": "...", "progmo": "0.1.0",
     "mujoco": "4.0.0", "pinocchio": "4.1.0",
     "cells": {"<scene>/<simulator>": {"verdict": "pass", "metrics": {"replay_residual": 1.3e-12, ...}}}}

Only the last ``KEEP`` records are read (older ones stay on disk). A file that is not a record is
named in the report's notes, never silently skipped.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .verdict import Run

FORMAT = 1
KEEP = 60
#: Verdicts that do not fail the nightly job (a streak of any other verdict is a failure streak).
OK = ("pass", "declared")


def record(run: "Run") -> dict[str, Any]:
    """The history record of a run."""
    p = run.provenance
    cells = {}
    for r in run.results:
        cells[f"{r.scene}/{r.simulator}"] = {
            "verdict": run.verdict(r),
            "metrics": {k: (v if v is not None and math.isfinite(v) else None) for k, v in r.metrics.items()},
        }
    keep = ("date", "git_revision", "progmo", "mujoco", "pinocchio", "drake")
    return {"format": FORMAT, **{k: p.get(k) for k in keep}, "cells": cells}


def save(run: "Run", directory: str | Path) -> Path:
    """Write the run's record into ``directory`` (created if needed); returns its path."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    rec = record(run)
    stamp = re.sub(r"[^0-9]", "", str(rec.get("date") or ""))[:14] or "undated"
    rev = re.sub(r"[^A-Za-z0-9]", "", str(rec.get("git_revision") or "unknown"))[:12]
    path = d / f"{stamp}_{rev}.json"
    k = 1
    while path.exists():  # two runs in the same second: keep both
        path = d / f"{stamp}_{rev}_{k}.json"
        k += 1
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(rec, indent=1) + "\n")
    tmp.replace(path)
    return path


def load(directory: str | Path) -> tuple[list[dict[str, Any]], list[str]]:
    """The last KEEP records of ``directory``, oldest first, and the problems met (unreadable files)."""
    d = Path(directory)
    recs, problems = [], []
    for f in sorted(d.glob("*.json")):
        try:
            rec = json.loads(f.read_text())
            if rec.get("format") != FORMAT or not isinstance(rec.get("cells"), dict):
                raise ValueError("not a history record of format 1")
            rec["file"] = f.name
            recs.append(rec)
        except (OSError, ValueError, AttributeError) as e:
            problems.append(f"history: {f}: skipped, {e}")
    recs.sort(key=lambda r: (str(r.get("date") or ""), r["file"]))
    return recs[-KEEP:], problems


def streak_start(records: list[dict[str, Any]], cell: str) -> dict[str, Any] | None:
    """The first record of the current streak of failing verdicts of ``cell`` (None when its last
    verdict is OK or it has no history)."""
    start = None
    for rec in reversed(records):
        c = rec["cells"].get(cell)
        if c is None or c.get("verdict") in OK:
            break
        start = rec
    return start


def series(records: list[dict[str, Any]], cell: str) -> dict[str, list[float | None]]:
    """metric -> value per record (None where absent or not finite)."""
    names: list[str] = []
    for rec in records:
        for m in rec["cells"].get(cell, {}).get("metrics", {}):
            if m not in names:
                names.append(m)
    return {m: [rec["cells"].get(cell, {}).get("metrics", {}).get(m) for rec in records] for m in names}


def trend_plot(records: list[dict[str, Any]], scene: str, simulators: list[str],
               budgets: dict[str, dict[str, float]]) -> str | None:
    """One PNG (data URI) per scene: each judged metric over the nights, one panel per simulator,
    log scale, budgets dashed, failing nights marked. None with fewer than two records."""
    if len(records) < 2:
        return None
    import base64
    import io

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    sims = [m for m in simulators if any(f"{scene}/{m}" in r["cells"] for r in records)]
    if not sims:
        return None
    fig = Figure(figsize=(3.9 * len(sims), 2.4), dpi=90)
    FigureCanvasAgg(fig)
    fig.subplots_adjust(left=0.1, right=0.98, bottom=0.22, top=0.88, wspace=0.3)
    axes = fig.subplots(1, len(sims), squeeze=False)[0]
    x = list(range(len(records)))
    labels = [str(r.get("date") or "")[5:10] for r in records]
    for ax, m in zip(axes, sims):
        cell = f"{scene}/{m}"
        for name, vals in series(records, cell).items():
            if name not in budgets.get(m, {}):
                continue  # information metrics have no trend worth judging
            y = [v if v is not None and v > 0 else math.nan for v in vals]
            ax.plot(x, y, marker="o", ms=2.5, lw=1, label=name)
        for i, rec in enumerate(records):
            v = rec["cells"].get(cell, {}).get("verdict")
            if v is not None and v not in OK:
                ax.axvline(i, color="#c0392b", alpha=0.25, lw=4)
        ax.set_yscale("log")
        ax.set_title(f"{m}: metrics over the last {len(records)} runs", fontsize=8.5)
        step = max(1, len(x) // 8)
        ax.set_xticks(x[::step], labels[::step], fontsize=7)
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=6, frameon=False, loc="upper left")
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")
