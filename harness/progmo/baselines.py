"""Accepted baselines and regression detection.

A baseline is the metrics of one accepted ``pass`` run of one (scene, simulator), stored as
``references/baselines/<scene>.<simulator>.json`` (format: ``references/baselines/README.md``).

A **regression** is a lower-is-better metric that grew beyond its baseline by more than the margin

    value > max(FACTOR * baseline, baseline + floor(metric class))          (FACTOR = 10)

or that became NaN/missing while the baseline had a number. The relative part (one order of
magnitude) ignores the normal jitter of integrated errors across machines and library versions
(factors of 2-3) but catches a lost order or a broken feature; the absolute floor keeps
round-off-level values (1e-16 .. 1e-13, which jitter by factors of 10-100 when summation order or
BLAS changes) from flagging. Floors per class:

* ``algebraic`` (``parity_*``, ``instant_*``, ``inverse_*``): identities evaluated at single states; floor 1e-12
  (about 5e3 machine epsilons, above the 1e-13 seen on a 30-link chain's mass matrix);
* ``integrated`` (names containing ``residual``, ``deviation``, ``error``, ``drift``): accumulated
  over thousands of steps (round-off about sqrt(N) eps, 1e-13 .. 1e-12); floor 1e-11;
* ``info``: any other metric (growth rates, counts, steps): recorded and shown, never judged, as
  "lower is better" does not hold for it.

Budgets (``results.judge``) say whether a run is acceptable at all; baselines say whether it got
worse than what was accepted. Both are reported; either fails the nightly job.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .results import CheckResult

FORMAT = 1
FACTOR = 10.0
#: Metric classes: (name, pattern on the metric name, absolute floor or None when not judged).
CLASSES: list[tuple[str, str, float | None]] = [
    ("algebraic", r"^(parity|instant|inverse)", 1e-12),
    ("integrated", r"residual|deviation|error|drift", 1e-11),
    ("info", r"", None),
]


def metric_class(metric: str) -> tuple[str, float | None]:
    """The class of a metric and its absolute floor (None: informational, never a regression)."""
    for name, pattern, floor in CLASSES:
        if re.search(pattern, metric):
            return name, floor
    return "info", None  # pragma: no cover (the last pattern matches everything)


def threshold(metric: str, baseline: float) -> float | None:
    """The largest value of ``metric`` that is not a regression against ``baseline``."""
    _, floor = metric_class(metric)
    if floor is None or baseline is None or not math.isfinite(baseline):
        return None
    return max(FACTOR * baseline, baseline + floor)


@dataclass
class Comparison:
    """One metric of a result against its baseline.

    ``state``: ``new`` (no baseline value), ``ok``, ``regression``, ``improved`` (below a tenth
    of the baseline and beyond the floor: worth accepting), ``info`` (not judged)."""

    metric: str
    value: float | None
    baseline: float | None
    threshold: float | None
    state: str


def _num(x: Any) -> float | None:
    return None if x is None else float(x)


def compare(result: CheckResult, baseline: dict[str, Any] | None) -> list[Comparison]:
    """Compare every metric of ``result`` (and every metric of the baseline) with the baseline.
    Results that are not ``pass``/``fail`` have no comparable metrics: an empty list."""
    if result.status not in ("pass", "fail"):
        return []
    base = (baseline or {}).get("metrics", {})
    out = []
    for m in list(result.metrics) + [m for m in base if m not in result.metrics]:
        v = _num(result.metrics.get(m))
        b = _num(base.get(m))
        _, floor = metric_class(m)
        thr = threshold(m, b) if b is not None else None
        if floor is None:
            state = "info"
        elif b is None or not math.isfinite(b):
            state = "new"
        elif v is None or not math.isfinite(v) or thr is None or v > thr:
            state = "regression"
        elif v * FACTOR < b and b - v > floor:
            state = "improved"
        else:
            state = "ok"
        out.append(Comparison(m, v, b, thr, state))
    return out


#: Versions a baseline records and a check compares (a different one is said in the report).
VERSIONED = ("progmo", "mujoco", "pinocchio")
#: a simulator added later is compared only in its own baselines (older ones never recorded it)
VERSIONED_OWN = ("drake",)


def version_differences(baseline: dict[str, Any] | None, provenance: dict[str, Any],
                        simulator: str = "") -> list[str]:
    """``"mujoco 3.9.0 (now 4.0.0)"`` for every versioned package the baseline was accepted with
    that differs from this run's (a baseline without the record says so); ``simulator``'s own
    package too when it is in :data:`VERSIONED_OWN` (Drake)."""
    if baseline is None:
        return []
    acc = baseline.get("accepted") or {}
    out = []
    for k in VERSIONED + tuple(k for k in VERSIONED_OWN if k == simulator):
        if k not in acc:
            out.append(f"{k} not recorded (now {provenance.get(k, '?')})")
        elif str(acc[k]) != str(provenance.get(k)):
            out.append(f"{k} {acc[k]} (now {provenance.get(k, '?')})")
    return out


def regressions(comparisons: list[Comparison]) -> list[Comparison]:
    return [c for c in comparisons if c.state == "regression"]


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]", "_", name)


def path_for(directory: str | os.PathLike, scene: str, simulator: str) -> Path:
    """``<directory>/<scene>.<simulator>.json`` (characters unsafe in file names become ``_``)."""
    return Path(directory) / f"{_safe(scene)}.{_safe(simulator)}.json"


def load(directory: str | os.PathLike, scene: str, simulator: str) -> dict[str, Any] | None:
    """The baseline of (scene, simulator), or None if there is none. A file that is not a valid
    baseline raises ValueError naming the file."""
    p = path_for(directory, scene, simulator)
    if not p.is_file():
        return None
    try:
        d = json.loads(p.read_text())
        if not isinstance(d.get("metrics"), dict):
            raise ValueError("no 'metrics' object")
        return d
    except (ValueError, AttributeError) as e:
        raise ValueError(f"{p}: not a valid baseline ({e})") from e


def make(result: CheckResult, provenance: dict[str, Any]) -> dict[str, Any]:
    """The baseline document of an accepted result."""
    return {
        "format": FORMAT,
        "scene": result.scene,
        "simulator": result.simulator,
        "metrics": {k: (v if v is None or math.isfinite(v) else None) for k, v in sorted(result.metrics.items())},
        "budgets": {b.metric: b.value for b in result.budgets},
        "accepted": provenance,
    }


def accept(
    directory: str | os.PathLike, result: CheckResult, provenance: dict[str, Any]
) -> tuple[Path, list[str]] | None:
    """Write the baseline of a ``pass`` result; returns (path, lines describing what changed), or
    None (nothing written) for any other status."""
    if result.status != "pass":
        return None
    old = load(directory, result.scene, result.simulator)
    doc = make(result, provenance)
    old_m = (old or {}).get("metrics", {})
    changes = []
    for m, v in doc["metrics"].items():
        if m not in old_m:
            changes.append(f"{m}: new {_fmt(v)}")
        elif old_m[m] != v:
            changes.append(f"{m}: {_fmt(old_m[m])} -> {_fmt(v)}")
    changes += [f"{m}: removed (was {_fmt(old_m[m])})" for m in old_m if m not in doc["metrics"]]
    p = path_for(directory, result.scene, result.simulator)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(doc, indent=1) + "\n")
    tmp.replace(p)
    return p, changes


def _fmt(v: Any) -> str:
    return "NaN" if v is None else f"{v:.3g}"
