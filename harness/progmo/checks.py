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
3. **Budgets**: every metric gets one, the scene's ``[tolerances]`` entry or the documented default
   of :func:`default_budgets`; ``replay_horizon`` shortens the replayed span (recorded in ``span``).
4. **Reference solve** at every RK4 stage time (output_dt = h/2) with rtol <= 1e-12; the replay step
   from ``replay_step`` or a convergence check. Its conditioning warnings are kept.
5. **Model parity** at ``options.samples`` states: the exported model's mass matrix and every
   non-control generalized force the simulator sees (``-bias + passive + harness forces``, the
   scene's point and coordinate forces included) against our ``A`` and ``G + Q``: ``parity_mass``,
   ``parity_bias``. **Instantaneous u** from the simulator's own constrained/inverse dynamics:
   ``instant_u``. When parity breaches its budget the replay is not run: a model mismatch must not
   be blamed on the dynamics.
6. **Open-loop replay** of the solver's u(t): ``replay_residual`` (max |row| of the core's own
   evaluator on the replayed states) and ``replay_deviation`` (max |dq|, |dv| against the solver,
   quaternions up to sign); the growth rate of the deviation is ``info``, not judged. With
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

import dataclasses
import importlib
import math
import time as _time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from .results import SOLVER_ONLY, Breach, Budget, CheckResult, Series, judge

SIMULATORS = ("mujoco", "pinocchio")
#: everything ``run_check`` can check in: the simulators and the solver-only check
CHECKERS = (*SIMULATORS, SOLVER_ONLY)

#: metrics with budgets (``programme_residual`` in a scene's table judges ``solver_residual``)
BUDGETED = ("solver_residual", "parity_mass", "parity_bias", "instant_u", "replay_residual",
            "replay_deviation")
#: metrics of scenes with loop closures (``[[model.closures]]``), budgeted in addition
CLOSURE_BUDGETED = ("parity_closure", "reaction_closure")
#: metrics of scenes with ``[[actuators]]`` (servo-constraints), budgeted in addition
ACTUATOR_BUDGETED = ("replay_unactuated",)
#: metrics of the solver_only check (``reference_error`` only where the scene gives references)
SOLVER_ONLY_BUDGETED = ("solver_residual", "formulation_deviation", "formulation_force_deviation",
                        "reference_error")
#: the scene-table name of a metric's budget where it differs
TABLE_NAME = {"solver_residual": "programme_residual"}

#: the reference solve is tighter than the scene's settings, so that the replay measures the
#: simulator and the per-stage feed of u rather than the solver's own tolerance
REF_RTOL, REF_ATOL = 1e-12, 1e-14

_PACKAGES = {"mujoco": ("mujoco", "mjcf"), "pinocchio": ("pinocchio", "urdf")}


