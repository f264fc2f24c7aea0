"""Per-scene, per-simulator checks: model parity, open-loop replay of u(t), instantaneous u.

Interface used by the nightly command (``cli.py``) and the report:

``run_check(scene_path, simulator, options) -> CheckResult`` where ``simulator`` is ``"mujoco"`` or
``"pinocchio"``; it never raises for a scene or simulator problem: a scene the simulator cannot
represent gives ``status="skipped"`` with the reason, a missing package or a simulator failure gives
``status="error"`` with the reason (see ``results.py``).

What a check does (back-ends in ``simulators/``):

1. **Model parity** at ``options.samples`` states along the solver's trajectory: the exported model's
   mass matrix and its non-control generalized forces (``-bias + passive + harness forces``, i.e. all
   field forces the simulator sees, mapped to our coordinates) against our ``A`` and ``G + Q``.
   Metrics ``parity_mass``, ``parity_bias`` (relative to max |A|, max |G + Q|). When parity breaches
   its budget the replay is not run: a model mismatch must not be blamed on the dynamics.
2. **Open-loop replay** of the solver's u(t) (solved at output_dt = h/2, so u is exact at every RK4
   stage) from the scene's initial state. Metrics ``replay_residual`` (max |row| of the core's own
   evaluator on the replayed states, acceleration rows with the simulator's accelerations) and
   ``replay_deviation`` (max |dq|, |dv| against the solver, quaternions up to sign), and
   ``replay_growth_rate`` (log-linear fit of the deviation, 1/s; reported, not budgeted).
3. **Instantaneous u** at the sample states: Pinocchio's constrained forward dynamics (u = J^T lambda)
   or MuJoCo's inverse dynamics (qfrc_inverse minus harness forces), relative to max |u|: ``instant_u``.
4. ``solver_residual``: max |row| of the reference solve, against the scene's ``programme_residual``.

Budgets come from the scene's ``[tolerances]``: an entry named like a metric (``parity_mass``,
``parity_bias``, ``replay_residual``, ``replay_deviation``, ``instant_u``) is its budget; an entry
``<metric>_mujoco`` / ``<metric>_pinocchio`` overrides it for one simulator. ``replay_step`` fixes the
step (else a convergence check picks it) and ``replay_horizon`` shortens the replayed span (for
unstable programmes, whose open-loop error grows exponentially: the growth rate is reported).
"""

from __future__ import annotations

import importlib
import math
import time as _time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from .results import Budget, CheckResult, Series, judge

SIMULATORS = ("mujoco", "pinocchio")

#: metrics with budgets from the tolerance table (``programme_residual`` judges ``solver_residual``)
BUDGETED = ("parity_mass", "parity_bias", "replay_residual", "replay_deviation", "instant_u")

#: the reference solve is tighter than the scene's settings, so that the replay measures the
#: simulator and the per-stage feed of u rather than the solver's own tolerance
REF_RTOL, REF_ATOL = 1e-12, 1e-14

_PACKAGES = {"mujoco": ("mujoco", "mjcf"), "pinocchio": ("pinocchio", "urdf")}


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


def run_check(scene_path: str, simulator: str, options: CheckOptions | None = None) -> CheckResult:
    """Check one scene in one simulator; never raises (see the module docs)."""
    return _run(scene_path, simulator, options)[0]


def _load_backend(simulator: str):
    """Import the simulator's package and back-end; ImportError names the missing package."""
    pkg, fmt = _PACKAGES[simulator]
    importlib.import_module(pkg)
    mod = importlib.import_module(f".simulators.{simulator}_sim", __package__)
    return mod, fmt


def _run(scene_path: str, simulator: str, options: CheckOptions | None = None, *,
         corrupt_u: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
         frame_every: int = 0, record: Recording | None = None) -> tuple[CheckResult, Recording | None]:
    """The check. ``corrupt_u(t, u) -> u'`` replaces the replayed (and instantaneous-reference)
    control forces: the negative control. ``frame_every`` > 0 records body frames every that many
    replay steps; ``record`` is filled with the trajectories."""
    t_start = _time.perf_counter()
    options = options or CheckOptions()
    res = CheckResult(scene=str(scene_path), simulator=simulator, status="error")
    try:
        _check(res, scene_path, simulator, options, corrupt_u, frame_every, record)
    except Exception as e:  # never raise out of a check
        res.status = "error"
        res.reason = res.reason or f"{type(e).__name__}: {e}"
    res.wall_seconds = _time.perf_counter() - t_start
    return res, record


