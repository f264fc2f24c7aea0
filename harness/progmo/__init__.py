"""progmo: programmed motions of mechanical systems (Do Sanh 1998) and the control forces that
realize them, computed by the Rust core and proven by replaying the forces open-loop in MuJoCo and
Pinocchio.

    import progmo
    scene = progmo.load("double_pendulum")          # a bundled scene name or a scene file
    sol = scene.solve(rtol=1e-10)                   # overrides in the scene file's vocabulary
    sol.t, sol.q, sol.u                             # numpy arrays (n,), (n, nq), (n, nv)
    result = progmo.check(scene, "mujoco")          # CheckResult: status, metrics, budgets, reason
    mjcf, report = progmo.export(scene, "mjcf")

The command line is ``progmo`` (``progmo --help``); the scene format is src/scene/FORMAT.md.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Literal

from . import data
from ._core import (
    DRIFTS,
    FORMULATIONS,
    INTEGRATORS,
    ExportUnsupported,
    SceneError,
    SettingsError,
    Solution,
    SolveStopped,
    version,
)
from ._core import Scene as Scene
from .results import Budget, CheckResult

data.export_robot_path()  # package:// robot files (example-robot-data) for the Rust core

__version__ = version()

__all__ = [
    "DRIFTS", "FORMULATIONS", "INTEGRATORS", "Budget", "CheckResult", "ExportUnsupported",
    "Scene", "SceneError", "SettingsError", "Solution", "SolveStopped", "check", "export", "load",
    "version",
]


def load(name_or_path: str | os.PathLike[str]) -> Scene:
    """Load a scene: a scene file (TOML), or the name of a bundled scene (``progmo.data
    .bundled_scenes()``), from any directory. Raises SceneError with a located message. The robot
    file a scene names must lie inside the scene's folder, its ``package://`` package or a folder
    of ``$PROGMO_ALLOW_ROOTS`` (src/scene/FORMAT.md, "Files a scene reads")."""
    return Scene(str(data.scene_file(name_or_path)))


def _scene(scene: Scene | str | os.PathLike[str]) -> Scene:
    return scene if isinstance(scene, Scene) else load(scene)


def check(scene: Scene | str | os.PathLike[str],
          simulator: Literal["mujoco", "pinocchio", "solver_only"] = "mujoco",
          *, step: float | None = None, horizon: float | None = None, samples: int = 8,
          baselines: str | os.PathLike[str] | None = None) -> CheckResult:
    """Replay the scene's control forces open-loop in ``simulator`` and judge every metric against
    its budget (the nightly check of one pair); ``"solver_only"`` compares two formulations and the
    scene's ``[[reference]]`` values instead (how a lagrangian scene is checked). ``step``/``horizon``/``samples`` as in ``progmo
    check``. With ``baselines`` (a folder of accepted baselines, e.g. ``progmo.data.baselines_dir()``;
    None: no comparison), a pass worse than its baseline has the status ``regression`` (the verdict
    ``progmo check`` gives it: ``verdict.cell_verdict``) and a ``reason`` naming the regressed
    metrics. Never raises for a failing scene: ``status`` says what happened; bad options raise
    SettingsError with the message of ``progmo check`` (``step: must be a finite number > 0, got 0``)."""
    from . import baselines as bl
    from .checks import CHECKERS, CheckOptions, run_check
    from .verdict import cell_verdict

    if simulator not in CHECKERS:
        raise ValueError(f"unknown simulator {simulator!r} (one of {', '.join(CHECKERS)})")
    options = CheckOptions(step=step, horizon=horizon, samples=samples)
    problem = options.problem()  # the check of `progmo check --step/--horizon/--samples`
    if problem is not None:
        raise SettingsError(problem)
    sc = _scene(scene)
    r = run_check(sc.path, simulator, options)
    if baselines is not None and r.status == "pass":
        worse = bl.regressions(bl.compare(r, bl.load(Path(baselines), r.scene, r.simulator)))
        r.status = cell_verdict(r, regressed=bool(worse))
        if worse:
            r.reason = "regression against the baseline: " + "; ".join(
                f"{c.metric} {c.value} > {c.threshold} (baseline {c.baseline})" for c in worse)
    return r


def export(scene: Scene | str | os.PathLike[str], format: Literal["mjcf", "urdf"] = "mjcf",
           *, timestep: float = 1e-3) -> tuple[str, dict[str, Any]]:
    """The scene's model as an MJCF or URDF document and the export report (mass floors, forces the
    harness applies, q/v maps). Raises ExportUnsupported naming an element no simulator would
    enforce."""
    return _scene(scene).export(format, timestep=timestep)