def default_budgets(settings: dict[str, Any]) -> dict[str, tuple[float, str]]:
    """The budget of every metric a scene's ``[tolerances]`` does not give, with its reason
    (documented in src/scene/FORMAT.md, "Default budgets"). ``settings`` is ``Scene.settings``."""
    drift = settings.get("drift", {})
    if drift.get("kind") == "projection":
        tol = float(drift["tol"])
        residual = (100 * tol, f"default: 100 x projection_tol ({tol:g}): the projection holds every "
                               "state row to projection_tol after each step; x100 for samples between "
                               "steps and acceleration rows solved to round-off")
    else:
        residual = (1e4 * REF_RTOL, f"default: drift control {drift.get('kind', '?')}: rows drift with "
                                    f"the integration error of the reference solve (rtol {REF_RTOL:g}); "
                                    "1e4 x rtol")
    return {
        "solver_residual": residual,
        "parity_mass": (1e-11, "default (algebraic identity): exported M vs ours relative to max|A|: "
                               "round-off (catalog <= 2e-15) plus MuJoCo's 1e-14 inertia floor"),
        "parity_bias": (1e-11, "default (algebraic identity): every non-control force the simulator "
                               "applies vs our G + Q, relative to max|G + Q|: round-off (catalog <= 3e-15)"),
        "instant_u": (1e-9, "default (algebraic, through a constraint solve): u from the simulator's "
                            "own dynamics vs ours, relative to max|u| (catalog <= 2e-14; room for the "
                            "condition of B)"),
        "replay_residual": (1e-6, "default (cross-simulator): programme rows on the open-loop replay at "
                                  "the convergence-checked RK4 step (catalog 5e-14 .. 6e-9); an unstable "
                                  "programme needs a replay_horizon and its own budget"),
        "replay_deviation": (1e-6, "default (cross-simulator): max |dq|, |dv| of the replay from the "
                                   "solver (catalog 4e-13 .. 2e-9); an unstable programme needs a "
                                   "replay_horizon and its own budget"),
        "parity_closure": (1e-11, "default (algebraic identity): the simulator's closure Jacobian "
                                  "rows vs ours, both ways, as relative distances to the other's row "
                                  "space (frame and sign free; catalog <= 2e-15)"),
        "reaction_closure": (1e-9, "default (algebraic, through a constraint solve): the closures' "
                                   "generalized reaction J^T f from the simulator's own multipliers under "
                                   "the solver's u vs ours B_c^T lambda_c, relative to its max (Pinocchio "
                                   "catalog <= 1e-13; MuJoCo's soft equalities need a scene budget)"),
        "replay_unactuated": (1e-14, "default (algebraic identity): the part of the replayed force "
                                     "outside range(H), relative to max|u|: u = H tau has exact zeros on "
                                     "joints no actuator drives (along a direction: round-off of the "
                                     "projection, ~1e-16)"),
        "formulation_deviation": (1e-8, f"default (integrated): max |dq|, |dv| between two formulations "
                                        f"solved at rtol {REF_RTOL:g}: both carry the integration error "
                                        "(about 1e4 x rtol for non-stiff scenes) and the conditioning of B"),
        "formulation_force_deviation": (1e-8, "default (integrated): u and reactions of two formulations, "
                                              "relative to their largest value: the state difference "
                                              "propagated through A, G and the multipliers"),
        "reference_error": (1e-8, f"default (integrated): the reference solve (rtol {REF_RTOL:g}) against "
                                  "values of independent origin, max |x - x_ref| / max(1, |x_ref|): the "
                                  "global error of a tight solve; published values need the scene's own "
                                  "budget (their digits)"),
    }


def budgets_for(tolerances: dict[str, tuple[float, str]], settings: dict[str, Any],
                simulator: str, metrics: tuple[str, ...] = BUDGETED) -> list[Budget]:
    """One budget per metric of ``metrics``: ``<name>_<simulator>``, else ``<name>`` from the
    scene's table, else the default."""
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

    #: Replay step; None: the scene's tolerance table `replay_step`, else chosen by a convergence
    #: check (halving until the replay residual stops improving).
    step: float | None = None
    #: Replay horizon; None: the scene's whole time span.
    horizon: float | None = None
    #: Number of sample states of the parity and instantaneous checks.
    samples: int = 8


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
    frame_every: int = 0
    record: Recording | None = None
    scene: Any = None
    backend: Any = None
    tol: dict[str, tuple[float, str]] = field(default_factory=dict)
    horizon: float = 0.0
    ref: Any = None
    first: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    #: system rows whose reactions progmo supplies (export report ``supplied_reaction``)
    supplied: list[str] = field(default_factory=list)


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
         withhold: tuple[str, ...] = (),
         frame_every: int = 0, record: Recording | None = None) -> tuple[CheckResult, Recording | None]:
    """The check. Negative controls: ``corrupt_u(t, u) -> u'`` replaces the replayed (and
    instantaneous-reference) control forces; ``corrupt_export(doc) -> doc'`` alters the exported
    document; ``withhold`` names harness-force kinds the back-end must not apply. ``frame_every``
    > 0 records body frames every that many replay steps; ``record`` is filled with the
    trajectories."""
    t_start = _time.perf_counter()
    c = _Check(str(scene_path), simulator, options or CheckOptions(),
               CheckResult(scene=str(scene_path), simulator=simulator, status="error"),
               corrupt_u, corrupt_export, tuple(withhold), frame_every, record)
    steps = (_scene, _solver_only) if simulator == SOLVER_ONLY else (
        _scene, _export, _budgets, _reference, _parity, _replay)
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

    pkg, fmt = _PACKAGES[c.simulator]
    try:
        importlib.import_module(pkg)
        mod = importlib.import_module(f".simulators.{c.simulator}_sim", __package__)
    except ImportError as e:
        raise _Stop("error", f"simulator package for {c.simulator} is not importable: {e}") from None
    try:
        doc, report = c.scene.export(fmt, supply_reactions=True)
    except ExportUnsupported as e:
        raise _Stop("not_checked", f"{fmt.upper()} export: {e}") from None
    except ValueError as e:
        raise _Stop("error", f"export failed: {e}") from None
    _supplied_route(c, report)
    if c.corrupt_export is not None:
        doc = c.corrupt_export(doc)
    cls = mod.MujocoBackend if c.simulator == "mujoco" else mod.PinocchioBackend
    try:
        c.backend = cls(doc, report, c.scene, c.withhold)
    except Unsupported as e:
        raise _Stop("not_checked", str(e)) from None
    except Exception as e:
        raise _Stop("error", f"{c.simulator} rejected the exported model: {type(e).__name__}: {e}") from None
    c.res.notes += c.backend.notes()
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
        ACTUATOR_BUDGETED if c.scene.actuators else ())
    c.res.budgets = budgets_for(c.tol, dict(c.scene.settings), c.simulator, metrics)
    full = c.scene.t1 - c.scene.t0
    horizon = c.options.horizon or (c.tol["replay_horizon"][0] if "replay_horizon" in c.tol else full)
    c.horizon = min(horizon, full)
    c.res.span = [c.horizon, full]
    if c.horizon < full:
        why = c.tol["replay_horizon"][1] if "replay_horizon" in c.tol and not c.options.horizon else "given by the options"
        c.res.notes.append(f"replay horizon {c.horizon:g} s of {full:g} s ({why})")