def _fail(res: CheckResult, status: str, reason: str) -> None:
    res.status, res.reason = status, reason


class _Stop(Exception):
    pass


def _check(res, scene_path, simulator, options, corrupt_u, frame_every, record):
    from . import Scene  # the Rust core
    from .simulators import BlowUp
    from .simulators.replay import Reference

    if simulator not in SIMULATORS:
        return _fail(res, "error", f"unknown simulator {simulator!r} (one of {', '.join(SIMULATORS)})")
    try:
        scene = Scene(str(scene_path))
    except Exception as e:
        return _fail(res, "error", f"cannot load scene: {e}")
    res.scene = scene.name
    if scene.kind != "tree":
        return _fail(res, "skipped", f"{scene.kind} scene: only kinematic trees can be exported to "
                                     f"{simulator} (no MJCF/URDF for a mass-matrix-and-constraints model)")
    try:
        mod, fmt = _load_backend(simulator)
    except ImportError as e:
        return _fail(res, "error", f"simulator package for {simulator} is not importable: {e}")
    try:
        doc, report = scene.export(fmt)
    except ValueError as e:
        msg = str(e)
        if "unsupported" in msg.lower():
            return _fail(res, "skipped", f"{fmt.upper()} cannot represent the scene: {msg}")
        return _fail(res, "error", f"export failed: {msg}")
    try:
        be = (mod.MujocoBackend if simulator == "mujoco" else mod.PinocchioBackend)(doc, report)
    except Exception as e:
        return _fail(res, "error", f"{simulator} rejected the exported model: {type(e).__name__}: {e}")
    res.notes += be.notes()

    tol = {k: (float(v[0]), str(v[1])) for k, v in dict(scene.tolerances).items()}
    T_full = scene.t1 - scene.t0
    horizon = options.horizon or (tol["replay_horizon"][0] if "replay_horizon" in tol else T_full)
    horizon = min(horizon, T_full)
    if horizon < T_full:
        res.notes.append(f"replay horizon {horizon:g} s of {T_full:g} s"
                         + (f" ({tol['replay_horizon'][1]})" if "replay_horizon" in tol and not options.horizon else ""))
    accel_rows = any(r["level"] == "acceleration" for r in scene.rows)

    def reference(h: float) -> Reference:
        n = int(round(horizon / h))
        if n < 2 or abs(n * h - horizon) > 1e-9 * max(1.0, horizon):
            raise _Stop(f"replay step {h:g} does not divide the horizon {horizon:g}")
        t0s = _time.perf_counter()
        st = scene.settings
        sol = scene.solve(output_dt=h / 2, t1=scene.t0 + n * h,
                          rtol=min(st["rtol"], REF_RTOL), atol=min(st["atol"], REF_ATOL))
        if not sol["success"]:
            raise _Stop(f"solve failed: {sol['code_name']} at t = {sol['t_end']}")
        t = np.asarray(sol["t"])
        if len(t) != 2 * n + 1 or np.abs(t - (scene.t0 + 0.5 * h * np.arange(2 * n + 1))).max() > 1e-9:
            raise _Stop(f"solver output grid does not match the stages of h = {h:g} "
                        f"({len(t)} outputs for {2 * n + 1} stage times)")
        u = np.array(sol["u"])
        if corrupt_u is not None:
            u = np.array([corrupt_u(tk, uk) for tk, uk in zip(t, u)])
        return Reference(t, np.asarray(sol["q"]), np.asarray(sol["v"]), np.asarray(sol["a"]), u,
                         np.asarray(sol["residual"]), h, n, scene.t0, _time.perf_counter() - t0s)

    def replay(ref):
        fe = frame_every if frame_every >= 0 else max(1, -(-ref.steps // 1000))  # -1: <= ~1000 samples
        return be.replay(ref, fe)

    def replay_residual(ref, rp):
        r = np.asarray(scene.residuals(rp.t, rp.q, rp.v, rp.a if accel_rows else None))
        return r

    try:
        # ---- step
        if options.step:
            h, why = options.step, "given by the options"
            ref = reference(h)
        elif "replay_step" in tol:
            h, why = tol["replay_step"][0], f"scene tolerance replay_step: {tol['replay_step'][1]}"
            ref = reference(h)
        else:
            # halve from 1e-2 while the residual still improves like a 4th-order method (>= 8x
            # per halving, i.e. 16x up to a factor 2); stop at round-off or after 5 halvings
            h = min(1e-2, horizon / 100)
            ref = reference(h)
            prev = float(np.abs(replay_residual(ref, replay(ref))).max())
            seq = [f"{h:g}: {prev:.1e}"]
            for _ in range(5):
                if not prev > 1e-13:
                    break
                ref2 = reference(h / 2)
                cur = float(np.abs(replay_residual(ref2, replay(ref2))).max())
                seq.append(f"{h / 2:g}: {cur:.1e}")
                improved = cur < prev / 8
                h, ref, prev = h / 2, ref2, cur
                if not improved:
                    break
            why = "convergence check, residual by step " + ", ".join(seq)
        res.notes.append(f"replay step h = {h:g} ({why}); RK4 with u at every stage "
                         f"(solver output_dt = h/2, solve {ref.solve_seconds:.2f} s)")
        res.metrics["replay_step"] = h
        res.metrics["solver_residual"] = float(np.nanmax(np.abs(ref.residual))) if ref.residual.size else 0.0

        # ---- sample states, parity
        ns = max(1, options.samples)
        idx = np.unique(np.linspace(0, 2 * ref.steps, ns).round().astype(int))
        times = ref.t[idx]
        sM = sR = 0.0
        dmt, drt, dU = [], [], []
        sU = max(float(np.abs(ref.u).max()), 1e-300)
        for k in idx:
            tk, qk, vk, ak = ref.t[k], ref.q[k], ref.v[k], ref.a[k]
            dyn = scene.dynamics(tk, qk, vk)
            A = np.asarray(dyn["mass"])
            rhs = np.asarray(dyn["velocity_terms"]) + np.asarray(dyn["applied_forces"])
            Ms, rs = be.model_terms(tk, qk, vk)
            dmt.append(float(np.abs(Ms - A).max()))
            drt.append(float(np.abs(rs - rhs).max()))
            sM, sR = max(sM, float(np.abs(A).max())), max(sR, float(np.abs(rhs).max()))
            us = be.instant_u(tk, qk, vk, ak, np.asarray(dyn["B"]), np.asarray(dyn["gamma"]))
            dU.append(float(np.abs(us - ref.u[k]).max()))
        sR = sR if sR > 0 else 1.0
        pm = np.array(dmt) / max(sM, 1e-300)
        pb = np.array(drt) / sR
        iu = np.array(dU) / sU
        res.metrics["parity_mass"] = float(pm.max())
        res.metrics["parity_bias"] = float(pb.max())
        res.metrics["instant_u"] = float(iu.max())
        res.notes.append(f"parity scales: max|A| {sM:.3g}, max|G+Q| {sR:.3g}; instant_u scale max|u| {sU:.3g}; "
                         f"{len(idx)} sample states")
        first = {"parity_mass": (times, pm), "parity_bias": (times, pb), "instant_u": (times, iu)}

        budgets = _budgets(tol, simulator)
        res.budgets = budgets
        bval = {b.metric: b.value for b in budgets}
        parity_bad = [m for m in ("parity_mass", "parity_bias")
                      if m in bval and not (res.metrics[m] <= bval[m])]
        if parity_bad:
            res.notes.append("model parity failed (" + ", ".join(parity_bad) + "): the exported model "
                             "differs from ours, the replay was not run and nothing is blamed on the dynamics")
            res.budgets = [b for b in budgets if b.metric in ("parity_mass", "parity_bias")]
            res.status = "pass"  # judge() leaves error/skipped alone
            judge(res, _first_times(first, bval))
            res.reason = "model parity: " + ", ".join(f"{b.metric} {b.value:.3g} > {b.budget:.3g}"
                                                      for b in res.breaches)
            return

        # ---- replay
        t0r = _time.perf_counter()
        try:
            rp = replay(ref)
        except BlowUp as e:
            return _fail(res, "error", f"{simulator} replay: {e}")
        res.notes.append(f"replay of {ref.steps} steps took {_time.perf_counter() - t0r:.2f} s")
        R = replay_residual(ref, rp)
        from .simulators.replay import quat_aware_diff, growth_rate, downsample
        rabs = np.abs(R).max(axis=1) if R.shape[1] else np.zeros(len(rp.t))
        rq, rv = ref.q[::2][: ref.steps + 1], ref.v[::2][: ref.steps + 1]
        dq = quat_aware_diff(be.cm, rp.q, rq).max(axis=1)
        dv = np.abs(rp.v - rv).max(axis=1)
        dev = np.maximum(dq, dv)
        if not np.all(np.isfinite(rabs)):
            return _fail(res, "error", f"{simulator} replay: non-finite programme residual at "
                                       f"t = {rp.t[np.argmax(~np.isfinite(rabs))]:.6g}")
        res.metrics["replay_residual"] = float(rabs.max())
        res.metrics["replay_deviation"] = float(dev.max())
        g = growth_rate(rp.t, dev)
        res.metrics["replay_growth_rate"] = g
        if math.isfinite(g) and g * horizon > math.log(100):
            res.notes.append(f"open-loop deviation grows like exp({g:.3g} t): x{math.exp(g * horizon):.2g} "
                             f"over the replayed {horizon:g} s (unstable programme"
                             + (f"; the scene's budgets are stated for {tol['replay_horizon'][0]:g} s)"
                                if "replay_horizon" in tol else ")"))
        first.update({"replay_residual": (rp.t, rabs), "replay_deviation": (rp.t, dev)})

        sel = downsample(len(rp.t))
        res.series.append(Series("replay_residual", rp.t[sel].tolist(), rabs[sel].tolist(), "row units"))
        res.series.append(Series("replay_deviation", rp.t[sel].tolist(), dev[sel].tolist(), "q/v units"))
        selu = downsample(len(ref.t))
        for j, name in enumerate(scene.v_names):
            res.series.append(Series(f"u.{name}", ref.t[selu].tolist(), ref.u[selu, j].tolist(), "N or N m"))
        if record is not None:
            record.scene, record.ref, record.replay = scene, ref, rp
            record.residual, record.deviation = R, dev
            record.sample_times = times.tolist()
            record.q_names, record.v_names = list(scene.q_names), list(scene.v_names)
            record.row_names = [r["name"] for r in scene.rows]
        res.status = "pass"
        judge(res, _first_times(first, bval))
        if res.status == "fail":
            res.reason = "; ".join(
                f"{b.metric} {b.value:.3g} > {b.budget:.3g}"
                + (f" first at t = {b.first_time:.6g}" if b.first_time is not None else "")
                for b in res.breaches)
    except _Stop as e:
        return _fail(res, "error", str(e))


def _budgets(tol: dict, simulator: str) -> list[Budget]:
    out = []
    if "programme_residual" in tol:
        v, why = tol["programme_residual"]
        out.append(Budget("solver_residual", v, f"programme_residual: {why}"))
    for m in BUDGETED:
        key = f"{m}_{simulator}" if f"{m}_{simulator}" in tol else m
        if key in tol:
            v, why = tol[key]
            out.append(Budget(m, v, why))
    return out


def _first_times(first: dict, bval: dict) -> dict:
    from .simulators.replay import first_time_above
    out = {}
    for m, (t, x) in first.items():
        if m in bval:
            ft = first_time_above(np.asarray(t), np.asarray(x), bval[m])
            if ft is not None:
                out[m] = ft
    return out
