"""Per-scene, per-simulator checks: model parity, open-loop replay of u(t), instantaneous u.

Interface used by the nightly command (``cli.py``) and the report:

``run_check(scene_path, simulator, options) -> CheckResult`` where ``simulator`` is ``"mujoco"`` or
``"pinocchio"``; it never raises. Statuses (``results.py``): a scene element the simulator cannot
reproduce gives ``not_checked`` naming it (expected when the scene declares it in
``[checks] not_checked``), a missing package, a refused scene, a stopped solve or a simulator failure
gives ``error`` with the reason.

A check is a sequence of small steps over a typed back-end (``simulators.Backend``):

1. **Scene**: load it; the solver's verdict on the initial state (the located message ``progmo
   solve`` gives); a declared ``not_checked``.
2. **Export** (``Scene.export``): refused for what no simulator document carries (lagrangian models)
   -> ``not_checked``; every force the back-end must apply itself is in the report, and a back-end
   that cannot apply one says so (``Unsupported``) -> ``not_checked``. System rows no simulator
   holds (expression ``[[constraints]]``, nonholonomic or not; ``distance``, ``line``, ``plane``,
   ``rolling`` closures) are left out of the document and their **reactions supplied by progmo**
   (:func:`supplied_reactions`): the generalized reaction B_s^T lambda_s of the reference solve,
   applied with u at every stage time (open loop), named in the result (``supplied``), the notes,
   the report row and the summary line; everything else in the model is checked as usual.
   A scene whose model is a robot file (``kind = "urdf"``/``"mjcf"``) takes the route "user's
   file" (``CheckResult.route``): the back-end reads that file itself (``simulators.robot_file``)
   and the export only supplies the coordinate names and the scene's forces. Elements of the file
   progmo does not model (``Scene.unmodelled`` and the simulator's own reading) make the check
   ``not_checked`` naming them unless the scene declares their kind ignored (then the simulator's
   feature is off and the report lists them): :func:`_unmodelled`.
3. **Budgets**: every metric gets one, the scene's ``[tolerances]`` entry or the documented default
   of :func:`default_budgets`; the replayed span is the scene's whole span (``span``; only the
   ``horizon`` option shortens it, and the span then says so).
4. **Reference solve** at every RK4 stage time (output_dt = h/2) with rtol <= 1e-12; the replay step
   from ``replay_step`` or a convergence check. Its conditioning warnings are kept.
   Robot file: a joint range of the file that the reference motion leaves is such an element
   (:func:`_active_limits`); parity at random states with nonzero velocities and along the solution,
   and ``inverse_dynamics`` (u from the file's inverse dynamics at the solver's accelerations),
   both gating the replay and naming the worst joint (:func:`_inverse_dynamics`).
5. **Model parity** at ``options.samples`` states: the exported model's mass matrix and every
   non-control generalized force the simulator sees (``-bias + passive + harness forces``, the
   scene's point and coordinate forces included) against our ``A`` and ``G + Q``: ``parity_mass``,
   ``parity_bias``. **Instantaneous u** from the simulator's own constrained/inverse dynamics:
   ``instant_u``. When parity breaches its budget the replay is not run: a model mismatch must not
   be blamed on the dynamics.
6. **Open-loop replay** of the solver's u(t) over the whole span, in segments when the dynamics
   amplify errors (:func:`_probe`, :func:`_segments`): each segment restarts from the solver's state
   and is judged; ``replay_residual`` (max |row| of the core's own evaluator on the replayed states)
   and ``replay_deviation`` (max |dq|, |dv| against the solver, quaternions up to sign) are the
   worst over the segments. The continuous open-loop replay, its growth rate and the finite-time
   Lyapunov prediction of that growth are ``info``, not judged. With
   ``[[actuators]]`` also ``replay_unactuated``: the part of the replayed force no actuator can
   produce (outside range(H); on joint actuators the force on the other joints), relative to
   max |u| (:func:`unactuated_force`).

A scene no simulator document describes (a lagrangian model) is checked ``solver_only``
(``run_check(path, "solver_only")``): the scene (step 1), then :func:`_solver_only`: the solve with
the scene's formulation against a **second formulation** (``kkt``, or ``null_space`` when the scene
uses ``kkt``) at the reference tolerance (``formulation_deviation``: max |dq|, |dv|;
``formulation_force_deviation``: u and the system reactions relative to their scale) and, where the
scene gives ``[[reference]]`` values of independent origin, ``reference_error`` (max |x - x_ref| /
max(1, |x_ref|)). It is a verdict of its own, shown as such in the report, never a skip.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import importlib
import math
import time as _time
from dataclasses import dataclass, field
from collections.abc import Iterator
from typing import Any, Callable

import numpy as np

from . import _core, attribution
from .results import SOLVER_ONLY, Breach, Budget, CheckResult, Series, judge

#: the simulators of the cross-simulator check (``progmo::check::SIMULATORS``)
SIMULATORS: tuple[str, ...] = tuple(_core.SIMULATORS)
#: everything ``run_check`` can check in: the simulators and the solver-only check
CHECKERS = (*SIMULATORS, SOLVER_ONLY)

# The check's vocabulary is the core's (``progmo::check::METRICS``, one definition that the scene
# loader, the schema and FORMAT.md read too): these names are views of it.
_METRICS: list[dict[str, str]] = _core.check_metrics()


def _judged(check: str, *when: str) -> tuple[str, ...]:
    return tuple(m["name"] for m in _METRICS if m[check] in when)


#: metrics with budgets (``programme_residual`` in a scene's table judges ``solver_residual``)
BUDGETED = _judged("simulators", "always")
#: metrics of scenes with loop closures (``[[model.closures]]``), budgeted in addition
CLOSURE_BUDGETED = _judged("simulators", "closures")
#: metrics of scenes with ``[[actuators]]`` (servo-constraints), budgeted in addition
ACTUATOR_BUDGETED = _judged("simulators", "actuators")
#: metrics of scenes whose simulators read the user's robot file (``[model] kind = "urdf"/"mjcf"``)
ROBOT_FILE_BUDGETED = _judged("simulators", "robot_file")
#: metrics of the solver_only check (``reference_error`` only where the scene gives references)
SOLVER_ONLY_BUDGETED = _judged("solver_only", "always") + _judged("solver_only", "references")
#: the scene-table name of a metric's budget where it differs
TABLE_NAME = {m["name"]: m["table"] for m in _METRICS if m["table"] != m["name"]}

#: the reference solve is tighter than the scene's settings, so that the replay measures the
#: simulator and the per-stage feed of u rather than the solver's own tolerance
REF_RTOL, REF_ATOL = float(_core.REFERENCE_RTOL), float(_core.REFERENCE_ATOL)

#: simulator -> (the package it needs, the export format it reads, its back-end class)
_PACKAGES = {"mujoco": ("mujoco", "mjcf", "MujocoBackend"), "pinocchio": ("pinocchio", "urdf", "PinocchioBackend"),
             "drake": ("pydrake", "urdf", "DrakeBackend")}
#: how to install a simulator's package when it is missing
INSTALL = {"drake": "pip install 'progmo[drake]'"}


def available(simulator: str) -> str | None:
    """None when the simulator's package imports; else the reason (with how to install it)."""
    try:
        importlib.import_module(_PACKAGES[simulator][0])
    except ImportError as e:
        how = INSTALL.get(simulator)
        return f"{e}" + (f" (install: {how})" if how else "")
    return None


def default_budgets(settings: dict[str, Any]) -> dict[str, tuple[float, str]]:
    """The budget of every metric a scene's ``[tolerances]`` does not give, with its reason: the
    core's rule (``progmo::check::Metric::default_budget``; FORMAT.md, "Default budgets").
    ``settings`` is ``Scene.settings`` (its drift control sets ``solver_residual``'s)."""
    return {k: (float(v), str(why)) for k, (v, why) in
            _core.default_budgets(dict(settings.get("drift") or {"kind": "none"})).items()}


def budgets_for(tolerances: dict[str, tuple[float, str]], settings: dict[str, Any],
                simulator: str, metrics: tuple[str, ...] = BUDGETED) -> list[Budget]:
    """One budget per metric of ``metrics``: ``<name>_<simulator>``, else ``<name>`` from the
    scene's table (the loader admits no other names), else the default."""
    defaults = default_budgets(settings)
    out = []
    for m in metrics:
        name = TABLE_NAME.get(m, m)
        key = next((k for k in (f"{name}_{simulator}", name) if k in tolerances), None)
        if key is not None:
            v, why = tolerances[key]
            out.append(Budget(m, v, why if key == m else f"{key}: {why}", "scene"))
        else:
            v, why = defaults[m]
            out.append(Budget(m, v, why, "default"))
    return out