def _solve_reference(c: _Check, h: float):
    """The solver's motion at every RK4 stage time of step h (output_dt = h/2)."""
    from .simulators.replay import Reference

    n = int(round(c.horizon / h))
    if n < 2 or abs(n * h - c.horizon) > 1e-9 * max(1.0, c.horizon):
        raise _Stop("error", f"replay step {h:g} does not divide the replayed span {c.horizon:g} s")
    t0s = _time.perf_counter()
    scene = c.scene
    st = scene.settings
    sol = scene.solve(output_dt=h / 2, t1=scene.t0 + n * h,
                      rtol=min(st["rtol"], REF_RTOL), atol=min(st["atol"], REF_ATOL))
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
                    np.asarray(sol.residuals), h, n, scene.t0, _time.perf_counter() - t0s,
                    lam, np.asarray(sol.residual_rates))
    if scene.actuation_varies:  # H(t, q): the replay applies H at the simulator's state
        m = len(scene.actuators)
        ref.actuation = lambda tk, qk: np.asarray(scene.actuation_map_at(tk, qk))
        ref.tau, ref.u_model = lam[:, :m], u_model
    if c.supplied:  # rows the simulator does not hold: their reactions, from this solve
        ref.supplied = supplied_reactions(scene, c.supplied, t, ref.q, ref.v, lam)
    return ref


