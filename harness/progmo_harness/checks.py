"""Per-scene, per-simulator checks: model parity, open-loop replay of u(t), instantaneous u.

Interface used by the nightly command (``cli.py``) and the report:

``run_check(scene_path, simulator, options) -> CheckResult`` where ``simulator`` is ``"mujoco"`` or
``"pinocchio"``; it never raises for a scene or simulator problem: a scene the simulator cannot
represent gives ``status="skipped"`` with the reason, a missing package or a simulator failure gives
``status="error"`` with the reason (see ``results.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

from .results import CheckResult

SIMULATORS = ("mujoco", "pinocchio")


@dataclass
class CheckOptions:
    """How a check runs. Defaults are what the nightly job uses."""

    #: Replay step; None: the scene's tolerance table `replay_step`, else chosen by a convergence
    #: check (halving until the replay residual stops improving).
    step: float | None = None
    #: Replay horizon; None: the scene's whole time span.
    horizon: float | None = None
    #: Number of sample states of the parity and instantaneous checks.
    samples: int = 8


def run_check(scene_path: str, simulator: str, options: CheckOptions | None = None) -> CheckResult:
    """Check one scene in one simulator (implemented with the simulator back-ends)."""
    raise NotImplementedError("simulator back-ends are not implemented yet")