@dataclass
class CheckOptions:
    """How a check runs. Defaults are what the nightly job uses."""

    #: Replay step; None: the scene's `[checks] replay_step`, else chosen by a convergence
    #: check (halving until the replay residual stops improving).
    step: float | None = None
    #: Replay horizon; None: the scene's whole time span.
    horizon: float | None = None
    #: Number of sample states of the parity and instantaneous checks.
    samples: int = 8

    def problem(self) -> str | None:
        """What is wrong with the options, as ``name: message`` (None if nothing): the one check of
        ``progmo check``/``debug`` (flags ``--step``, ...) and ``progmo.check`` (keywords)."""
        return options_problem(self.step, self.horizon, self.samples)


#: most sample states of the parity and instantaneous checks
MAX_SAMPLES = 10_000


def options_problem(step: Any, horizon: Any, samples: Any) -> str | None:
    """``name: message`` for the first bad check option (step, horizon: numbers > 0, step finite;
    samples: an integer from 1 to MAX_SAMPLES), else None."""
    def number(x: Any) -> bool:
        return isinstance(x, (int, float)) and not isinstance(x, bool)

    def shown(x: Any) -> str:
        return f"{x:g}" if number(x) else repr(x)

    if step is not None and not (number(step) and math.isfinite(step) and step > 0):
        return f"step: must be a finite number > 0, got {shown(step)}"
    if horizon is not None and not (number(horizon) and horizon > 0):
        return f"horizon: must be a number > 0 (s), got {shown(horizon)}"
    if not (isinstance(samples, int) and not isinstance(samples, bool) and 1 <= samples <= MAX_SAMPLES):
        return f"samples: must be an integer from 1 to {MAX_SAMPLES}, got {samples!r}"
    return None


@dataclass
class Recording:
    """Everything a debugging run writes (filled by ``_run`` when asked)."""

    scene: Any = None
    ref: Any = None  # replay.Reference
    replay: Any = None  # replay.Replay
    residual: Any = None  # (n, rows) residual of the replay
    deviation: Any = None  # (n,) max deviation per replay sample
    sample_times: list = field(default_factory=list)
    q_names: list = field(default_factory=list)
    v_names: list = field(default_factory=list)
    row_names: list = field(default_factory=list)


@dataclass
class _Check:
    """The state of one check as its steps fill it in."""

    path: str
    simulator: str
    options: CheckOptions
    res: CheckResult
    corrupt_u: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    corrupt_export: Callable[[str], str] | None = None
    withhold: tuple[str, ...] = ()
    simulator_file: str | None = None
    frame_every: int = 0
    record: Recording | None = None
    scene: Any = None
    backend: Any = None
    tol: dict[str, tuple[float, str]] = field(default_factory=dict)
    horizon: float = 0.0
    ref: Any = None
    first: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    #: the element each metric's worst value comes from (``attribution.py``), for its breach
    where: dict[str, str] = field(default_factory=dict)
    #: a fresh back-end of the same export withholding the given harness-force kinds
    make_backend: Callable[[tuple[str, ...]], Any] | None = None
    #: robot-file route: parity over random states (metric -> value), worst joints (metric -> name)
    file_parity: dict[str, float] = field(default_factory=dict)
    worst_joint: dict[str, str] = field(default_factory=dict)
    #: system rows whose reactions progmo supplies (export report ``supplied_reaction``)
    supplied: list[str] = field(default_factory=list)
    #: a reference solve of this check came from an earlier check of the same file (``shared_solves``)
    shared_solve: bool = False


class _Stop(Exception):
    """Ends a check with a status and a reason."""

    def __init__(self, status: str, reason: str, expected: bool = False):
        super().__init__(reason)
        self.status, self.reason, self.expected = status, reason, expected


def run_check(scene_path: str, simulator: str, options: CheckOptions | None = None) -> CheckResult:
    """Check one scene in one simulator; never raises (see the module docs)."""
    return _run(scene_path, simulator, options)[0]


def _run(scene_path: str, simulator: str, options: CheckOptions | None = None, *,
         corrupt_u: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
         corrupt_export: Callable[[str], str] | None = None,
         withhold: tuple[str, ...] = (), simulator_file: str | None = None,
         frame_every: int = 0, record: Recording | None = None) -> tuple[CheckResult, Recording | None]:
    """The check. Negative controls: ``corrupt_u(t, u) -> u'`` replaces the replayed (and
    instantaneous-reference) control forces; ``corrupt_export(doc) -> doc'`` alters the exported
    document; ``withhold`` names harness-force kinds the back-end must not apply;
    ``simulator_file`` is the robot file the simulators load instead of the scene's (the scene
    reads a doctored copy, the simulators the original). ``frame_every``
    > 0 records body frames every that many replay steps; ``record`` is filled with the
    trajectories."""
    t_start = _time.perf_counter()
    c = _Check(str(scene_path), simulator, options or CheckOptions(),
               CheckResult(scene=str(scene_path), simulator=simulator, status="error"),
               corrupt_u, corrupt_export, tuple(withhold), simulator_file, frame_every, record)
    steps = (_scene, _solver_only) if simulator == SOLVER_ONLY else (
        _scene, _export, _unmodelled, _budgets, _reference, _active_limits, _inverse_dynamics, _parity,
        _replay)
    try:
        for step in steps:
            step(c)
    except _Stop as e:
        c.res.status, c.res.reason, c.res.expected = e.status, e.reason, e.expected
    except Exception as e:  # never raise out of a check
        c.res.status = "error"
        c.res.reason = c.res.reason or f"{type(e).__name__}: {e}"
    c.res.wall_seconds = _time.perf_counter() - t_start
    return c.res, record


# --- steps ---------------------------------------------------------------------------------------
def _scene(c: _Check) -> None:
    """Load the scene; the solver's verdict on its initial state; a declared not_checked."""
    from . import Scene, SceneError  # the Rust core

    if c.simulator not in CHECKERS:
        raise _Stop("error", f"unknown simulator {c.simulator!r} (one of {', '.join(CHECKERS)})")
    try:
        c.scene = Scene(c.path)
    except Exception as e:
        raise _Stop("error", f"cannot load scene: {e}") from None
    c.res.scene = c.scene.name
    try:
        c.scene.check_initial()
    except SceneError as e:
        raise _Stop("error", f"the solver refuses the scene: {e}") from None
    declared = dict(c.scene.expected_not_checked)
    if c.simulator in declared:
        raise _Stop("not_checked", f"declared in the scene ([checks] not_checked): {declared[c.simulator]}",
                    expected=True)


def _export(c: _Check) -> None:
    """The simulator's model of the scene and its back-end."""
    from ._core import ExportUnsupported
    from .simulators import Unsupported

    pkg, fmt, clsname = _PACKAGES[c.simulator]
    missing = available(c.simulator)
    if missing is not None:
        raise _Stop("error", f"simulator package for {c.simulator} is not importable: {missing}")
    mod = importlib.import_module(f".simulators.{c.simulator}_sim", __package__)
    try:
        doc, report = c.scene.export(fmt, supply_reactions=True)
    except ExportUnsupported as e:
        raise _Stop("not_checked", f"{fmt.upper()} export: {e}") from None
    except ValueError as e:
        raise _Stop("error", f"export failed: {e}") from None
    _supplied_route(c, report)
    if c.corrupt_export is not None:
        doc = c.corrupt_export(doc)
    robot = _robot_route(c)
    cls = getattr(mod, clsname)
    try:
        c.backend = cls(doc, report, c.scene, c.withhold, robot=robot)
        c.make_backend = lambda withhold: cls(doc, report, c.scene, withhold, robot=robot)
    except Unsupported as e:
        raise _Stop("not_checked", str(e)) from None
    except Exception as e:
        what = f"the robot file {robot.path.name}" if robot is not None else "the exported model"
        raise _Stop("error", f"{c.simulator} rejected {what}: {type(e).__name__}: {e}") from None
    c.res.notes += c.backend.notes()
    c.res.route = getattr(c.backend, "route", c.res.route)  # Drake reads an MJCF scene's URDF export
    if c.withhold:
        c.res.notes.append("NEGATIVE CONTROL: withheld from the simulator: " + ", ".join(c.withhold))


def _supplied_route(c: _Check, report: dict) -> None:
    """Name the rows whose reactions progmo supplies (export report ``supplied_reaction``), visibly:
    the result's ``supplied`` (report row, summary line) and a note with the reason."""
    for hf in report.get("harness_forces", []):
        if hf["kind"] != "supplied_reaction":
            continue
        c.supplied += list(hf["rows"])
        c.res.notes.append(
            f"reactions of rows {', '.join(hf['rows'])} supplied by progmo: {hf['reason']}. The "
            f"{c.simulator} model leaves these rows out and receives their generalized reaction "
            "B_s^T lambda_s from the reference solve at every RK4 stage time, with u (open loop); "
            "their residual on the replay is measured (replay_residual, info "
            "replay_supplied_residual), not enforced by the simulator; model parity and instant_u "
            "(against u + B_s^T lambda_s) judge everything else")
    c.res.supplied = list(c.supplied)
    if c.supplied and "supplied_reaction" in c.withhold:
        c.res.notes.append("NEGATIVE CONTROL: the supplied reactions are withheld from the replay")


