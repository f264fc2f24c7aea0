"""Which element a failed metric comes from: a verdict that says *what* broke, not only how much.

Every function takes what a check step measured and returns a short phrase for ``Breach.where``
(``results.py``) and the reason ("joint q2", "joints q1, q2", "coordinate q1", "row tip_z",
"closure loop"); "" when nothing singles an element out.

* parity_mass: the entry of the worst |M_sim - A| (its two joints);
* parity_bias, instant_u: the joint of the worst entry; for parity_bias also a harness force of the
  export report (``harness_forces``: attractors, springs, dampers, point and coordinate forces)
  when the discrepancy is that force's generalized force times a factor (:func:`force_explaining`:
  a force the simulator misses reads "x -1");
* replay_deviation: the coordinate (q) or velocity (v) that deviates most; replay_residual: the row;
* replay_unactuated: the joint carrying most of the force no actuator produces;
* parity_closure: the closure whose rows lie farthest from the simulator's closure row space;
  reaction_closure: the closure whose rows carry most of the reaction's discrepancy.
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

#: a harness force "explains" a discrepancy d when d - alpha f leaves at most this fraction of |d|
EXPLAINED = 1e-3


def worst(diffs: Sequence[np.ndarray]) -> tuple[int, tuple[int, ...]]:
    """(sample, entry index) of the largest |x| over a list of per-sample arrays."""
    k = int(np.argmax([float(np.abs(d).max()) if np.size(d) else -1.0 for d in diffs]))
    d = np.abs(np.asarray(diffs[k]))
    return k, tuple(int(i) for i in np.unravel_index(int(np.argmax(d)), d.shape))


def joint(v_names: Sequence[str], diffs: Sequence[np.ndarray]) -> str:
    """"joint q2" for the largest entry of per-sample generalized-force differences."""
    if not diffs or not any(np.size(d) for d in diffs):
        return ""
    _, (i,) = worst(diffs)
    return f"joint {v_names[i]}"


def mass_entry(v_names: Sequence[str], diffs: Sequence[np.ndarray]) -> str:
    """"joint q2" (a diagonal entry) or "joints q1, q2" for the largest |M_sim - A| entry."""
    if not diffs or not any(np.size(d) for d in diffs):
        return ""
    _, (i, j) = worst(diffs)
    i, j = min(i, j), max(i, j)
    return f"joint {v_names[i]}" if i == j else f"joints {v_names[i]}, {v_names[j]}"


def deviation(q_names: Sequence[str], v_names: Sequence[str], dq: np.ndarray, dv: np.ndarray) -> str:
    """The coordinate (``dq``: samples x nq) or velocity (``dv``: samples x nv) whose replay
    deviates most from the solver."""
    mq = float(np.abs(dq).max()) if dq.size else -1.0
    mv = float(np.abs(dv).max()) if dv.size else -1.0
    if mq < 0 and mv < 0:
        return ""
    if mq >= mv:
        return f"coordinate {q_names[int(np.argmax(np.abs(dq).max(axis=0)))]}"
    return f"velocity {v_names[int(np.argmax(np.abs(dv).max(axis=0)))]}"


def row(row_names: Sequence[str], R: np.ndarray) -> str:
    """The row of the largest |residual| (``R``: samples x rows)."""
    if not R.size:
        return ""
    return f"row {row_names[int(np.argmax(np.abs(R).max(axis=0)))]}"


def unactuated(v_names: Sequence[str], off: np.ndarray) -> str:
    """The joint carrying the largest part of u outside range(H) (``off``: samples x n, the core's
    ``Scene.unactuated_part``): where the replayed force acts that no actuator can produce."""
    off = np.asarray(off)
    if not off.size or not np.abs(off).max() > 0:
        return ""
    return f"joint {v_names[int(np.argmax(np.abs(off).max(axis=0)))]}"


def _closure_rows(closures: list[dict], row_names: Sequence[str], closure_idx: Sequence[int]) -> dict[str, list[int]]:
    """Closure name -> positions of its (kept) rows within ``closure_idx``."""
    pos = {row_names[r]: k for k, r in enumerate(closure_idx)}
    return {cl["name"]: [pos[r] for r in cl["rows"] if r in pos] for cl in closures}


def _distance_from(x: np.ndarray, Y: np.ndarray) -> float:
    """Relative distance of a row x from the row space of Y."""
    n = float(np.linalg.norm(x))
    if n == 0.0:
        return 0.0
    if not Y.size:
        return 1.0
    _, S, Vt = np.linalg.svd(Y, full_matrices=False)
    basis = Vt[S > 1e-12 * S.max()] if S.size and S.max() > 0 else Vt[:0]
    return float(np.linalg.norm(x - basis.T @ (basis @ x))) / n


def closure_parity(closures: list[dict], row_names: Sequence[str], closure_idx: Sequence[int],
                   ours: np.ndarray, sim: np.ndarray) -> str:
    """The closure whose rows (of ``ours``: the closure rows of B) lie farthest from the
    simulator's closure row space (``sim``); "" when ours all lie in it (the mismatch is a
    simulator row outside ours)."""
    best, name = 0.0, ""
    for cl, idx in _closure_rows(closures, row_names, closure_idx).items():
        dist = max((_distance_from(ours[k], sim) for k in idx), default=0.0)
        if dist > best:
            best, name = dist, cl
    return f"closure {name}" if name and best > 1e-12 else ""


def closure_reaction(closures: list[dict], row_names: Sequence[str], closure_idx: Sequence[int],
                     ours: np.ndarray, d: np.ndarray) -> str:
    """The closure whose rows (of ``ours``) carry the largest part of the reaction discrepancy
    ``d`` (a generalized force): its projection onto each closure's row space."""
    best, name = 0.0, ""
    for cl, idx in _closure_rows(closures, row_names, closure_idx).items():
        if not idx:
            continue
        Y = ours[idx]
        part = float(np.linalg.norm(d)) * (1.0 - _distance_from(d, Y)) if np.linalg.norm(d) > 0 else 0.0
        if part > best:
            best, name = part, cl
    return f"closure {name}" if name else ""