def _replay_of(c: _Check, ref):
    fe = c.frame_every if c.frame_every >= 0 else max(1, -(-ref.steps // 1000))  # -1: <= ~1000 samples
    if ref.supplied is not None and "supplied_reaction" in c.withhold:  # negative control
        ref = dataclasses.replace(ref, supplied=None)
    return c.backend.replay(ref, fe)


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
    elif "replay_step" in c.tol:
        h, why = c.tol["replay_step"][0], f"scene tolerance replay_step: {c.tol['replay_step'][1]}"
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
    c.res.notes.append(f"replay step h = {h:g} ({why}); RK4 with u at every stage "
                       f"(solver output_dt = h/2, solve {c.ref.solve_seconds:.2f} s)")
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
        sM, sR = max(sM, float(np.abs(A).max())), max(sR, float(np.abs(rhs).max()))
        B = np.asarray(dyn["B"])
        us = be.instant_u(tk, qk, vk, ak, B, np.asarray(dyn["gamma"]), programme,
                          actuated=bool(scene.actuators))
        dU.append(float(np.abs(us - applied[k]).max()))
        if closures:
            Jsim = be.closure_jacobian(tk, qk, vk)
            dJ.append(row_space_distance(B[closure_idx], Jsim))
            # closure reactions: ours B_c^T lambda_c; the simulator's J^T f under the same u
            ours_r = B[closure_idx].T @ np.asarray(ref.lam[k])[closure_idx]
            sim_r = Jsim.T @ be.closure_forces(tk, qk, vk, applied[k])
            dR.append(float(np.abs(sim_r - ours_r).max()))
            sRc = max(sRc, float(np.abs(ours_r).max()))
    sR = sR if sR > 0 else 1.0
    # u relative to its own scale; without a programme (u = 0) relative to the forces.
    uabs = float(np.abs(applied).max()) if applied.size else 0.0
    sU = uabs if uabs > 0 else sR
    pm, pb, iu = np.array(dmt) / max(sM, 1e-300), np.array(drt) / sR, np.array(dU) / sU
    c.res.metrics.update(parity_mass=float(pm.max()), parity_bias=float(pb.max()), instant_u=float(iu.max()))
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
    bad = [m for m in gate if not (c.res.metrics[m] <= bval[m])]
    if bad:
        c.res.notes.append("model parity failed (" + ", ".join(bad) + "): the exported model differs "
                           "from ours, the replay was not run and nothing is blamed on the dynamics")
        # Judge what was measured; the replay's budgets stay listed, unmeasured and unjudged.
        budgets = c.res.budgets
        c.res.budgets = [b for b in budgets if b.metric in c.res.metrics]
        c.res.status = "pass"  # judge() decides
        judge(c.res, _first_times(c.first, bval))
        c.res.budgets = budgets
        c.res.reason = "model parity: " + "; ".join(
            f"{b.metric} {b.value:.3g} > {b.budget:.3g}" for b in c.res.breaches
            if b.metric in gate) + "; replay not run"
        raise _Stop(c.res.status, c.res.reason)


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


def _replay(c: _Check) -> None:
    """Open-loop replay of u in the simulator, its metrics and the verdict."""
    from .simulators import BlowUp
    from .simulators.replay import downsample, growth_rate, quat_aware_diff

    scene, ref, be, res = c.scene, c.ref, c.backend, c.res
    t0r = _time.perf_counter()
    blowup: BlowUp | None = None
    try:
        rp = _replay_of(c, ref)
    except BlowUp as e:
        # Keep the evidence: judge the replay up to its last finite sample, and report the blow-up
        # as a breach with its time and quantity (a failure of the forces, not of the check).
        if e.partial is None or len(e.partial.t) < 2:
            res.breaches = [Breach("replay_blowup", e.value, e.limit, e.time)]
            raise _Stop("fail", f"{c.simulator} replay: {e}") from None
        blowup, rp = e, e.partial
        res.span = [float(rp.t[-1]) - scene.t0, res.span[1] if res.span else c.horizon]
        res.notes.append(f"{c.simulator} replay: {e}; the metrics cover the replay up to "
                         f"t = {rp.t[-1]:.6g}, the last finite sample")
    res.notes.append(f"replay of {len(rp.t) - 1} of {ref.steps} steps took {_time.perf_counter() - t0r:.2f} s")
    R = _replay_residual(c, ref, rp)
    rabs = np.abs(R).max(axis=1) if R.shape[1] else np.zeros(len(rp.t))
    rq, rv = ref.q[::2][: len(rp.t)], ref.v[::2][: len(rp.t)]
    dev = np.maximum(quat_aware_diff(be.cm, rp.q, rq).max(axis=1), np.abs(rp.v - rv).max(axis=1))
    if not np.all(np.isfinite(rabs)):
        raise _Stop("error", f"{c.simulator} replay: non-finite programme residual at "
                             f"t = {rp.t[np.argmax(~np.isfinite(rabs))]:.6g}")
    res.metrics["replay_residual"] = float(rabs.max())
    closures = be.report.get("closures", [])
    if closures and R.shape[1]:  # the closure rows alone (info: how well the simulator holds the loops)
        names = [r["name"] for r in scene.rows]
        ci = [names.index(r) for cl in closures for r in cl["rows"] if r not in cl["set_aside"]]
        res.info["replay_closure_residual"] = float(np.abs(R[:, ci]).max())
    if c.supplied and R.shape[1]:  # the supplied rows alone: how well their reactions held them
        names = [r["name"] for r in scene.rows]
        si = [names.index(r) for r in c.supplied]
        res.info["replay_supplied_residual"] = float(np.abs(R[:, si]).max())
    res.metrics["replay_deviation"] = float(dev.max())
    if scene.actuators:  # servo-constraints: the force fed to the simulator acts on actuated joints only
        H = (np.array([scene.actuation_map_at(tk, qk) for tk, qk in zip(ref.t, ref.q)])
             if scene.actuation_varies else scene.actuation_map)
        res.metrics["replay_unactuated"] = unactuated_force(ref.u, H)
    g = growth_rate(rp.t, dev)
    res.info["replay_growth_rate"] = g
    if math.isfinite(g) and g * c.horizon > math.log(100):
        res.notes.append(f"open-loop deviation grows like exp({g:.3g} t): x{math.exp(g * c.horizon):.2g} "
                         f"over the replayed {c.horizon:g} s (unstable programme"
                         + (f"; the scene's budgets are stated for {c.tol['replay_horizon'][0]:g} s)"
                            if "replay_horizon" in c.tol else ")"))
    c.first.update({"replay_residual": (rp.t, rabs), "replay_deviation": (rp.t, dev)})
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
    if c.record is not None:
        rec = c.record
        rec.scene, rec.ref, rec.replay = scene, ref, rp
        rec.residual, rec.deviation = R, dev
        rec.sample_times = c.first["parity_mass"][0].tolist()
        rec.q_names, rec.v_names = list(scene.q_names), list(scene.v_names)
        rec.row_names = [r["name"] for r in scene.rows]
    res.status = "pass"
    bval = {b.metric: b.value for b in res.budgets}
    judge(res, _first_times(c.first, bval))
    if blowup is not None:
        res.breaches.insert(0, Breach("replay_blowup", blowup.value, blowup.limit, blowup.time))
        res.status = "fail"
    if res.status == "fail":
        res.reason = "; ".join(
            (f"{c.simulator} replay: {blowup}" if b.metric == "replay_blowup" and blowup is not None else
             f"{b.metric} {b.value:.3g} > {b.budget:.3g}"
             + (f" first at t = {b.first_time:.6g}" if b.first_time is not None else ""))
            for b in res.breaches)


def unactuated_force(u: np.ndarray, H: np.ndarray) -> float:
    """The largest part of u(t) no actuator can produce, relative to max |u| (0 when u = 0): on
    joint actuators (unit columns of H) max |u_j| over the joints j none drives, read exactly; else
    the component of u outside range(H), |u - Q Q^T u| with Q an orthonormal basis of range(H).
    H is one n x m map, or one per sample of u (K x n x m) for a state-dependent map."""
    u, H = np.asarray(u), np.asarray(H)
    scale = float(np.abs(u).max()) if u.size else 0.0
    if scale == 0.0:
        return 0.0
    if H.ndim == 3:
        return max(unactuated_force(uk[None, :], Hk) * float(np.abs(uk).max()) for uk, Hk in zip(u, H)) / scale
    unit = all(np.count_nonzero(c) == 1 and c[np.flatnonzero(c)[0]] == 1.0 for c in H.T)
    if unit:
        free = [j for j in range(u.shape[1]) if not H[j].any()]
        return float(np.abs(u[:, free]).max()) / scale if free else 0.0
    Q, _ = np.linalg.qr(H)
    off = u - (u @ Q) @ Q.T
    return float(np.abs(off).max()) / scale


def _first_times(first: dict, bval: dict) -> dict:
    from .simulators.replay import first_time_above

    out = {}
    for m, (t, x) in first.items():
        if m in bval:
            ft = first_time_above(np.asarray(t), np.asarray(x), bval[m])
            if ft is not None:
                out[m] = ft
    return out


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
    res.status = "pass"
    bval = {bd.metric: bd.value for bd in res.budgets}
    judge(res, _first_times(first_series, bval))
    if res.status == "fail":
        res.reason = "; ".join(f"{br.metric} {br.value:.3g} > {br.budget:.3g}" for br in res.breaches)