def supplied_reactions(scene: Any, rows: list[str], t: np.ndarray, q: np.ndarray, v: np.ndarray,
                       lam: np.ndarray) -> np.ndarray:
    """B_s^T lambda_s at every sample (K x nv): the generalized reaction of ``rows`` (the core's
    jet B at the sample's state, the solver's multipliers ``lam``, K x s, in scene row order)."""
    names = [r["name"] for r in scene.rows]
    idx = [names.index(r) for r in rows]
    return np.array([np.asarray(scene.dynamics(float(tk), qk, vk)["B"])[idx].T @ lam[k, idx]
                     for k, (tk, qk, vk) in enumerate(zip(t, q, v))])


def _budgets(c: _Check) -> None:
    """Every metric's budget and the replayed span."""
    c.tol = {k: (float(v[0]), str(v[1])) for k, v in dict(c.scene.tolerances).items()}
    closures = bool(c.backend.report.get("closures"))
    metrics = BUDGETED + (CLOSURE_BUDGETED if closures else ()) + (
        ACTUATOR_BUDGETED if c.scene.actuators else ()) + (
        ROBOT_FILE_BUDGETED if c.res.route == "user's file" else ())
    c.res.budgets = budgets_for(c.tol, dict(c.scene.settings), c.simulator, metrics)
    full = c.scene.t1 - c.scene.t0
    c.horizon = min(c.options.horizon or full, full)
    c.res.span = [c.horizon, full]
    if c.horizon < full:
        c.res.notes.append(f"replay horizon {c.horizon:g} s of {full:g} s (given by the options)")


#: reference solves shared by the checks of one scene file (``shared_solves``); None outside
_SHARED: dict[tuple, tuple[Any, float]] | None = None


@contextlib.contextmanager
def shared_solves() -> Iterator[None]:
    """Within the block, checks of the same scene file share their reference solves: a solve is a
    pure function of the scene file and its settings, so the simulators of one scene solve once
    (``parallel`` runs a scene's checks in one worker inside this block). The memo lives only
    for the block, so a file edited between runs is read afresh."""
    global _SHARED
    prev, _SHARED = _SHARED, {}
    try:
        yield
    finally:
        _SHARED = prev


def _shared_solve(c: _Check, **kw: Any) -> tuple[Any, float, bool]:
    """``c.scene.solve(**kw)``, its seconds, and whether an earlier check of the same file (same
    bytes, same settings) computed it (:func:`shared_solves`)."""
    key = None
    if _SHARED is not None:
        try:
            with open(c.path, "rb") as f:
                key = (c.path, hashlib.sha256(f.read()).hexdigest(), tuple(sorted(kw.items())))
        except OSError:
            key = None
        if key in _SHARED:
            sol, secs = _SHARED[key]
            return sol, secs, True
    t0 = _time.perf_counter()
    sol = c.scene.solve(**kw)
    secs = _time.perf_counter() - t0
    if key is not None and _SHARED is not None:
        _SHARED[key] = (sol, secs)
    return sol, secs, False


def _solve_reference(c: _Check, h: float):
    """The solver's motion at every RK4 stage time of step h (output_dt = h/2)."""
    from ._core import SettingsError
    from .simulators.replay import Reference

    try:  # the step named as itself (replay_step), not as the output_dt = h/2 of the solve below
        c.scene.check_replay_step(h, t1=c.scene.t0 + c.horizon)
    except SettingsError as e:
        raise _Stop("error", str(e)) from None
    n = int(round(c.horizon / h))
    if n < 2 or abs(n * h - c.horizon) > 1e-9 * max(1.0, c.horizon):
        raise _Stop("error", f"replay step {h:g} does not divide the replayed span {c.horizon:g} s")
    scene = c.scene
    st = scene.settings
    sol, secs, shared = _shared_solve(c, output_dt=h / 2, t1=scene.t0 + n * h,
                                      rtol=min(st["rtol"], REF_RTOL), atol=min(st["atol"], REF_ATOL))
    c.shared_solve = c.shared_solve or shared
    c.res.warnings = [w["message"] for w in sol.warnings]
    if not sol.success:
        raise _Stop("error", f"the reference solve stopped ({sol.code}): {sol.message}")
    t = np.asarray(sol.t)
    if len(t) != 2 * n + 1 or np.abs(t - (scene.t0 + 0.5 * h * np.arange(2 * n + 1))).max() > 1e-9:
        raise _Stop("error", f"solver output grid does not match the stages of h = {h:g} "
                             f"({len(t)} outputs for {2 * n + 1} stage times)")
    u_model = np.array(sol.u)
    u = u_model
    if c.corrupt_u is not None:
        u = np.array([c.corrupt_u(tk, uk) for tk, uk in zip(t, u_model)])
    lam = np.asarray(sol.lambda_)
    ref = Reference(t, np.asarray(sol.q), np.asarray(sol.v), np.asarray(sol.a), u,
                    np.asarray(sol.residuals), h, n, scene.t0, secs,
                    lam, np.asarray(sol.residual_rates))
    if scene.actuation_varies:  # H(t, q): the replay applies H at the simulator's state
        ref.actuation = lambda tk, qk: np.asarray(scene.actuation_map_at(tk, qk))
        ref.tau, ref.u_model = np.asarray(sol.tau), u_model
    if c.supplied:  # rows the simulator does not hold: their reactions, from this solve
        ref.supplied = supplied_reactions(scene, c.supplied, t, ref.q, ref.v, lam)
    return ref


def _replay_of(c: _Check, ref):
    return c.backend.replay(_replay_ref(c, ref), _frame_every(c, ref))


def _replay_ref(c: _Check, ref):
    """The reference the replay feeds: without the supplied reactions when they are withheld (negative
    control)."""
    if ref.supplied is not None and "supplied_reaction" in c.withhold:
        ref = dataclasses.replace(ref, supplied=None)
    return ref


def _replay_residual(c: _Check, ref, rp) -> np.ndarray:
    accel = any(r["level"] == "acceleration" for r in c.scene.rows)
    return np.asarray(c.scene.residuals(rp.t, rp.q, rp.v, rp.a if accel else None))


def _max_abs(R: np.ndarray) -> float:
    return float(np.abs(R).max()) if R.size else 0.0


def _reference(c: _Check) -> None:
    """The replay step and the reference solve at its stage times."""
    from .simulators import BlowUp

    if c.options.step:
        h, why = c.options.step, "given by the options"
        c.ref = _solve_reference(c, h)
    elif c.scene.replay_step is not None:
        h, reason = c.scene.replay_step
        why = f"scene's [checks] replay_step: {reason}"
        c.ref = _solve_reference(c, h)
    else:
        # halve from 1e-2 while the residual still improves like a 4th-order method (>= 8x per
        # halving, i.e. 16x up to a factor 2); stop at round-off or after 5 halvings. A scene
        # without rows has no residual: its deviation from the solver decides.
        def err(ref) -> float:
            try:
                rp = _replay_of(c, ref)
            except BlowUp:
                return math.inf
            R = _replay_residual(c, ref, rp)
            if R.size:
                return _max_abs(R)
            return float(np.abs(rp.q - ref.q[::2][: ref.steps + 1]).max())
        h = min(1e-2, c.horizon / 100)
        c.ref = _solve_reference(c, h)
        prev = err(c.ref)
        seq = [f"{h:g}: {prev:.1e}"]
        for _ in range(5):
            if not prev > 1e-13:
                break
            ref2 = _solve_reference(c, h / 2)
            cur = err(ref2)
            seq.append(f"{h / 2:g}: {cur:.1e}")
            improved = cur < prev / 8
            h, c.ref, prev = h / 2, ref2, cur
            if not improved:
                break
        why = "convergence check, error by step " + ", ".join(seq)
    c.res.notes.append(f"replay step h = {h:g} ({why}); {getattr(c.backend, 'scheme', 'RK4')} with u at every stage "
                       f"(solver output_dt = h/2, solve {c.ref.solve_seconds:.2f} s"
                       f"{', shared with an earlier check of this scene file' if c.shared_solve else ''})")
    c.res.info["replay_step"] = h
    c.res.metrics["solver_residual"] = _max_abs(c.ref.residual)
    for w in c.res.warnings:
        c.res.notes.append(f"solver warning: {w}")