def force_label(kind: str, forces: list[dict]) -> str:
    """"the point force on body arm" (one force of the kind), else "the scene's point forces"."""
    what = kind.replace("_", " ")
    if len(forces) == 1:
        hf = forces[0]
        on = hf.get("body") or hf.get("joint") or hf.get("v_name") or ""
        return f"the {what}" + (f" on {on}" if on else "")
    return f"the scene's {what}s"


def force_explaining(d: np.ndarray, contributions: dict[str, np.ndarray]) -> str:
    """The force (label -> its generalized force as the simulator applies it) that explains a
    discrepancy ``d`` = simulator - ours: d = alpha f up to :data:`EXPLAINED` of |d|. Phrased
    "the point force on arm (x -1: the simulator misses it)"."""
    nd = float(np.linalg.norm(d))
    if nd == 0.0:
        return ""
    best: tuple[float, str, float] | None = None
    for label, f in contributions.items():
        ff = float(f @ f)
        if ff == 0.0:
            continue
        alpha = float(d @ f) / ff
        rest = float(np.linalg.norm(d - alpha * f)) / nd
        if rest <= EXPLAINED and (best is None or rest < best[0]):
            best = (rest, label, alpha)
    if best is None:
        return ""
    _, label, alpha = best
    note = ": the simulator misses it" if abs(alpha + 1) < 1e-3 else ""
    return f"{label} (discrepancy = {alpha:.3g} x its force{note})"


def harness_forces(report: dict, make_backend: Callable[[tuple[str, ...]], object] | None,
                   t: float, q: np.ndarray, v: np.ndarray) -> dict[str, np.ndarray]:
    """Each harness-force kind's generalized force at (t, q, v) as the simulator applies it: the
    difference of ``model_terms`` between a back-end with every force and one without that kind
    (``make_backend(withhold)``). {} without a report's harness forces or a way to build back-ends."""
    by_kind: dict[str, list[dict]] = {}
    for hf in report.get("harness_forces", []):
        by_kind.setdefault(hf["kind"], []).append(hf)
    if not by_kind or make_backend is None:
        return {}
    full = make_backend(())
    _, r_full = full.model_terms(t, q, v)  # type: ignore[attr-defined]
    out = {}
    for kind, forces in by_kind.items():
        _, r_without = make_backend((kind,)).model_terms(t, q, v)  # type: ignore[attr-defined]
        out[force_label(kind, forces)] = np.asarray(r_full) - np.asarray(r_without)
    return out
