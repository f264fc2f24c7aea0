"""Simulator back-ends of the checks: MuJoCo 4.0 (``mujoco_sim``), Pinocchio 4.1
(``pinocchio_sim``) and Drake 1.51 (``drake_sim``, optional: ``pip install 'progmo[drake]'``; its
replay is RK4 on Drake's own time derivatives, u at every stage), with the shared
coordinate maps and metrics in ``replay``.

Every back-end implements :class:`Backend`, built from a scene's export (document + report) and the
scene itself (to evaluate its expression forces at the simulator's own states):

* ``model_terms(t, q, v) -> (M, rhs)`` in OUR coordinates, ``rhs`` = every non-control generalized
  force the simulator's equations contain (``-bias + passive + harness forces``, including the
  scene's point and coordinate forces as the simulator applies them), to compare with our ``G + Q``;
* ``instant_u(t, q, v, a, B, gamma, programme) -> u`` the control force the simulator itself
  derives (with loop closures: split over the simulator's own closure Jacobian and our programme
  rows ``B[programme]``);
* ``closure_jacobian(t, q, v)`` the simulator's Jacobian of the scene's loop closures (rows in its
  own order and frame) in OUR v, and ``closure_forces(t, q, v, u)`` its closure multipliers under u;
* ``replay(ref, frame_every, start=0, stop=None, x0=None) -> Replay`` open-loop replay of ``ref.u``
  (u at each RK4 stage; ``Reference.force_at`` adds the reactions progmo supplies for rows the
  document leaves out, the report's ``supplied_reaction``) over the steps ``start`` .. ``stop`` (default: the whole span), from the
  reference's state at ``start`` (a segment restarted from the solver's state) or from ``x0`` = (q, v)
  (the checks' Lyapunov probe).
* for a scene whose model is a robot file, the back-end reads that file itself (``robot_file``,
  ``route = "user's file"``) and adds ``inverse_force(t, q, v, a)`` (the control force of its
  inverse dynamics), ``unmodelled()`` (elements of its reading progmo does not model) and
  ``joint_ranges()`` (its joint limits).

A back-end that meets a harness force it cannot apply raises :class:`Unsupported` naming it, and
the check becomes ``not_checked``: a model the simulator does not share never passes.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

#: Harness-force kinds of the export report (``src/export/mod.rs``, ``HarnessForce``).
FORCE_KINDS = ("attractor", "spring", "damper", "point_force", "coordinate_force", "supplied_reaction")


class BlowUp(RuntimeError):
    """The replay produced a non-finite state or an absurd acceleration. ``value`` is the quantity
    that crossed ``limit`` (inf for a non-finite state); ``partial`` the replay up to the last
    finite sample (set by the back-end), so the evidence is kept."""

    def __init__(self, time: float, what: str, value: float = float("inf"), limit: float = float("nan")):
        super().__init__(f"simulator blew up at t = {time:.6g}: {what}")
        self.time, self.what, self.value, self.limit = time, what, value, limit
        self.partial: Any = None


class Unsupported(RuntimeError):
    """The back-end cannot reproduce an element of the scene; the message names it."""


class Backend(Protocol):
    """What the checks need of a simulator."""

    name: str
    cm: Any  # replay.CoordMap

    def notes(self) -> list[str]: ...

    def model_terms(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...

    def instant_u(self, t: float, q: np.ndarray, v: np.ndarray, a: np.ndarray, B: np.ndarray,
                  gamma: np.ndarray, programme: list[int] | None = None,
                  actuated: bool = False) -> np.ndarray: ...

    def closure_jacobian(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray: ...

    def closure_forces(self, t: float, q: np.ndarray, v: np.ndarray, u: np.ndarray) -> np.ndarray: ...

    def replay(self, ref: Any, frame_every: int = 0, start: int = 0, stop: int | None = None,
               x0: tuple[np.ndarray, np.ndarray] | None = None) -> Any: ...

    # robot files (``route == "user's file"``, see ``robot_file``)
    route: str

    def inverse_force(self, t: float, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray: ...

    def unmodelled(self) -> list[dict]: ...

    def joint_ranges(self) -> dict[str, tuple[float, float]]: ...


def attractor_force(point: np.ndarray, mu: float, mass: float, com: np.ndarray) -> np.ndarray:
    """World-frame Newtonian attraction on a body of mass ``mass`` whose CoM is at ``com``:
    -mu m r / |r|^3, r = com - point (the export report's formula, ``HarnessForce::Attractor``)."""
    r = com - point
    return -mu * mass * r / np.sqrt(r.dot(r)) ** 3  # |r|: np.linalg.norm's arithmetic, without its overhead


def require_forces(report: dict, supported: tuple[str, ...], simulator: str) -> None:
    """Raise :class:`Unsupported` for the first harness force of the report that the back-end
    cannot apply."""
    for hf in report.get("harness_forces", []):
        if hf["kind"] not in supported:
            what = hf.get("body") or hf.get("joint") or hf.get("v_name") or ""
            raise Unsupported(f"{simulator} cannot apply the scene's {hf['kind'].replace('_', ' ')}"
                              + (f" on {what}" if what else ""))


class ExpressionForces:
    """The scene's point and coordinate forces (expressions of t, q, v), evaluated by the core at
    a simulator's state (``Scene.expression_forces``). ``withhold`` drops kinds on purpose: the
    negative control of a check that must then fail."""

    def __init__(self, scene: Any, report: dict, withhold: tuple[str, ...] = ()):
        kinds = {hf["kind"] for hf in report.get("harness_forces", [])}
        self.scene = scene
        self.points = "point_force" in kinds and "point_force" not in withhold
        self.generalized = "coordinate_force" in kinds and "coordinate_force" not in withhold
        self.active = scene is not None and (self.points or self.generalized)

    def at(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray | None, list]:
        """(generalized force in our coordinates or None, [(body, world point, world force)])."""
        if not self.active:
            return None, []
        d = self.scene.expression_forces(float(t), np.ascontiguousarray(q, float),
                                         np.ascontiguousarray(v, float))
        gen = np.asarray(d["generalized"]) if self.generalized else None
        pts = [(b, np.asarray(p), np.asarray(f)) for b, p, f in d["points"]] if self.points else []
        return gen, pts