def _parity(c: _Check) -> None:
    """Model parity and instantaneous u at sample states along the reference."""
    scene, ref, be = c.scene, c.ref, c.backend
    idx = np.unique(np.linspace(0, 2 * ref.steps, max(1, c.options.samples)).round().astype(int))
    times = ref.t[idx]
    sM = sR = 0.0
    dmt, drt, dU, dJ, dR = [], [], [], [], []
    diffs: dict[str, list[np.ndarray]] = {m: [] for m in ("parity_mass", "parity_bias", "instant_u",
                                                          "reaction_closure")}
    closure_jac: list[tuple[np.ndarray, np.ndarray]] = []
    sRc = 0.0
    names = [r["name"] for r in scene.rows]
    programme = [i for i, r in enumerate(scene.rows) if r["role"] == "programme"]
    # supplied rows: the simulator derives their force with the programme's (u + B_s^T lambda_s)
    programme += [names.index(r) for r in c.supplied]
    applied = ref.u if ref.supplied is None else ref.u + ref.supplied
    closures = be.report.get("closures", [])
    closure_idx = [names.index(r) for cl in closures for r in cl["rows"] if r not in cl["set_aside"]]
    for k in idx:
        tk, qk, vk, ak = ref.t[k], ref.q[k], ref.v[k], ref.a[k]
        dyn = scene.dynamics(tk, qk, vk)
        A = np.asarray(dyn["mass"])
        rhs = np.asarray(dyn["velocity_terms"]) + np.asarray(dyn["applied_forces"])
        Ms, rs = be.model_terms(tk, qk, vk)
        dmt.append(float(np.abs(Ms - A).max()))
        drt.append(float(np.abs(rs - rhs).max()))
        diffs["parity_mass"].append(Ms - A)
        diffs["parity_bias"].append(rs - rhs)
        sM, sR = max(sM, float(np.abs(A).max())), max(sR, float(np.abs(rhs).max()))
        B = np.asarray(dyn["B"])
        us = be.instant_u(tk, qk, vk, ak, B, np.asarray(dyn["gamma"]), programme,
                          actuated=bool(scene.actuators))
        dU.append(float(np.abs(us - applied[k]).max()))
        diffs["instant_u"].append(us - applied[k])
        if closures:
            Jsim = be.closure_jacobian(tk, qk, vk)
            dJ.append(row_space_distance(B[closure_idx], Jsim))
            closure_jac.append((B[closure_idx], Jsim))
            # closure reactions: ours B_c^T lambda_c; the simulator's J^T f under the same u
            ours_r = B[closure_idx].T @ np.asarray(ref.lam[k])[closure_idx]
            sim_r = Jsim.T @ be.closure_forces(tk, qk, vk, applied[k])
            dR.append(float(np.abs(sim_r - ours_r).max()))
            diffs["reaction_closure"].append(sim_r - ours_r)
            sRc = max(sRc, float(np.abs(ours_r).max()))
    sR = sR if sR > 0 else 1.0
    # u relative to its own scale; without a programme (u = 0) relative to the forces.
    uabs = float(np.abs(applied).max()) if applied.size else 0.0
    sU = uabs if uabs > 0 else sR
    pm, pb, iu = np.array(dmt) / max(sM, 1e-300), np.array(drt) / sR, np.array(dU) / sU
    c.res.metrics.update(parity_mass=float(pm.max()), parity_bias=float(pb.max()), instant_u=float(iu.max()))
    for m in ("parity_mass", "parity_bias"):  # a robot file's parity also covers random states
        c.res.metrics[m] = max(c.res.metrics[m], c.file_parity.get(m, 0.0))
    uname = "max|u + B_s^T lambda_s|" if c.supplied else "max|u|"
    c.res.notes.append(f"parity scales: max|A| {sM:.3g}, max|G+Q| {sR:.3g}; instant_u scale "
                       f"{uname if uabs > 0 else 'max|G+Q| (u = 0)'} {sU:.3g}; {len(idx)} sample states")
    c.first = {"parity_mass": (times, pm), "parity_bias": (times, pb), "instant_u": (times, iu)}
    gate = ["parity_mass", "parity_bias"]
    if closures:
        c.res.metrics["parity_closure"] = float(max(dJ))
        c.first["parity_closure"] = (times, np.array(dJ))
        rc = np.array(dR) / max(sRc, 1e-300)
        c.res.metrics["reaction_closure"] = float(rc.max())
        c.first["reaction_closure"] = (times, rc)
        c.res.notes.append(f"closure reaction scale: max|B_c^T lambda_c| {sRc:.3g}")
        gate.append("parity_closure")
    bval = {b.metric: b.value for b in c.res.budgets}
    _attribute_parity(c, times, diffs, closure_jac, closure_idx, bval)
    bad = [m for m in gate if not (c.res.metrics[m] <= bval[m])]
    if bad:
        c.res.notes.append("model parity failed (" + ", ".join(bad) + "): the exported model differs "
                           "from ours, the replay was not run and nothing is blamed on the dynamics")
        # Judge what was measured; the replay's budgets stay listed, unmeasured and unjudged.
        budgets = c.res.budgets
        c.res.budgets = [b for b in budgets if b.metric in c.res.metrics]
        c.res.status = "pass"  # judge() decides
        _judge(c, _first_times(c.first, bval))
        c.res.budgets = budgets
        c.res.reason = "model parity: " + "; ".join(
            b.text() for b in c.res.breaches if b.metric in gate) + "; replay not run"
        raise _Stop(c.res.status, c.res.reason)


def _judge(c: _Check, first_times: dict) -> None:
    """``judge`` the result, each breach naming the element it comes from (``c.where``)."""
    judge(c.res, first_times)
    for b in c.res.breaches:
        b.where = c.where.get(b.metric, "")


def _attribute_parity(c: _Check, times: np.ndarray, diffs: dict[str, list[np.ndarray]],
                      closure_jac: list[tuple[np.ndarray, np.ndarray]], closure_idx: list[int],
                      bval: dict[str, float]) -> None:
    """``c.where`` of the parity metrics: the worst entry's joint(s), the closure; for a
    parity_bias beyond its budget also a harness force that explains the discrepancy."""
    scene, be = c.scene, c.backend
    v_names = list(scene.v_names)
    c.where["parity_mass"] = attribution.mass_entry(v_names, diffs["parity_mass"])
    c.where["instant_u"] = attribution.joint(v_names, diffs["instant_u"])
    c.where["parity_bias"] = attribution.joint(v_names, diffs["parity_bias"])
    if not (c.res.metrics["parity_bias"] <= bval.get("parity_bias", math.inf)):
        k, _ = attribution.worst(diffs["parity_bias"])
        i = int(np.argmin(np.abs(c.ref.t - times[k])))
        forces = attribution.harness_forces(be.report, c.make_backend, float(c.ref.t[i]), c.ref.q[i], c.ref.v[i])
        why = attribution.force_explaining(diffs["parity_bias"][k], forces)
        if why:
            c.where["parity_bias"] += f", {why}"
    closures = be.report.get("closures", [])
    if closures and closure_jac:
        names = [r["name"] for r in scene.rows]
        k = int(np.argmax([row_space_distance(o, s) for o, s in closure_jac]))
        c.where["parity_closure"] = attribution.closure_parity(closures, names, closure_idx, *closure_jac[k])
        k = int(np.argmax([float(np.abs(d).max()) for d in diffs["reaction_closure"]]))
        c.where["reaction_closure"] = attribution.closure_reaction(
            closures, names, closure_idx, closure_jac[k][0], diffs["reaction_closure"][k])


def row_space_distance(ours: np.ndarray, sim: np.ndarray) -> float:
    """Closure Jacobian parity: the largest relative distance of a row of either matrix from the
    row space of the other (|b - proj b| / |b|; rows below 1e-12 of the largest norm, e.g. the
    gradient-free z row of a planar loop, are skipped). Free of frame, sign and scaling of rows."""
    def dist(X: np.ndarray, Y: np.ndarray) -> float:
        if not len(X):
            return 0.0
        scale = max(float(np.abs(X).max()), float(np.abs(Y).max()) if Y.size else 0.0, 1e-300)
        if not Y.size:
            return float(np.linalg.norm(X, axis=1).max()) / scale
        U, S, Vt = np.linalg.svd(Y, full_matrices=False)
        basis = Vt[S > 1e-12 * S.max()] if S.size and S.max() > 0 else Vt[:0]
        worst = 0.0
        for x in X:
            n = np.linalg.norm(x)
            if n <= 1e-12 * scale:
                continue
            worst = max(worst, float(np.linalg.norm(x - basis.T @ (basis @ x)) / n))
        return worst
    return max(dist(ours, sim), dist(sim, ours))


#: coordinates whose solver and replay q(t) the report overlays
Q_OVERLAY = 4


