"""The data contract between the checks, the baselines, the report and the debugging runs.

A nightly check produces one :class:`CheckResult` per (scene, simulator). Everything is plain data
(numbers, strings, lists) so a result serializes to JSON (``to_json``/``from_json``) and the report
can be rebuilt from saved results.

Verdicts (``status``):

* ``pass``: every metric within its budget;
* ``fail``: at least one metric beyond its budget (``breaches`` says which, by how much, and when);
* ``skipped``: the simulator cannot represent the scene (``reason`` says why) — not a failure;
* ``error``: the check itself could not run (missing package, simulator blew up): a failure of the
  nightly job, with ``reason``.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from typing import Any

STATUSES = ("pass", "fail", "skipped", "error")


@dataclass
class Budget:
    """A cross-simulator tolerance: a metric must stay at or below ``value``."""

    metric: str
    value: float
    reason: str


@dataclass
class Breach:
    """A metric beyond its budget: the first time it happened and the worst value."""

    metric: str
    value: float
    budget: float
    first_time: float | None = None


@dataclass
class Series:
    """A time series for plots: ``values`` has one entry per time in ``t``."""

    name: str
    t: list[float]
    values: list[float]
    unit: str = ""


@dataclass
class CheckResult:
    """Outcome of checking one scene in one simulator."""

    scene: str
    simulator: str  # "mujoco" or "pinocchio"
    status: str  # one of STATUSES
    reason: str = ""
    #: Scalar metrics, e.g. parity_mass, parity_bias, replay_residual, replay_deviation,
    #: replay_growth_rate, instant_u (relative), solver_residual.
    metrics: dict[str, float] = field(default_factory=dict)
    budgets: list[Budget] = field(default_factory=list)
    breaches: list[Breach] = field(default_factory=list)
    #: Series for plots: programme residual of the replay, deviation from the solver's trajectory,
    #: control forces (one series per component) ...
    series: list[Series] = field(default_factory=list)
    #: Free-form facts worth printing (step used, export adjustments, versions of simulators).
    notes: list[str] = field(default_factory=list)
    wall_seconds: float = 0.0

    def ok(self) -> bool:
        """True unless the nightly job must fail on this result."""
        return self.status in ("pass", "skipped")

    def to_json(self) -> dict[str, Any]:
        return _clean(dataclasses.asdict(self))

    @staticmethod
    def from_json(d: dict[str, Any]) -> "CheckResult":
        d = dict(d)
        d["budgets"] = [Budget(**b) for b in d.get("budgets", [])]
        d["breaches"] = [Breach(**b) for b in d.get("breaches", [])]
        d["series"] = [Series(**s) for s in d.get("series", [])]
        return CheckResult(**d)


def judge(result: CheckResult, first_times: dict[str, float] | None = None) -> CheckResult:
    """Set ``status`` and ``breaches`` of ``result`` from its metrics and budgets (a metric that is
    missing or NaN breaches its budget: a check that produced no number did not pass)."""
    if result.status in ("skipped", "error"):
        return result
    result.breaches = []
    for b in result.budgets:
        v = result.metrics.get(b.metric, math.nan)
        if not (v <= b.value):
            result.breaches.append(
                Breach(b.metric, v, b.value, (first_times or {}).get(b.metric))
            )
    result.status = "fail" if result.breaches else "pass"
    return result


def _clean(x: Any) -> Any:
    """JSON-safe: NaN and infinities become None."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    return x


def save(results: list[CheckResult], path: str) -> None:
    with open(path, "w") as f:
        json.dump([r.to_json() for r in results], f, indent=1)
        f.write("\n")


def load(path: str) -> list[CheckResult]:
    with open(path) as f:
        return [CheckResult.from_json(d) for d in json.load(f)]
