"""The verdict of a check, decided once: :func:`cell_verdict` for one (scene x checker) and
:class:`Run` for a whole run (the counts, ``ok``, the coverage line). ``progmo check`` and its
report, the history and ``progmo.check`` all read them, so a regression has one status at every door.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from .results import SOLVER_ONLY, CheckResult


def cell_verdict(r: CheckResult, regressed: bool, accepted: bool = False) -> str:
    """A result's verdict: its status, ``regression`` for a pass worse than its accepted baseline
    (unless this run accepted it), ``declared`` for a not_checked the scene declares."""
    if r.status == "pass" and regressed and not accepted:
        return "regression"
    if r.status == "not_checked" and r.expected:
        return "declared"
    return r.status


#: Verdicts in order of attention, the first problems first. ``not_checked`` is a simulator that
#: could not reproduce the scene (fails the run); ``declared`` a not_checked the scene declares.
RANK = {"error": 0, "fail": 1, "regression": 2, "not_checked": 3, "not run": 4, "pass": 5, "declared": 6}
#: verdicts that do not fail a run
OK_VERDICTS = ("pass", "declared")
#: how a verdict reads
LABEL = {"not_checked": "not checked", "declared": "not checked (declared)"}


def label(verdict: str) -> str:
    return LABEL.get(verdict, verdict)


@dataclass
class Run:
    """Everything the report shows besides the results themselves."""

    results: list[CheckResult]
    simulators: list[str]
    provenance: dict[str, Any]
    #: (scene, simulator) -> comparisons against the baseline, as dicts (``baselines.Comparison``).
    comparisons: dict[tuple[str, str], list[dict[str, Any]]] = field(default_factory=dict)
    #: scene -> {"path", "description", "purpose"} of the scenes asked for (also the unrun ones).
    scenes: dict[str, dict[str, str]] = field(default_factory=dict)
    #: Facts about the run as a whole (interrupted, load errors, accepted baselines ...).
    notes: list[str] = field(default_factory=list)
    #: (scene, simulator) pairs whose baseline this run accepted (--accept).
    accepted: list[tuple[str, str]] = field(default_factory=list)
    #: Draw the series (the slow part of the report: about 0.5 s per result).
    plots: bool = True
    #: Records of earlier runs and this one (``history.load``, oldest first) when --history is given.
    history: list[dict[str, Any]] = field(default_factory=list)
    #: The (scene, checker) cells this run scheduled; empty: every scene x simulator. A lagrangian
    #: scene is scheduled as one ``solver_only`` cell, and its simulator cells do not apply.
    planned: list[tuple[str, str]] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {
            "simulators": self.simulators,
            "provenance": self.provenance,
            "comparisons": [
                {"scene": s, "simulator": m, "metrics": c} for (s, m), c in self.comparisons.items()
            ],
            "scenes": self.scenes,
            "notes": self.notes,
            "accepted": [list(p) for p in self.accepted],
            "plots": self.plots,
            "history": self.history,
            "planned": [list(p) for p in self.planned],
        }

    @staticmethod
    def from_json(d: dict[str, Any], results: list[CheckResult]) -> "Run":
        return Run(
            results=results,
            simulators=d.get("simulators", []),
            provenance=d.get("provenance", {}),
            comparisons={(c["scene"], c["simulator"]): c["metrics"] for c in d.get("comparisons", [])},
            scenes=d.get("scenes", {}),
            notes=d.get("notes", []),
            accepted=[tuple(p) for p in d.get("accepted", [])],
            plots=d.get("plots", True),
            history=d.get("history", []),
            planned=[tuple(p) for p in d.get("planned", [])],
        )

    # --- derived views -------------------------------------------------------------------------
    def result(self, scene: str, sim: str) -> CheckResult | None:
        for r in self.results:
            if r.scene == scene and r.simulator == sim:
                return r
        return None

    def regressed(self, r: CheckResult) -> list[dict[str, Any]]:
        return [c for c in self.comparisons.get((r.scene, r.simulator), []) if c["state"] == "regression"]

    def verdict(self, r: CheckResult | None) -> str:
        """The cell's verdict (:func:`cell_verdict`), ``not run`` without a result."""
        if r is None:
            return "not run"
        return cell_verdict(r, bool(self.regressed(r)), (r.scene, r.simulator) in self.accepted)

    def cells(self, scene: str) -> list[str]:
        """The checkers (simulators, ``solver_only``) whose cell applies to ``scene``: planned by the
        run or holding a result."""
        planned = set(self.planned)
        return [m for m in self.simulators
                if not planned or (scene, m) in planned or self.result(scene, m) is not None]

    def worst(self, scene: str) -> str:
        """The scene's verdict that needs the most attention."""
        return min((self.verdict(self.result(scene, m)) for m in self.cells(scene)),
                   key=lambda v: RANK[v], default="not run")

    def scene_names(self) -> list[str]:
        names = list(dict.fromkeys([*self.scenes, *(r.scene for r in self.results)]))
        return sorted(names, key=lambda s: (RANK[self.worst(s)], s))

    def totals(self) -> dict[str, int]:
        t = {k: 0 for k in RANK}
        for s in self.scene_names():
            for m in self.cells(s):
                t[self.verdict(self.result(s, m))] += 1
        return t

    def ok(self) -> bool:
        t = self.totals()
        checked = t["pass"] > 0  # a run that checked nothing proves nothing
        return checked and all(n == 0 for k, n in t.items() if k not in OK_VERDICTS)

    def supplied(self) -> dict[str, list[str]]:
        """Scenes whose checks received the reactions of rows the simulator's model leaves out
        (``CheckResult.supplied``), with the rows."""
        out: dict[str, list[str]] = {}
        for r in self.results:
            if r.supplied:
                out.setdefault(r.scene, [])
                out[r.scene] += [x for x in r.supplied if x not in out[r.scene]]
        return out

    def coverage(self) -> str:
        """What the verdict covers, in one line: counts of every (scene x simulator) cell, the
        declared not_checked cells, shortened replay spans (``--horizon``), segmented replays and
        conditioning warnings."""
        t = self.totals()
        cells = sum(t.values())
        head = ("PASS" if self.ok() else "FAIL") + f": {t['pass']} of {cells} (scene x simulator) passed"
        rest = [f"{n} {label(k)}" for k, n in t.items() if n and k not in ("pass", "declared")]
        solver_only = [s for s in self.scene_names() if SOLVER_ONLY in self.cells(s)]
        if solver_only:
            rest.append(f"{len(solver_only)} checked solver-only, no simulator model "
                        f"({', '.join(solver_only)})")
        declared = [f"{r.scene}/{r.simulator}" for r in self.results if self.verdict(r) == "declared"]
        if declared:
            rest.append(f"{len(declared)} not checked as declared ({', '.join(declared)})")
        short = sorted({f"{r.scene} {r.span_text()}" for r in self.results
                        if r.span and r.span[0] < r.span[1] and r.status in ("pass", "fail")})
        if short:  # only a run asked for it (`progmo check --horizon`): a scene's check covers its span
            rest.append("replayed over a shortened span: " + ", ".join(short))
        segmented = sorted({f"{r.scene} ({r.info['replay_segments']:g})" for r in self.results
                            if r.info.get("replay_segments", 1) > 1 and r.status in ("pass", "fail")})
        if segmented:
            from .checks import SEGMENT_GROWTH

            rest.append(f"replayed in segments restarted from the solver (open-loop growth beyond "
                        f"x{SEGMENT_GROWTH:g}): " + ", ".join(segmented))
        supplied = self.supplied()
        if supplied:
            rest.append("reactions supplied by progmo for rows no simulator holds: " + ", ".join(
                f"{s} ({', '.join(rows)})" for s, rows in supplied.items()))
        warned = sorted({r.scene for r in self.results if r.warnings})
        if warned:
            rest.append("solver conditioning warnings: " + ", ".join(warned))
        if not t["pass"]:
            rest.append("nothing was checked")
        return head + ("; " + "; ".join(rest) if rest else "")
