"""The data contract between the checks, the baselines, the report and the debugging runs.

A nightly check produces one :class:`CheckResult` per (scene, simulator). Everything is plain data
(numbers, strings, lists) so a result serializes to JSON (``to_json``/``from_json``) and the report
can be rebuilt from saved results.

Statuses (``status``); the verdict (``verdict.cell_verdict``) adds ``regression`` (a pass worse than
its baseline), which ``progmo.check(..., baselines=...)`` returns as the status:

* ``pass``: every budgeted metric within its budget (every metric has one: the scene's, or the
  documented default of ``checks.default_budgets``);
* ``fail``: at least one metric beyond its budget (``breaches`` says which, by how much, and when);
* ``not_checked``: the simulator cannot reproduce the scene (``reason`` names the element: a
  lagrangian model, system constraints, a force the back-end cannot apply). A failure of the run
  unless the scene declares it (``[checks] not_checked``, then ``expected`` is true and ``reason``
  quotes the declaration);
* ``error``: the check itself could not run (missing package, a solve that stopped, a simulator
  that blew up): a failure of the run, with ``reason``.

``span`` is the replayed time span against the scene's (the whole span, in segments for an unstable
programme; shorter only when a run asks for it with ``--horizon`` or the replay blew up, and then
visible in every verdict); ``warnings`` are the solver's conditioning warnings on the reference solve;
``supplied`` names the system rows whose reactions progmo supplied to the simulator (visible in the
report row and the summary line).
"""

from __future__ import annotations

import dataclasses
import json
import math
import textwrap
from dataclasses import dataclass, field
from typing import Any

STATUSES = ("pass", "fail", "not_checked", "error")
#: The checker of a scene no simulator document describes (a lagrangian model): a second
#: formulation and the scene's reference values instead of a replay (``checks._solver_only``).
SOLVER_ONLY = "solver_only"


@dataclass
class Budget:
    """A cross-simulator tolerance: a metric must stay at or below ``value``."""

    metric: str
    value: float
    reason: str
    #: "scene" (the scene's [tolerances]) or "default" (checks.default_budgets)
    source: str = "scene"


@dataclass
class Breach:
    """A metric beyond its budget: the first time it happened, the worst value, and the element
    it comes from (``where``: "joint q2", "entry (q1, q2)", "closure loop", "row p1", ... set by the
    check's attribution, ``attribution.py``; "" when nothing singles one out)."""

    metric: str
    value: float
    budget: float
    first_time: float | None = None
    where: str = ""

    def text(self, fmt: Any = None) -> str:
        """"replay_deviation 3e-06 > 1e-06 at coordinate q2 first at t = 0.41" (``fmt`` formats
        the numbers; default ``.3g``)."""
        f = fmt or (lambda x: f"{x:.3g}")
        return (f"{self.metric} {f(self.value)} > {f(self.budget)}"
                + (f" at {self.where}" if self.where else "")
                + (f" first at t = {self.first_time:.6g}" if self.first_time is not None else ""))


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
    simulator: str  # "mujoco", "pinocchio" or "solver_only"
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
    #: not_checked declared by the scene ([checks] not_checked): does not fail the run
    expected: bool = False
    #: [replayed span, scene span] in seconds (None before the replay horizon is known)
    span: list[float] | None = None
    #: conditioning warnings of the reference solve (sentences with time and rows)
    warnings: list[str] = field(default_factory=list)
    #: facts that are not judged (replay step, growth rate of the open-loop deviation, ...)
    info: dict[str, float] = field(default_factory=dict)
    #: where the simulator's model came from: "user's file" (the scene's URDF/MJCF read by the
    #: simulator itself), "progmo export" (progmo's MJCF/URDF of its model), "" (not built)
    route: str = ""
    #: system rows the simulator's model leaves out, their reactions supplied by progmo (applied
    #: forces from the reference solve; ``checks._supplied_route``): shown in the report row and
    #: the summary line
    supplied: list[str] = field(default_factory=list)

    def ok(self) -> bool:
        """True unless the nightly job must fail on this result."""
        return self.status == "pass" or (self.status == "not_checked" and self.expected)

    def span_text(self) -> str:
        """"1 of 2 s" (or "" when unknown)."""
        if not self.span:
            return ""
        a, b = self.span
        return f"{a:g} s" if abs(a - b) <= 1e-12 * max(1.0, abs(b)) else f"{a:g} of {b:g} s"

    def to_json(self) -> dict[str, Any]:
        return _clean(dataclasses.asdict(self))

    @staticmethod
    def from_json(d: dict[str, Any]) -> "CheckResult":
        d = dict(d)
        d["budgets"] = [Budget(**b) for b in d.get("budgets", [])]
        d["breaches"] = [Breach(**b) for b in d.get("breaches", [])]
        d["series"] = [Series(**s) for s in d.get("series", [])]
        if d.get("status") == "skipped":  # results saved before not_checked existed
            d["status"] = "not_checked"
        return CheckResult(**d)


def judge(result: CheckResult, first_times: dict[str, float] | None = None) -> CheckResult:
    """Set ``status`` and ``breaches`` of ``result`` from its metrics and budgets (a metric that is
    missing or NaN breaches its budget: a check that produced no number did not pass)."""
    if result.status in ("not_checked", "error"):
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


def save(results: list[CheckResult], path: str, encoded: dict[int, str] | None = None) -> None:
    """Whole under ``path``, or ``path.partial`` and :class:`progmo._files.WriteFailed`. The text is
    ``json.dump(..., indent=1)``'s; ``encoded`` keeps each result's text by ``id`` between saves of
    a growing list (a run saves after every check: without it the run is quadratic in its checks),
    so a result must not change once it is in ``encoded``."""
    from ._files import staged

    def text(r: CheckResult) -> str:
        if encoded is None:
            return _encode(r)
        if id(r) not in encoded:
            encoded[id(r)] = _encode(r)
        return encoded[id(r)]

    body = ",\n".join(text(r) for r in results)
    with staged(path, "w") as f:
        f.write(f"[\n{body}\n]\n" if results else "[]\n")


def _encode(r: CheckResult) -> str:
    """One result as an element of ``json.dump(list, indent=1)``: its lines one space in."""
    return textwrap.indent(json.dumps(r.to_json(), indent=1), " ")


def load(path: str) -> list[CheckResult]:
    with open(path) as f:
        return [CheckResult.from_json(d) for d in json.load(f)]
