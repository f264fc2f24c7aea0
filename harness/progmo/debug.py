"""``progmo debug SCENE [--simulator mujoco|pinocchio|drake|all] [--out DIR]``: run the check with full
recording and write what a person needs to see where a replay leaves the programme:

* ``DIR/<scene>.mcap`` (JSON messages, jsonschema schemas; open in Foxglove with the layout
  harness/progmo/foxglove/progmo.json): the solver's motion on the topics and schemas of
  ``progmo solve`` (``/progmo/state``, ``/progmo/control``, ``/progmo/residual``, ``/progmo/tf``,
  ``/progmo/scene`` drawn as a translucent ghost) at the replay's sample times; each simulator's
  replay on ``/<sim>/state``, ``/<sim>/residual`` (same schemas), ``/<sim>/deviation``,
  ``/<sim>/tf`` (world -> ``<sim>/<body>`` from the simulator's own kinematics: MuJoCo
  ``xpos``/``xquat``, Pinocchio ``oMf``), ``/<sim>/scene`` (the mechanism on those frames) and the
  breaches on ``/<sim>/breach``; the scene's view targets once on ``/progmo/scene`` and, at the end,
  the traces of the programme's sites (``<prefix>/trace/<site>``) for the solver and each replay;
* ``DIR/<scene>_<sim>.csv``: solver columns named as in ``progmo solve``'s CSV (``t``, ``q:<q>``,
  ``v:<v>``, ``u:<v>``), the replay's (``<sim>.q:<q>``, ``<sim>.v:<v>``, ``<sim>.residual:<row>``)
  and ``deviation``, per replay sample (up to the last finite state when the simulator blows up);
* on stdout: where and when the first tolerance breach happened (metric, time, value vs budget), or
  that none did.

Each file is written under ``<name>.partial`` and gets its name when whole; an earlier run's files
of the scene (both simulators' CSVs, the recording) are removed first. Interrupted (Ctrl-C), the
recording so far is finished as ``<scene>.mcap.partial`` (the CSV of a simulator whose replay was
complete is whole).

Exit status: 0 no breach, 1 a breach or an error of the check, 2 bad input, 3 a result file or
standard output cannot be written (one line naming it; the file keeps its ``.partial`` name), 130
interrupted, 141 standard output closed early.
``--corrupt-u-scale F`` multiplies the replayed u by F (a negative control: the run must breach).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import sys

from pathlib import Path
from typing import Any

import numpy as np

from . import _files, cliutil
from ._files import WriteFailed
from .checks import SIMULATORS, CheckOptions, Recording, _run

SCALAR_SCHEMA = {"type": "object", "properties": {"t": {"type": "number"}, "value": {"type": "number"}}}
BREACH_SCHEMA = {
    "type": "object",
    "properties": {"metric": {"type": "string"}, "first_time": {"type": ["number", "null"]},
                   "value": {"type": ["number", "null"]}, "budget": {"type": ["number", "null"]},
                   "where": {"type": "string"}},
}

#: most body-frame samples per simulator in the MCAP (the states are recorded at every step)
MAX_FRAMES = 1000


def _ns(t: float) -> int:
    return max(0, int(round(t * 1e9)))


def _stamp(t: float) -> dict:
    n = _ns(t)
    return {"sec": n // 1_000_000_000, "nsec": n % 1_000_000_000}


def _num(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


class _Mcap:
    def __init__(self, f):
        from mcap.writer import Writer

        self.w = Writer(f)
        self.w.start(profile="", library="progmo debug")
        self.schemas: dict[str, int] = {}
        self.channels: dict[str, int] = {}

    def channel(self, topic: str, schema_name: str, schema: dict) -> int:
        if topic not in self.channels:
            if schema_name not in self.schemas:
                self.schemas[schema_name] = self.w.register_schema(
                    name=schema_name, encoding="jsonschema", data=json.dumps(schema).encode())
            self.channels[topic] = self.w.register_channel(
                topic=topic, message_encoding="json", schema_id=self.schemas[schema_name])
        return self.channels[topic]

    def write(self, ch: int, t: float, msg: dict) -> None:
        self.w.add_message(channel_id=ch, log_time=_ns(t), publish_time=_ns(t),
                           data=json.dumps(msg).encode())

    def finish(self):
        self.w.finish()


def _named(names, values) -> dict:
    return dict(zip(names, map(_num, values)))


def _frames(mc: _Mcap, topic: str, prefix: str, t: float, bodies, schemas: dict) -> None:
    ch = mc.channel(topic, "foxglove.FrameTransform", schemas["foxglove.FrameTransform"])
    for name, pos, wxyz in bodies:
        mc.write(ch, t, {
            "timestamp": _stamp(t), "parent_frame_id": "world", "child_frame_id": f"{prefix}/{name}",
            "translation": {"x": float(pos[0]), "y": float(pos[1]), "z": float(pos[2])},
            "rotation": {"x": float(wxyz[1]), "y": float(wxyz[2]), "z": float(wxyz[3]), "w": float(wxyz[0])}})


def _geometry(mc: _Mcap, prefix: str, t: float, rec: Recording, schemas: dict, alpha: float) -> None:
    """The mechanism on /<prefix>/scene; the solver's (prefix progmo) also carries the declared
    view targets, drawn once in the world frame."""
    update = rec.scene.scene_update(np.asarray(rec.ref.q[0]), prefix, alpha, targets=prefix == "progmo")
    if update is not None:
        mc.write(mc.channel(f"/{prefix}/scene", "foxglove.SceneUpdate", schemas["foxglove.SceneUpdate"]), t, update)


def _trace(mc: _Mcap, prefix: str, t: float, rec: Recording, q, schemas: dict) -> None:
    """The realized traces of the programme's sites through the configurations q (rows), on
    /<prefix>/scene at time t (the end of the motion), as `progmo solve` writes them."""
    update = rec.scene.scene_trace(np.asarray(q, dtype=float), prefix)
    if update is not None:
        mc.write(mc.channel(f"/{prefix}/scene", "foxglove.SceneUpdate", schemas["foxglove.SceneUpdate"]), t, update)


def _write_solver(mc: _Mcap, rec: Recording) -> None:
    """The solver's motion on the topics of `progmo solve` (/progmo/state, control, residual, tf,
    scene), at the replay's sample times; its geometry is drawn as a translucent ghost."""
    ref, schemas = rec.ref, rec.scene.recording_schemas()
    cs = mc.channel("/progmo/state", "progmo.State", schemas["progmo.State"])
    cc = mc.channel("/progmo/control", "progmo.Control", schemas["progmo.Control"])
    cr = mc.channel("/progmo/residual", "progmo.Residual", schemas["progmo.Residual"])
    n = len(range(0, len(ref.t), 2))
    every = max(1, -(-n // MAX_FRAMES))
    for i, k in enumerate(range(0, len(ref.t), 2)):  # the replay's sample times
        t = float(ref.t[k])
        mc.write(cs, t, {"t": t, "q": _named(rec.q_names, ref.q[k]), "v": _named(rec.v_names, ref.v[k]),
                         "a": _named(rec.v_names, ref.a[k])})
        lam = ref.lam[k] if ref.lam is not None else [math.nan] * len(rec.row_names)
        mc.write(cc, t, {"t": t, "u": _named(rec.v_names, ref.u[k]), "lambda": _named(rec.row_names, lam)})
        rate = ref.residual_rate[k] if ref.residual_rate is not None else [math.nan] * len(rec.row_names)
        mc.write(cr, t, {"t": t, "residual": _named(rec.row_names, ref.residual[k]),
                         "residual_rate": _named(rec.row_names, rate)})
        if i == 0:
            _geometry(mc, "progmo", t, rec, schemas, 0.35)
        if i % every == 0:
            _frames(mc, "/progmo/tf", "progmo", t, rec.scene.body_poses(np.asarray(ref.q[k])), schemas)
    if len(ref.t):
        _trace(mc, "progmo", float(ref.t[-1]), rec, np.asarray(ref.q)[::2], schemas)


def _write_sim(mc: _Mcap, sim: str, rec: Recording, result) -> None:
    """A simulator's replay on /<sim>/state, residual (the schemas of the solver's), deviation,
    tf (its own kinematics), scene (the mechanism on its frames) and breach."""
    rp, schemas = rec.replay, rec.scene.recording_schemas()
    cs = mc.channel(f"/{sim}/state", "progmo.State", schemas["progmo.State"])
    cr = mc.channel(f"/{sim}/residual", "progmo.Residual", schemas["progmo.Residual"])
    cd = mc.channel(f"/{sim}/deviation", "progmo.Scalar", SCALAR_SCHEMA)
    none = [math.nan] * len(rec.row_names)
    for k in range(len(rp.t)):
        t = float(rp.t[k])
        mc.write(cs, t, {"t": t, "q": _named(rec.q_names, rp.q[k]), "v": _named(rec.v_names, rp.v[k]),
                         "a": _named(rec.v_names, rp.a[k])})
        mc.write(cr, t, {"t": t, "residual": _named(rec.row_names, rec.residual[k]),
                         "residual_rate": _named(rec.row_names, none)})
        mc.write(cd, t, {"t": t, "value": _num(rec.deviation[k])})
    if len(rp.t):
        _geometry(mc, sim, float(rp.t[0]), rec, schemas, 1.0)
    for t, bodies in rp.frames:
        _frames(mc, f"/{sim}/tf", sim, t, bodies, schemas)
    if len(rp.t):
        _trace(mc, sim, float(rp.t[-1]), rec, rp.q, schemas)
    cb = mc.channel(f"/{sim}/breach", "progmo.Breach", BREACH_SCHEMA)
    for b in result.breaches:
        t = b.first_time if b.first_time is not None else float(rp.t[-1])
        mc.write(cb, t, {"metric": b.metric, "first_time": b.first_time, "value": _num(b.value),
                         "budget": _num(b.budget), "where": b.where})


def _write_csv(path: str, sim: str, rec: Recording) -> None:
    """Solver columns named as in `progmo solve`'s trajectory.csv (t, q:<q>, v:<v>, u:<v>), the
    replay's as <sim>.q:<q>, <sim>.v:<v>, <sim>.residual:<row>, then deviation."""
    ref, rp = rec.ref, rec.replay
    with _files.staged(path, "w", newline="") as f:  # whole, or `.partial` and WriteFailed
        w = csv.writer(f)
        w.writerow(["t"] + [f"q:{n}" for n in rec.q_names] + [f"v:{n}" for n in rec.v_names]
                   + [f"u:{n}" for n in rec.v_names] + [f"{sim}.q:{n}" for n in rec.q_names]
                   + [f"{sim}.v:{n}" for n in rec.v_names] + [f"{sim}.residual:{n}" for n in rec.row_names]
                   + ["deviation"])
        for k in range(len(rp.t)):
            j = 2 * k
            w.writerow([repr(float(rp.t[k]))] + [repr(float(x)) for x in (
                *ref.q[j], *ref.v[j], *ref.u[j], *rp.q[k], *rp.v[k], *rec.residual[k], rec.deviation[k])])


def _value_at(rec: Recording, result, metric: str, t: float | None):
    """The metric's value at its first breach time (replay metrics), else None."""
    if rec is None or rec.replay is None or t is None:
        return None
    k = int(np.argmin(np.abs(rec.replay.t - t)))
    if metric == "replay_residual":
        return float(np.abs(rec.residual[k]).max())
    if metric == "replay_deviation":
        return float(rec.deviation[k])
    return None


def _parser() -> argparse.ArgumentParser:
    """The command line of `progmo debug`."""
    p = cliutil.parser("progmo debug", description=__doc__ or "")
    p.add_argument("scene", help="scene file (.toml) or name of a bundled scene")
    p.add_argument("--simulator", choices=[*SIMULATORS, "all"], default="all",
                   help="the simulator to record (default: all, every installed one)")
    p.add_argument("--out", default="debug-out", help="output directory (default: debug-out)")
    p.add_argument("--step", type=float, default=None, help="replay step (default: the scene's)")
    p.add_argument("--horizon", type=float, default=None, help="replay horizon in s")
    p.add_argument("--corrupt-u-scale", type=float, default=None,
                   help="negative control: multiply the replayed u by this factor")
    return p


def main(argv: list[str] | None = None) -> int:
    try:
        a = _parser().parse_args(argv)
    except SystemExit as e:
        return 2 if e.code else 0
    refused = _refusal(a)
    if refused is not None:
        return refused
    from .cli import default_simulators

    sims = default_simulators(None)[0] if a.simulator == "all" else [a.simulator]
    try:
        os.makedirs(a.out, exist_ok=True)
    except OSError as e:
        raise WriteFailed(a.out, e) from None
    corrupt = None
    if a.corrupt_u_scale is not None:
        factor = a.corrupt_u_scale
        corrupt = lambda t, u: u * factor  # noqa: E731
    opts = CheckOptions(step=a.step, horizon=a.horizon)
    stem = os.path.splitext(os.path.basename(a.scene))[0]
    mcap_path = os.path.join(a.out, stem + ".mcap")
    # Nothing of an earlier run (the other simulator's CSV, an old recording) may pass for this one's.
    _files.remove([Path(a.out) / f"{stem}{x}" for x in
                   (".mcap", ".mcap" + _files.PARTIAL,
                    *(f"_{s}.csv{p}" for s in SIMULATORS for p in ("", _files.PARTIAL)))])
    results = _record(a, sims, opts, corrupt, stem, mcap_path)
    print(f"wrote {mcap_path}" + "".join(f", {os.path.join(a.out, f'{stem}_{s}.csv')}"
                                         for s, _, rec in results if rec.replay is not None))
    return _verdict(results)


def _refusal(a: argparse.Namespace) -> int | None:
    """The exit status of bad input (2) or a missing mcap package (1), the message printed; None
    when the run may go on (`a.scene` then names the scene file)."""
    from . import data
    try:
        a.scene = str(data.scene_file(a.scene))
    except ValueError as e:
        print(f"progmo debug: error: {e}", file=sys.stderr)
        return 2
    problem = CheckOptions(step=a.step, horizon=a.horizon).problem()  # as progmo check, progmo.check
    if problem is not None:
        print(f"progmo debug: error: --{problem}", file=sys.stderr)
        return 2
    # A scene that does not load or that the solver refuses: the located message of `progmo solve`.
    from . import Scene, SceneError
    try:
        Scene(a.scene).check_initial()
    except SceneError as e:
        print(str(e), file=sys.stderr)
        return 2
    try:
        import mcap.writer  # noqa: F401
    except ImportError as e:
        print(f"progmo debug: error: the mcap package is not importable: {e}", file=sys.stderr)
        return 1
    return None


def _record(a: argparse.Namespace, sims: list[str], opts: CheckOptions, corrupt: Any, stem: str,
            mcap_path: str) -> list[tuple[str, Any, Recording]]:
    """Run the check of each simulator with full recording into the MCAP (under its `.partial`
    name until whole) and the CSVs; (simulator, result, recording) of each."""
    results: list[tuple[str, Any, Recording]] = []
    part = _files.partial(mcap_path)
    _files.check_destination(mcap_path)
    try:
        f = open(part, "wb")
    except OSError as e:
        raise WriteFailed(part, e) from None
    mc = None
    written: list[str] = []
    try:
        mc = _Mcap(f)
        _record_sims(mc, a, sims, opts, corrupt, stem, results, written)
        mc.finish()
        f.close()
    except KeyboardInterrupt:
        # what was recorded so far, a valid recording, under the `.partial` name
        try:
            if mc is not None:
                mc.finish()
            f.close()
        except Exception:  # noqa: BLE001 - the interrupt is what is reported
            pass
        print(f"progmo debug: interrupted; the recording up to there is {part}"
              + "".join(f", {w}" for w in written), file=sys.stderr)
        raise
    except OSError as e:
        try:
            f.close()
        except OSError:
            pass
        raise WriteFailed(part, e) from None
    _files.check_destination(mcap_path)
    try:
        os.replace(part, mcap_path)
    except OSError as e:
        raise WriteFailed(part, e) from None
    return results


def _record_sims(mc: _Mcap, a: argparse.Namespace, sims: list[str], opts: CheckOptions, corrupt: Any, stem: str,
                 results: list[tuple[str, Any, Recording]], written: list[str]) -> None:
    """Each simulator's check, recorded (the solver's motion once, with the first replay); appends to
    `results` and to `written` (the CSVs)."""
    solver_written = False
    for sim in sims:
        rec = Recording()
        # frames: at most MAX_FRAMES samples (the step is only known inside the check)
        r, _ = _run(a.scene, sim, opts, corrupt_u=corrupt, frame_every=-1, record=rec)
        results.append((sim, r, rec))
        if rec.replay is not None:
            with _files.deferred_interrupt():  # a simulator's records whole, or not at all
                if not solver_written:
                    _write_solver(mc, rec)
                    solver_written = True
                _write_sim(mc, sim, rec, r)
                csv_path = os.path.join(a.out, f"{stem}_{sim}.csv")
                _write_csv(csv_path, sim, rec)
                written.append(csv_path)


def _verdict(results: list[tuple[str, Any, Recording]]) -> int:
    """Print each simulator's line and the first tolerance breach (or that none happened); the exit
    status: 1 on a breach or an error of the check, else 0."""
    breaches = []
    bad = False
    for sim, r, rec in results:
        m = {**r.metrics, **r.info}
        print(f"{sim:9s} {r.status:7s} " + "  ".join(
            f"{k} {m[k]:.3g}" for k in ("parity_mass", "parity_bias", "replay_residual", "replay_deviation",
                                        "replay_growth_rate", "instant_u", "parity_closure", "reaction_closure",
                                        "replay_closure_residual", "replay_step", "replay_segments",
                                        "lyapunov_exponent") if k in m)
              + (f"  ({r.reason})" if r.reason else ""))
        for w in r.warnings:
            print(f"  solver warning: {w}")
        if r.status == "error" or (r.status == "not_checked" and not r.expected):
            bad = True
        for b in r.breaches:
            breaches.append((sim, b, _value_at(rec, r, b.metric, b.first_time)))
    if breaches:
        _print_breaches(breaches)
        return 1
    print("no tolerance breach")
    return 1 if bad else 0


def _print_breaches(breaches: list[tuple[str, Any, float | None]]) -> None:
    """The first tolerance breach in time (where and when, the value there against the budget), then the others."""
    timed = [x for x in breaches if x[1].first_time is not None]
    sim, b, at = min(timed, key=lambda x: float(x[1].first_time or 0.0)) if timed else breaches[0]
    when = f"t = {b.first_time:.6g} s" if b.first_time is not None else "(no time)"
    there = f"value there {at:.3g}, " if at is not None else ""
    print(f"first tolerance breach: {sim} {b.metric} at {when}: {there}worst {b.value:.3g} "
          f"vs budget {b.budget:.3g}" + (f" ({b.where})" if b.where else ""))
    for sim2, b2, _ in breaches:
        if b2 is not b:
            ft = f"t = {b2.first_time:.6g} s" if b2.first_time is not None else "(no time)"
            print(f"  also: {sim2} {b2.metric} from {ft}: worst {b2.value:.3g} vs budget {b2.budget:.3g}")


if __name__ == "__main__":
    from ._stdio import run

    sys.exit(run(main, "progmo debug"))