#: segmented replay (:func:`_segments`): within one segment the linearized dynamics along the
#: reference may amplify a deviation at most this much (:func:`_probe`); a programme whose whole
#: span stays below it is replayed in one piece, as a stable one always was
SEGMENT_GROWTH = 1e3
#: the Lyapunov probe (:func:`_probe`): chunks of the span, size of the perturbation (max-norm over
#: q and v: well above the replay's own error once it cancels, well inside the linear range)
PROBE_CHUNKS = 16
PROBE_EPS = 1e-7
#: the continuous open-loop replay says something about the forces while its deviation from the
#: solver stays below this (m, rad; m/s, rad/s); beyond it the motion is no longer near the reference
OPEN_LOOP_INFORMATIVE = 1e-3


@dataclass
class Probe:
    """Finite-time Lyapunov estimate of the replay's flow along the reference (:func:`_probe`)."""

    k: np.ndarray  # chunk boundaries (replay step indices)
    t: np.ndarray  # their times
    inc: np.ndarray  # ln of each chunk's amplification (len(k) - 1)

    @property
    def growth(self) -> np.ndarray:
        """Lambda at the boundaries (Lambda[0] = 0): ln of the amplification from the start."""
        return np.concatenate([[0.0], np.cumsum(self.inc)])


def _frame_every(c: _Check, ref) -> int:
    return c.frame_every if c.frame_every >= 0 else max(1, -(-ref.steps // 1000))  # -1: <= ~1000 samples


def _probe(c: _Check, base, base_dev: np.ndarray) -> Probe:
    """How much the simulator's own flow under u amplifies a small deviation along the reference,
    by finite differences (Benettin's method): the span is cut into PROBE_CHUNKS chunks; on each the
    simulator runs from a state x_a and from x_a + eps d (max-norm eps; quaternions renormalized),
    both under the same u, and ln(|dx_b| / |dx_a|) is the chunk's growth; dx_b / |dx_b| is the next
    chunk's direction d (it turns into the most amplified one; the first is random, fixed seed).
    x_a is the continuous open-loop replay's state while it stays within OPEN_LOOP_INFORMATIVE of
    the solver (its own run is then the unperturbed one), else the solver's state with a run of the
    chunk from it. The cumulative Lambda(t) predicts that a deviation at s has grown by about
    exp(Lambda(t) - Lambda(s)) at t; Lambda(T) / T is the finite-time Lyapunov exponent."""
    from .simulators import BlowUp

    ref, be, cm = _replay_ref(c, c.ref), c.backend, c.backend.cm
    n, nq = ref.steps, ref.q.shape[1]
    ks = np.unique(np.linspace(0, n, min(PROBE_CHUNKS, n) + 1).round().astype(int))
    rng = np.random.default_rng(0)
    d = rng.standard_normal(nq + ref.v.shape[1])
    inc: list[float] = []  # ln amplification per chunk (inf: the perturbed run blew up; nan: both)
    for a, b in zip(ks[:-1], ks[1:]):
        if base is not None and len(base.t) > b and not (base_dev[: a + 1].max() > OPEN_LOOP_INFORMATIVE):
            qa, va, qb, vb = base.q[a], base.v[a], base.q[b], base.v[b]
        else:
            qa, va = ref.q[2 * a], ref.v[2 * a]
            try:
                rb = be.replay(ref, 0, int(a), int(b))
                qb, vb = rb.q[-1], rb.v[-1]
            except BlowUp:  # the forces themselves blow up: no growth to measure (the replay fails)
                inc.append(math.nan)
                continue
        dn = PROBE_EPS * d / np.abs(d).max()
        qp, vp = qa + dn[:nq], va + dn[nq:]
        for g in cm.quats:
            qp[g] /= np.linalg.norm(qp[g])
        dx0 = max(float(np.abs(qp - qa).max()), float(np.abs(vp - va).max()))
        try:
            rp = be.replay(ref, 0, int(a), int(b), x0=(qp, vp))
        except BlowUp:
            inc.append(math.inf)
            continue
        dx = np.concatenate([rp.q[-1] - qb, rp.v[-1] - vb])
        dx1 = float(np.abs(dx).max())
        inc.append(math.log(dx1 / dx0) if dx1 > 0 and dx0 > 0 else -math.inf)
        if dx1 > 0 and np.all(np.isfinite(dx)):
            d = dx
    return Probe(ks, ref.t[2 * ks], np.array(inc))


def _segments(p: Probe) -> tuple[list[tuple[int, int]], float]:
    """Cut the span at the probe's chunk boundaries into the fewest segments, from the start on,
    within which the predicted amplification max_{s <= t} exp(Lambda(t) - Lambda(s)) stays below
    SEGMENT_GROWTH (a chunk above it alone is a segment of its own). Returns the segments (replay
    step indices) and the largest predicted ln-amplification within one (Kadane's maximum sum of
    consecutive chunk growths)."""
    lim = math.log(SEGMENT_GROWTH)
    inc, k = p.inc, p.k
    segs: list[tuple[int, int]] = []
    s0, cur, worst, most = 0, 0.0, 0.0, 0.0
    for i, gi in enumerate(inc):  # chunk i: steps k[i] .. k[i + 1]
        gi = 0.0 if math.isnan(gi) else float(gi)  # unmeasured (the unperturbed run blew up): no cut
        c2 = max(cur, 0.0) + gi
        w2 = max(worst, c2)
        if w2 > lim and i > s0:  # close the segment before chunk i
            segs.append((int(k[s0]), int(k[i])))
            most = max(most, worst)
            s0, c2, w2 = i, gi, max(0.0, gi)
        cur, worst = c2, w2
    segs.append((int(k[s0]), int(k[-1])))
    return segs, max(most, worst)


def _measure(c: _Check, rp, start: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The programme rows (R), their max (per sample) and the deviation from the solver of a replay
    whose first sample is replay step ``start``."""
    from .simulators.replay import quat_aware_diff

    ref = c.ref
    R = _replay_residual(c, ref, rp)
    rabs = np.abs(R).max(axis=1) if R.shape[1] else np.zeros(len(rp.t))
    rq, rv = ref.q[::2][start: start + len(rp.t)], ref.v[::2][start: start + len(rp.t)]
    dev = np.maximum(quat_aware_diff(c.backend.cm, rp.q, rq).max(axis=1), np.abs(rp.v - rv).max(axis=1))
    return R, rabs, dev


def _joined(parts: list) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray]:
    """One replay of the segments, one sample per step: a segment's end is kept (the evidence) and
    the next segment's restart at the solver's state left out (it is judged all the same)."""
    from .simulators.replay import Replay

    rps = [p[1] for p in parts]
    cut = [0] + [1] * (len(parts) - 1)
    cat = lambda xs: np.concatenate([x[k:] for x, k in zip(xs, cut)])  # noqa: E731
    frames = list(rps[0].frames)
    for rp in rps[1:]:
        frames += [f for f in rp.frames if f[0] > frames[-1][0]] if frames else list(rp.frames)
    joined = Replay(cat([r.t for r in rps]), cat([r.q for r in rps]), cat([r.v for r in rps]),
                    cat([r.a for r in rps]), frames, rps[0].frame_every)
    return joined, cat([p[2] for p in parts]), cat([p[3] for p in parts]), cat([p[4] for p in parts])


def _replay(c: _Check) -> None:
    """Open-loop replay of u in the simulator over the whole span, in segments where the dynamics
    amplify errors (each restarted from the solver's state and judged), its metrics and the verdict;
    the continuous replay and the Lyapunov prediction of its growth as info."""
    from .simulators import BlowUp

    scene, ref, be, res = c.scene, _replay_ref(c, c.ref), c.backend, c.res
    t0r = _time.perf_counter()
    fe = _frame_every(c, ref)
    # the continuous open-loop replay: judged when the span is one segment, else information
    cont_blowup: BlowUp | None = None
    try:
        cont = be.replay(ref, fe)
    except BlowUp as e:
        cont_blowup, cont = e, e.partial
    if cont is not None and len(cont.t) < 1:
        cont = None
    cont_m = _measure(c, cont, 0) if cont is not None else None
    probe = _probe(c, cont, cont_m[2] if cont_m is not None else np.zeros(0))
    segs, most = _segments(probe)
    res.info["replay_segments"] = float(len(segs))
    res.info["segment_amplification"] = math.exp(most)  # predicted, the largest within one segment
    span = c.horizon
    lam = float(probe.growth[-1]) / span if span > 0 else math.nan
    res.info["lyapunov_exponent"] = lam
    parts = _replay_parts(c, ref, fe, segs, cont, cont_m, cont_blowup)
    blowup = parts[-1][5]
    rp, R, rabs, dev = _joined(parts)
    if blowup is not None:
        res.span = [float(rp.t[-1]) - scene.t0, res.span[1] if res.span else c.horizon]
        res.notes.append(f"{c.simulator} replay: {blowup}; the metrics cover the replay up to "
                         f"t = {rp.t[-1]:.6g}, the last finite sample")
    res.notes.append(f"replay of {len(rp.t) - 1} of {ref.steps} steps"
                     + (f" in {len(segs)} segments" if len(segs) > 1 else "")
                     + f" took {_time.perf_counter() - t0r:.2f} s (with the Lyapunov probe)")
    _replay_metrics(c, ref, parts, rp, R, rabs)
    _open_loop_info(c, cont, cont_m[2] if cont_m is not None else None, cont_blowup, probe, segs, most)
    if len(segs) > 1:
        res.notes.append("per segment (max replay_residual, replay_deviation): " + "; ".join(
            f"{ref.t[2 * p[0]]:g} .. {p[1].t[-1]:g} s: {p[3].max():.2g}, {p[4].max():.2g}" for p in parts))
    c.first.update({"replay_residual": (rp.t, rabs), "replay_deviation": (rp.t, dev)})
    _replay_series(c, ref, rp, rabs, dev)
    if c.record is not None:
        rec = c.record
        rec.scene, rec.ref, rec.replay = scene, ref, rp
        rec.residual, rec.deviation = R, dev
        rec.sample_times = c.first["parity_mass"][0].tolist()
        rec.q_names, rec.v_names = list(scene.q_names), list(scene.v_names)
        rec.row_names = [r["name"] for r in scene.rows]
    _replay_verdict(c, ref, segs, blowup)


def _replay_parts(c: _Check, ref: Any, fe: int, segs: list[tuple[int, int]], cont: Any, cont_m: Any,
                  cont_blowup: Any) -> list:
    """The replay's parts, (start step, replay, R, rabs, dev, blow-up) each: the continuous replay when
    the span is one segment, else one replay per segment up to the first that blows up (a first
    segment that leaves no two samples fails the check)."""
    from .simulators import BlowUp

    res = c.res
    parts: list = []
    if len(segs) == 1:
        if cont is None or len(cont.t) < 2:
            first = cont_blowup
            assert first is not None
            res.breaches = [Breach("replay_blowup", first.value, first.limit, first.time)]
            raise _Stop("fail", f"{c.simulator} replay: {first}") from None
        assert cont_m is not None
        parts.append((0, cont, *cont_m, cont_blowup))
        return parts
    for a, b in segs:
        try:
            rp, blow = c.backend.replay(ref, fe, a, b), None
        except BlowUp as e:
            rp, blow = e.partial, e
        if rp is None or len(rp.t) < 2:
            if not parts:
                assert blow is not None
                res.breaches = [Breach("replay_blowup", blow.value, blow.limit, blow.time)]
                raise _Stop("fail", f"{c.simulator} replay (segment 1 of {len(segs)}): {blow}") from None
            parts[-1] = (*parts[-1][:5], blow)
            break
        parts.append((a, rp, *_measure(c, rp, a), blow))
        if blow is not None:
            break
    return parts


def _replay_metrics(c: _Check, ref: Any, parts: list, rp: Any, R: np.ndarray, rabs: np.ndarray) -> None:
    """The replay's metrics (residual, deviation, the unactuated force of servo-constraints), where
    they are worst, and the closure and supplied rows' residuals as info; a non-finite residual is an error."""
    from .simulators.replay import quat_aware_diff

    scene, be, res = c.scene, c.backend, c.res
    all_rabs = np.concatenate([p[3] for p in parts])
    if not np.all(np.isfinite(all_rabs)):
        raise _Stop("error", f"{c.simulator} replay: non-finite programme residual at "
                             f"t = {rp.t[np.argmax(~np.isfinite(rabs))]:.6g}")
    res.metrics["replay_residual"] = float(all_rabs.max())
    closures = be.report.get("closures", [])
    if closures and R.shape[1]:  # the closure rows alone (info: how well the simulator holds the loops)
        names = [r["name"] for r in scene.rows]
        ci = [names.index(r) for cl in closures for r in cl["rows"] if r not in cl["set_aside"]]
        res.info["replay_closure_residual"] = float(max(np.abs(p[2][:, ci]).max() for p in parts))
    if c.supplied and R.shape[1]:  # the supplied rows alone: how well their reactions held them
        names = [r["name"] for r in scene.rows]
        si = [names.index(r) for r in c.supplied]
        res.info["replay_supplied_residual"] = float(max(np.abs(p[2][:, si]).max() for p in parts))
    res.metrics["replay_deviation"] = float(max(p[4].max() for p in parts))
    rq, rv = ref.q[::2][: len(rp.t)], ref.v[::2][: len(rp.t)]  # the joined replay: a sample per step
    c.where["replay_deviation"] = attribution.deviation(
        scene.q_names, scene.v_names, quat_aware_diff(be.cm, rp.q, rq), rp.v - rv)
    c.where["replay_residual"] = attribution.row([r["name"] for r in scene.rows], R)
    if scene.actuators:  # servo-constraints: the force fed to the simulator acts on actuated joints only
        off = np.asarray(scene.unactuated_part(ref.t, ref.q, ref.u))  # the core's range(H(t, q))
        res.metrics["replay_unactuated"] = unactuated_force(ref.u, off)
        c.where["replay_unactuated"] = attribution.unactuated(scene.v_names, off)


def _replay_series(c: _Check, ref: Any, rp: Any, rabs: np.ndarray, dev: np.ndarray) -> None:
    """The report's series: the replay's residual and deviation, u, and q of the solver and the replay."""
    from .simulators.replay import downsample

    scene, res = c.scene, c.res
    sel = downsample(len(rp.t))
    res.series.append(Series("replay_residual", rp.t[sel].tolist(), rabs[sel].tolist(),
                             "row units (m, rad, m/s ...)"))
    res.series.append(Series("replay_deviation", rp.t[sel].tolist(), dev[sel].tolist(), "m, rad (q); m/s, rad/s (v)"))
    selu = downsample(len(ref.t))
    for j, name in enumerate(scene.v_names):
        res.series.append(Series(f"u.{name}", ref.t[selu].tolist(), ref.u[selu, j].tolist(), "N or N m"))
    # q(t) of the solver and of the replay, overlaid (the first few coordinates)
    for j, name in enumerate(scene.q_names[:Q_OVERLAY]):
        res.series.append(Series(f"q.{name}", ref.t[selu].tolist(), ref.q[selu, j].tolist(), "m or rad"))
        res.series.append(Series(f"q.{name} replay", rp.t[sel].tolist(), rp.q[sel, j].tolist(), "m or rad"))


def _replay_verdict(c: _Check, ref: Any, segs: list[tuple[int, int]], blowup: Any) -> None:
    """The verdict: each metric judged against its budget, a blow-up fails; the reason of a failure
    names the segment where each breach happened."""
    res = c.res
    res.status = "pass"
    bval = {b.metric: b.value for b in res.budgets}
    _judge(c, _first_times(c.first, bval))
    if blowup is not None:
        res.breaches.insert(0, Breach("replay_blowup", blowup.value, blowup.limit, blowup.time))
        res.status = "fail"
    if res.status == "fail":
        def where(t: float | None) -> str:
            if t is None or len(segs) == 1:
                return ""
            i = next((i for i, (a, b) in enumerate(segs) if t <= ref.t[2 * b] + 1e-12), len(segs) - 1)
            a, b = segs[i]
            return f" (segment {i + 1} of {len(segs)}: {ref.t[2 * a]:g} .. {ref.t[2 * b]:g} s)"
        res.reason = "; ".join(
            (f"{c.simulator} replay: {blowup}{where(blowup.time)}" if b.metric == "replay_blowup" and blowup is not None
             else b.text() + where(b.first_time))
            for b in res.breaches)


def _open_loop_info(c: _Check, cont, dev, blowup, probe: Probe, segs: list, most: float) -> None:
    """Information, not judged: how long the continuous open-loop replay stays informative, its
    growth rate, and its growth against the Lyapunov prediction exp(Lambda(t_b) - Lambda(t_a))."""
    from .simulators.replay import growth_rate

    res, span, t0 = c.res, c.horizon, c.scene.t0
    L = probe.growth
    lam = res.info["lyapunov_exponent"]
    if len(segs) == 1:
        res.notes.append(f"one replay segment: the linearized dynamics amplify a deviation at most "
                         f"x{math.exp(most):.3g} over the span (segments start beyond x{SEGMENT_GROWTH:g}; "
                         f"finite-time Lyapunov exponent {lam:.3g} 1/s, {len(probe.k) - 1} probe chunks)")
    else:
        res.notes.append(f"segmented replay: {len(segs)} segments, each restarted from the solver's state "
                         "and judged (" + ", ".join(f"{c.ref.t[2 * a]:g} .. {c.ref.t[2 * b]:g} s" for a, b in segs)
                         + f"): the linearized dynamics amplify a deviation at most x{math.exp(most):.3g} "
                         f"within one (limit x{SEGMENT_GROWTH:g}), x{math.exp(L[-1]):.3g} over the span "
                         f"(finite-time Lyapunov exponent {lam:.3g} 1/s, {len(probe.k) - 1} probe chunks)")
    if cont is None or dev is None or len(cont.t) < 2:
        res.info["open_loop_informative"] = 0.0
        res.notes.append(f"continuous open-loop replay (info): {blowup}")
        return
    bad = ~(dev <= OPEN_LOOP_INFORMATIVE)
    m = int(np.argmax(bad)) if bad.any() else len(dev)
    informative = float(cont.t[m - 1] - t0) if m > 0 else 0.0
    res.info["open_loop_informative"] = informative
    g = growth_rate(cont.t[:m], dev[:m])
    res.info["replay_growth_rate"] = g
    # the growth measured from the end of the first probe chunk to the last informative boundary
    ks = [i for i in range(1, len(probe.k)) if probe.k[i] < m and dev[probe.k[i]] > 0]
    what = (f"continuous open-loop replay (info, not judged): deviation {float(dev[m - 1]):.2g} at "
            f"t = {cont.t[m - 1]:.6g}; within {OPEN_LOOP_INFORMATIVE:g} of the solver for {informative:g} "
            f"of {span:g} s" + (f" ({blowup})" if blowup is not None else ""))
    if len(ks) >= 2 and math.isfinite(float(L[ks[-1]] - L[ks[0]])):
        ia, ib = ks[0], ks[-1]
        meas = math.log(dev[probe.k[ib]] / dev[probe.k[ia]])
        pred = float(L[ib] - L[ia])
        res.info["open_loop_growth"] = meas
        res.info["lyapunov_growth"] = pred
        what += (f"; from t = {probe.t[ia]:g} to {probe.t[ib]:g} s it grew x{math.exp(meas):.3g}, "
                 f"the linearized dynamics predict x{math.exp(pred):.3g}")
    res.notes.append(what)


def unactuated_force(u: np.ndarray, off: np.ndarray) -> float:
    """The largest part of u(t) no actuator can produce, relative to max |u| (0 when u = 0).
    ``off``: per sample, the part of u outside range(H(t, q)) (``Scene.unactuated_part``: on joint
    actuators exactly the entries of the joints none drives)."""
    scale = float(np.abs(u).max()) if np.size(u) else 0.0
    return float(np.abs(off).max()) / scale if scale > 0.0 else 0.0


def _first_times(first: dict, bval: dict) -> dict:
    from .simulators.replay import first_time_above

    out = {}
    for m, (t, x) in first.items():
        if m in bval:
            ft = first_time_above(np.asarray(t), np.asarray(x), bval[m])
            if ft is not None:
                out[m] = ft
    return out


# --- robot files (issue 27): the simulators read the user's file ----------------------------------
#: states of the random-state parity of a robot file (besides the samples along the solution)
RANDOM_STATES = 8
#: at most this many samples of the reference judge inverse_dynamics (every sample when fewer)
INVERSE_SAMPLES = 2001


def _robot_route(c: _Check):
    """The user's robot file for a scene whose model is one (``simulators.robot_file``), with the
    negative-control substitute ``simulator_file``; sets ``CheckResult.route``."""
    from pathlib import Path

    from .simulators.robot_file import robot_file

    try:
        rf = robot_file(c.scene)
    except (OSError, ValueError) as e:
        raise _Stop("error", f"robot file: {e}") from None
    c.res.route = "progmo export" if rf is None else "user's file"
    if rf is not None and c.simulator_file:
        rf.path = Path(c.simulator_file)
        c.res.notes.append(f"NEGATIVE CONTROL: the simulators load {rf.path}, not the scene's file")
    return rf


def _unmodelled(c: _Check) -> None:
    """Elements of the robot file progmo does not model: the core's list (``Scene.unmodelled``) and
    what the simulator's own reading holds (``Backend.unmodelled``). Undeclared -> not_checked
    naming them; declared ones are listed (the simulator's feature is switched off). Joint ranges
    are judged along the motion instead (:func:`_active_limits`)."""
    if c.res.route != "user's file":
        return
    core = [dict(u) for u in getattr(c.scene, "unmodelled", []) or []]
    declared = {str(u["kind"]) for u in core if u.get("declared")}
    # a joint range counts when the motion leaves it (_active_limits); inside it no limit acts
    found = [u for u in core if not u.get("declared") and u["kind"] != "joint_limit"]
    found += [u for u in c.backend.unmodelled() if u["kind"] not in declared
              and not any(f["kind"] == u["kind"] and f["element"] == u["element"] for f in found)]
    if found:
        raise _Stop("not_checked", "the robot file holds what progmo does not model (declare it ignored "
                    "in the scene, or remove it): " + "; ".join(_element(u) for u in found))
    if declared:
        kinds: dict[str, list[str]] = {}
        for u in core:
            if u.get("declared"):
                kinds.setdefault(str(u["kind"]), []).append(str(u["element"]))
        c.res.notes.append("declared ignored by the scene (its simulator feature off where it has one): " + "; ".join(
            f"{k} ({len(v)}: {', '.join(v[:3])}{', ...' if len(v) > 3 else ''})" for k, v in kinds.items()))


def _element(u: dict) -> str:
    loc = f" ({u['location']})" if u.get("location") else ""
    return f"{u['kind']} {u['element']}{loc}"


def _active_limits(c: _Check) -> None:
    """A joint range (as the simulator reads the file) that the reference motion leaves is an
    element progmo does not model: not_checked unless the scene declares limits ignored."""
    if c.res.route != "user's file":
        return
    ref, names = c.ref, list(c.scene.q_names)
    for name, (lo, hi) in c.backend.joint_ranges().items():
        if name not in names:
            continue
        x = ref.q[:, names.index(name)]
        out = (x < lo) | (x > hi)
        if out.any():
            k = int(np.argmax(out))
            u = {"kind": "joint_limit", "element": f"joint {name} range [{lo:g}, {hi:g}]",
                 "location": f"left at t = {ref.t[k]:.6g} (q = {x[k]:.6g})"}
            if "joint_limit" in {str(e["kind"]) for e in getattr(c.scene, "unmodelled", []) or [] if e.get("declared")}:
                c.res.notes.append("active limit, declared ignored (limits off in the simulator): " + _element(u))
            else:
                raise _Stop("not_checked", "the reference motion leaves a joint range of the robot file (an "
                            "active limit progmo does not model): " + _element(u))


def _inverse_dynamics(c: _Check) -> None:
    """Robot file: parity of progmo's A and G + Q with the simulator's reading at random states
    (random nonzero velocities: damping, Coriolis) and along the solution, and ``inverse_dynamics``:
    u from the file's inverse dynamics at the solver's (t, q, v, dv/dt) against the solver's u,
    relative to max|u|, along the trajectory. A breach names the quantity and the worst joint; it
    stops the check before the replay (a model mismatch is not blamed on the dynamics)."""
    if c.res.route != "user's file":
        return
    scene, ref, be = c.scene, c.ref, c.backend
    rng = np.random.default_rng(27)
    nv = len(scene.v_names)
    states = []
    for _ in range(RANDOM_STATES):
        q = np.array(scene.q0) + rng.uniform(-0.5, 0.5, len(scene.q0))
        for g in be.cm.quats:
            q[g] /= np.linalg.norm(q[g])
        states.append((scene.t0, q, rng.uniform(-1.0, 1.0, nv)))
    idx = np.unique(np.linspace(0, 2 * ref.steps, max(1, c.options.samples)).round().astype(int))
    states += [(ref.t[k], ref.q[k], ref.v[k]) for k in idx]
    dM, dF, sM, sF = [], [], 0.0, 0.0
    for t, q, v in states:
        dyn = scene.dynamics(float(t), q, v)
        A = np.asarray(dyn["mass"])
        rhs = np.asarray(dyn["velocity_terms"]) + np.asarray(dyn["applied_forces"])
        Ms, rs = be.model_terms(float(t), q, v)
        dM.append(np.abs(Ms - A).max(axis=0))
        dF.append(np.abs(rs - rhs))
        sM, sF = max(sM, float(np.abs(A).max())), max(sF, float(np.abs(rhs).max()))
    vn = list(scene.v_names)
    for m, d, sc in (("parity_mass", np.array(dM), sM), ("parity_bias", np.array(dF), sF)):
        rel = d.max(axis=1) / max(sc, 1e-300)
        c.file_parity[m] = float(rel.max())
        c.worst_joint[m] = vn[int(np.argmax(d.max(axis=0)))]
    c.res.notes.append(f"robot-file parity: {RANDOM_STATES} random states (q0 +- 0.5, |v| <= 1) and {len(idx)} "
                       f"along the solution: parity_mass {c.file_parity['parity_mass']:.3g} (worst joint "
                       f"{c.worst_joint['parity_mass']}), parity_bias {c.file_parity['parity_bias']:.3g} "
                       f"(worst joint {c.worst_joint['parity_bias']})")
    # inverse dynamics along the trajectory
    stride = max(1, -(-len(ref.t) // INVERSE_SAMPLES))
    ks = np.arange(0, len(ref.t), stride)
    # with loop closures the file's inverse dynamics needs u plus the closures' reactions B_c^T lambda_c,
    # and the reactions of the system rows progmo supplies (a URDF <mimic>: the file's coupling)
    closures = be.report.get("closures", [])
    names = [r["name"] for r in scene.rows]
    cidx = [names.index(r) for cl in closures for r in cl["rows"] if r not in cl["set_aside"]]
    cidx += [names.index(r) for r in c.supplied if r in names and names.index(r) not in cidx]

    def needed(k: int) -> np.ndarray:
        if not cidx:
            return ref.u[k]
        B = np.asarray(scene.dynamics(float(ref.t[k]), ref.q[k], ref.v[k])["B"])
        return ref.u[k] + B[cidx].T @ np.asarray(ref.lam[k])[cidx]
    du = np.array([np.abs(be.inverse_force(ref.t[k], ref.q[k], ref.v[k], ref.a[k]) - needed(int(k))) for k in ks])
    uabs = float(np.abs(ref.u).max()) if ref.u.size else 0.0
    su = uabs if uabs > 0 else max(sF, 1e-300)
    rel = du.max(axis=1) / su
    c.res.metrics["inverse_dynamics"] = float(rel.max())
    c.worst_joint["inverse_dynamics"] = vn[int(np.argmax(du.max(axis=0)))]
    c.where["inverse_dynamics"] = f"joint {c.worst_joint['inverse_dynamics']}"
    c.first["inverse_dynamics"] = (ref.t[ks], rel)
    c.res.notes.append(f"inverse_dynamics: u from {c.simulator}'s inverse dynamics of the file at {len(ks)} "
                       f"samples of the solution vs the solver's u"
                       + (" plus the closures' reactions B_c^T lambda_c" if cidx else "")
                       + f", relative to max|u| {su:.3g}: "
                       f"{rel.max():.3g} (worst joint {c.worst_joint['inverse_dynamics']})")
    bval = {b.metric: b.value for b in c.res.budgets}
    bad = [(m, v) for m, v in (("parity_mass", c.file_parity["parity_mass"]),
                               ("parity_bias", c.file_parity["parity_bias"]),
                               ("inverse_dynamics", rel.max())) if not (v <= bval[m])]
    if bad:
        c.res.metrics.update({m: v for m, v in c.file_parity.items()})
        budgets = c.res.budgets
        c.res.budgets = [b for b in budgets if b.metric in c.res.metrics]
        c.res.status = "pass"  # judge() decides
        for m in ("parity_mass", "parity_bias"):  # the worst joint of the robot file's parity
            c.where.setdefault(m, f"joint {c.worst_joint[m]}")
        _judge(c, _first_times(c.first, bval))
        c.res.budgets = budgets
        c.res.reason = (f"{c.simulator}'s reading of the robot file differs from progmo's model: " + "; ".join(
            f"{m} {float(v):.3g} > {bval[m]:.3g} (worst joint {c.worst_joint[m]})" for m, v in bad)
            + "; replay not run")
        raise _Stop(c.res.status, c.res.reason)


# --- solver_only ---------------------------------------------------------------------------------
def second_formulation(formulation: str) -> str:
    """The formulation a solver_only check compares with: the KKT system (multipliers, the other
    side of the paper's contrast), or the paper's null-space method when the scene uses KKT."""
    return "null_space" if formulation == "kkt" else "kkt"


def _solver_only(c: _Check) -> None:
    """A scene no simulator document describes: two formulations and the scene's references."""
    from .simulators.replay import downsample

    scene, res = c.scene, c.res
    c.tol = {k: (float(v[0]), str(v[1])) for k, v in dict(scene.tolerances).items()}
    refs = list(scene.references)
    metrics = SOLVER_ONLY_BUDGETED if refs else SOLVER_ONLY_BUDGETED[:-1]
    st = dict(scene.settings)
    res.budgets = budgets_for(c.tol, st, SOLVER_ONLY, metrics)
    full = scene.t1 - scene.t0
    res.span = [full, full]
    tight = dict(rtol=min(st["rtol"], REF_RTOL), atol=min(st["atol"], REF_ATOL))
    first, second = st["formulation"], second_formulation(st["formulation"])
    t0s = _time.perf_counter()
    a = scene.solve(**tight)
    res.warnings = [w["message"] for w in a.warnings]
    if not a.success:
        raise _Stop("error", f"the reference solve stopped ({a.code}): {a.message}")
    b = scene.solve(formulation=second, **tight)
    if not b.success:
        raise _Stop("fail", f"the second formulation ({second}) stopped ({b.code}): {b.message}")
    ta, tb = np.asarray(a.t), np.asarray(b.t)
    if ta.shape != tb.shape or np.abs(ta - tb).max() > 1e-12 * max(1.0, abs(scene.t1)):
        raise _Stop("error", "the two formulations sampled different times")
    res.notes.append(
        f"solver-only check: no MJCF/URDF element describes a {scene.kind} model, so no simulator "
        f"replays it; formulation {first} against {second}, both at rtol {tight['rtol']:g}, "
        f"atol {tight['atol']:g} ({len(ta)} samples, {_time.perf_counter() - t0s:.2f} s)")
    for w in res.warnings:
        res.notes.append(f"solver warning: {w}")
    dev = np.maximum(np.abs(np.asarray(a.q) - np.asarray(b.q)).max(axis=1),
                     np.abs(np.asarray(a.v) - np.asarray(b.v)).max(axis=1))
    fa = np.hstack([np.asarray(a.u), np.asarray(a.reactions)])
    fb = np.hstack([np.asarray(b.u), np.asarray(b.reactions)])
    scale = float(np.abs(fa).max()) if fa.size else 0.0
    fdev = (np.abs(fa - fb).max(axis=1) / (scale if scale > 0 else 1.0)) if fa.size else np.zeros(len(ta))
    resid = np.abs(np.asarray(a.residuals)).max(axis=1) if np.asarray(a.residuals).size else np.zeros(len(ta))
    res.metrics.update(solver_residual=float(resid.max()), formulation_deviation=float(dev.max()),
                       formulation_force_deviation=float(fdev.max()))
    first_series = {"formulation_deviation": (ta, dev), "formulation_force_deviation": (ta, fdev)}
    sel = downsample(len(ta))
    res.series.append(Series("formulation_deviation", ta[sel].tolist(), dev[sel].tolist(), "m, rad (q); m/s, rad/s (v)"))
    res.series.append(Series("formulation_force_deviation", ta[sel].tolist(), fdev[sel].tolist(), "relative"))
    for j, name in enumerate(scene.v_names):
        res.series.append(Series(f"u.{name}", ta[sel].tolist(), np.asarray(a.u)[sel, j].tolist(), "N or N m"))
    if refs:
        errs = []
        sources = list(dict.fromkeys(r["source"] for r in refs))
        for r in refs:
            k = int(np.argmin(np.abs(ta - r["t"])))
            sol = a
            if abs(ta[k] - r["t"]) > 1e-12 * max(1.0, abs(r["t"])):
                # not on the output grid: a solve that ends there
                sol = scene.solve(t1=r["t"], **tight)
                if not sol.success:
                    raise _Stop("error", f"the solve to the reference time {r['t']:g} stopped: {sol.message}")
                k = len(np.asarray(sol.t)) - 1
            x = float(np.asarray(getattr(sol, r["quantity"]))[k, r["index"]])
            errs.append((abs(x - r["value"]) / max(1.0, abs(r["value"])), r, x))
        worst = max(errs, key=lambda e: e[0])
        res.metrics["reference_error"] = worst[0]
        res.info["reference_values"] = float(len(refs))
        res.notes.append(f"{len(refs)} reference value(s) of independent origin ({'; '.join(sources)}); "
                         f"worst {worst[1]['field']} at t = {worst[1]['t']:g}: {worst[2]:.15g} against "
                         f"{worst[1]['value']:.15g}")
        res.series.append(Series("reference_error", [e[1]["t"] for e in errs], [e[0] for e in errs], "relative"))
    c.where["formulation_deviation"] = attribution.deviation(
        scene.q_names, scene.v_names, np.asarray(a.q) - np.asarray(b.q), np.asarray(a.v) - np.asarray(b.v))
    res.status = "pass"
    bval = {bd.metric: bd.value for bd in res.budgets}
    _judge(c, _first_times(first_series, bval))
    if res.status == "fail":
        res.reason = "; ".join(br.text() for br in res.breaches)
