"""``progmo sweep``: tolerance reports over distributions of runs.

A sweep file (TOML; format below, bundled ones in ``references/sweeps/<scene>.toml``) says which
parameters, initial coordinates or velocities and solver settings vary, with which distribution,
and the seed. Each sample is a scene file derived from the scene (written to ``OUT/samples/``, a
reproducer runnable with ``progmo check``) checked in the chosen simulators on the chosen executor
(:mod:`progmo.executors`). Results are appended to ``OUT/results.jsonl`` as they arrive, one line
per (sample, simulator): an interrupted sweep rerun with the same arguments resumes, running only
what is missing, and never counts a sample twice. The tolerance report (``OUT/sweep.html``,
``sweep.md``, ``sweep.json``) aggregates in sample order, so it does not depend on the executor,
the number of workers or the order results arrived in.

Sweep file::

    scene = "double_pendulum"      # optional: the scene it is written for (a bundled name, or a
                                   # path from this file's folder that stays inside it)
    samples = 16                   # random draws (per point of the grid variables)
    seed = 20261123                # sample i draws from numpy's SeedSequence([seed, i])
    simulators = ["mujoco", "pinocchio"]     # default: both
    initial_state = "refuse"       # or "assemble": a sample whose initial state leaves the
                                   # programme is refused and counted, or projected onto it
    horizon = 1.0                  # optional: the span of each sample (s): [time] t1 = t0 + horizon
    step = 1e-3                    # optional: replay step

    [vary]                         # "where.name" = { distribution = [arguments] }
    "parameters.amp" = { uniform = [0.3, 0.7] }
    "initial.q.q1" = { normal = [0.3, 0.1] }        # mean, standard deviation
    "solver.rtol" = { grid = [1e-8, 1e-10] }        # every value, crossed with the draws
    "parameters.k" = { loguniform = [1e2, 1e4] }

``where`` is ``parameters``, ``initial.q``, ``initial.v`` or ``solver``. A sweep runs at most 100000
samples (``samples`` x the product of the grid variables' lengths; ``MAX_SAMPLES``): a larger one is
refused at its ``samples`` (or first grid variable) before any sample is drawn. Every name is checked before
any sample is made: a key of the file, a distribution, a numeric ``[solver]`` setting
(``_core.SOLVER_NUMBERS``: those of ``progmo::solve::Overrides``), and against the scene a parameter, a coordinate or a
velocity with one value; a misspelt one is refused at its line and column with the nearest valid
name ("did you mean `amp`?"). A solver number the scene's method ignores (``step`` without rk4,
``max_step`` with it, ``projection_tol`` without projection, the Baumgarte gains without
Baumgarte) is refused too: every sample would be the same run. Numbers are finite floats (an integer beyond
1e308 is refused, as is a uniform range wider than the floats'); a file that is not UTF-8 is refused
at the line and column of its first invalid byte, without quoting it.
"""

from __future__ import annotations

import argparse
import base64
import dataclasses
import glob
import hashlib
import io
import itertools
import json
import math
import os
import sys
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from . import _core, _files, cliutil, data, executors
from .parallel import Task, default_jobs, last_line
from .results import CheckResult

DISTRIBUTIONS = {"uniform": 2, "normal": 2, "loguniform": 2, "grid": None}
WHERE = ("parameters", "initial.q", "initial.v", "solver")
KEYS = ("scene", "samples", "seed", "simulators", "initial_state", "horizon", "step", "vary")
EXIT_OK, EXIT_FAIL, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130
#: most samples (draws x grid points) a sweep runs; a larger one is refused before sampling
MAX_SAMPLES = 100_000
#: largest sweep file read (bytes)
MAX_SPEC_BYTES = 1 << 20
#: suggested budget = SAFETY x the worst sampled value, rounded up to 1, 2 or 5 x 10^k
SAFETY = 10.0


class SweepError(ValueError):
    """A bad sweep file or an inconsistency with its scene: ``file:line: key: message``."""


@dataclass
class Variable:
    key: str  # "parameters.amp"
    where: str  # "parameters"
    name: str  # "amp"
    dist: str
    args: list[float]


@dataclass
class Spec:
    path: str
    scene: str | None
    samples: int
    seed: int
    simulators: list[str]
    initial_state: str
    horizon: float | None
    step: float | None
    variables: list[Variable]

    def grid(self) -> list[dict[str, float]]:
        gv = [v for v in self.variables if v.dist == "grid"]
        return [dict(zip([v.key for v in gv], combo)) for combo in itertools.product(*[v.args for v in gv])]

    def grid_points(self) -> int:
        """The number of points of the grid variables (1 without any), not materialized."""
        return math.prod(len(v.args) for v in self.variables if v.dist == "grid")

    def total(self) -> int:
        return self.grid_points() * self.samples

    def grid_point(self, j: int) -> dict[str, float]:
        """Point j of the grid (``grid()[j]``, the last grid variable varying fastest)."""
        out: dict[str, float] = {}
        for v in reversed([v for v in self.variables if v.dist == "grid"]):
            j, k = divmod(j, len(v.args))
            out[v.key] = v.args[k]
        return out

    def values(self, i: int) -> dict[str, float]:
        """The values of sample i: a function of (seed, i) only."""
        out = self.grid_point(i // self.samples)
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, i]))
        for v in self.variables:
            if v.dist == "uniform":
                out[v.key] = float(rng.uniform(v.args[0], v.args[1]))
            elif v.dist == "normal":
                out[v.key] = float(rng.normal(v.args[0], v.args[1]))
            elif v.dist == "loguniform":
                out[v.key] = float(math.exp(rng.uniform(math.log(v.args[0]), math.log(v.args[1]))))
        return {v.key: out[v.key] for v in self.variables}


def _line_of(text: str, needle: str) -> int:
    return _locate(text, needle)[0]


def _locate(text: str, needle: str) -> tuple[int, int]:
    """1-based (line, column) of the first occurrence of ``needle`` (a key, quoted or bare) in a
    sweep file's text, (0, 0) if absent. A quoted key's column is that of its opening quote."""
    for k, line in enumerate(text.splitlines(), 1):
        for q in ('"', "'", ""):
            j = line.find(q + needle + q)
            if j >= 0 and not line[:j].lstrip().startswith("#"):
                return k, j + 1
    return 0, 0


def _number(x: Any) -> float | None:
    """A TOML number as a finite float; None for anything else (a bool, a string, nan, inf, an
    integer beyond the floats' range)."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return None
    try:
        f = float(x)
    except OverflowError:
        return None
    return f if math.isfinite(f) else None


def _did_you_mean(name: str, candidates: "list[str] | tuple[str, ...]") -> str:
    """`` (did you mean `x`?)`` by the core's rule (``progmo::check::nearest``), or ""."""
    from ._core import nearest

    near = nearest(name, list(candidates))
    return f" (did you mean `{near}`?)" if near else ""


def _located(path: str | os.PathLike[str], text: str, key: str, msg: str, needle: str) -> SweepError:
    line, col = _locate(text, needle)
    return SweepError(f"{path}:{line}:{col}: {key}: {msg}" if line else f"{path}: {key}: {msg}")


def _read_spec_text(p: Path) -> str:
    """The sweep file's text: a regular file of at most MAX_SPEC_BYTES, in UTF-8 (else a SweepError
    naming the file, an invalid byte located)."""
    try:
        # a regular file of at most MAX_SPEC_BYTES: never a FIFO (blocks) or /dev/zero (endless)
        st = p.stat()
        kind = _files.kind(st.st_mode)
        if kind is not None:
            raise SweepError(f"{p}: cannot read the sweep file: it is {kind}, not a regular file")
        if st.st_size > MAX_SPEC_BYTES:
            raise SweepError(f"{p}: cannot read the sweep file: {st.st_size} bytes, more than the "
                             f"{MAX_SPEC_BYTES} a sweep file may hold")
        raw = p.read_bytes()
    except OSError as e:
        raise SweepError(f"{p}: cannot read the sweep file: {e.strerror or e}") from None
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as e:
        # located, never quoted (the core's rule for files that are not text, src/input.rs)
        before = raw[:e.start]
        line = before.count(b"\n") + 1
        col = len(before[before.rfind(b"\n") + 1:].decode("utf-8")) + 1
        raise SweepError(f"{p}:{line}:{col}: the sweep file is not valid UTF-8 (an invalid byte at line {line}, "
                         f"column {col}): save it as UTF-8") from None


def load_spec(path: str | os.PathLike[str]) -> Spec:
    """Read and validate a sweep file; errors name the file, the line and the key."""
    p = Path(path)
    text = _read_spec_text(p)
    try:
        d = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SweepError(f"{p}: {e}") from None

    def err(key: str, msg: str, needle: str | None = None) -> SweepError:
        return _located(p, text, key, msg, needle or key.split(".")[-1])

    samples, seed, sims, init, opt = _spec_options(d, err)
    vary = d.get("vary", {})
    if not isinstance(vary, dict) or not vary:
        raise err("vary", "a sweep needs a [vary] table with at least one variable", "vary")
    variables = [_spec_variable(key, dist, err) for key, dist in vary.items()]
    scene = d.get("scene")
    if scene is not None and not isinstance(scene, str):
        raise err("scene", f"must be a scene name or path, got {scene!r}")
    grid = [v for v in variables if v.dist == "grid"]
    points = math.prod(len(v.args) for v in grid)
    if samples * points > MAX_SAMPLES:
        # refused before any sample is drawn: a file per sample, a check per sample and simulator
        where = "samples" if "samples" in d or not grid else f"vary.{grid[0].key}"
        raise err(where, f"{samples} draw(s) x {points} grid point(s) = {samples * points:.4g} samples, more "
                  f"than the {MAX_SAMPLES} a sweep runs (progmo.sweep.MAX_SAMPLES)",
                  "samples" if where == "samples" else grid[0].key)
    return Spec(str(p), scene, samples, seed, list(dict.fromkeys(sims)), init, opt["horizon"], opt["step"],
                variables)


def _spec_options(d: dict[str, Any], err: Callable[..., SweepError]
                  ) -> tuple[int, int, list[str], str, dict[str, float | None]]:
    """The sweep file's keys besides `scene` and `[vary]`, validated: samples, seed, simulators,
    initial_state and {horizon, step}; an unknown key is refused (with the nearest known one)."""
    from .checks import SIMULATORS

    for k in d:
        if k not in KEYS:
            raise err(k, f"unknown key{_did_you_mean(k, KEYS)} (expected one of {', '.join(KEYS)})", k)
    samples, seed = d.get("samples", 10), d.get("seed", 0)
    if not isinstance(samples, int) or isinstance(samples, bool) or samples < 1:
        raise err("samples", f"must be an integer >= 1, got {samples!r}")
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise err("seed", f"must be an integer >= 0, got {seed!r}")
    sims = d.get("simulators", list(SIMULATORS))
    if not isinstance(sims, list) or not sims or any(s not in (*SIMULATORS, "solver_only") for s in sims):
        raise err("simulators", f"must be a list of {', '.join(SIMULATORS)} or solver_only, got {sims!r}")
    init = d.get("initial_state", "refuse")
    if init not in ("refuse", "assemble"):
        raise err("initial_state", f"must be \"refuse\" or \"assemble\", got {init!r}")
    opt: dict[str, float | None] = {}
    for k in ("horizon", "step"):
        x = d.get(k)
        f = _number(x)
        if x is not None and not (f is not None and f > 0):
            raise err(k, f"must be a finite number > 0, got {x!r}")
        opt[k] = f
    return samples, seed, sims, init, opt


def _spec_variable(key: str, dist: Any, err: Callable[..., SweepError]) -> Variable:
    """One `[vary]` entry, WHERE.NAME = { distribution = [numbers] }, validated."""
    where, _, name = key.rpartition(".")
    if where not in WHERE or not name:
        near = _core.nearest(where, list(WHERE)) if name else None
        raise err(f"vary.{key}", f"must be WHERE.NAME with WHERE one of {', '.join(WHERE)}"
                  + (f" (did you mean `{near}.{name}`?)" if near else ""), key)
    if where == "solver" and name not in _core.SOLVER_NUMBERS:
        raise err(f"vary.{key}", f"unknown solver setting `{name}`{_did_you_mean(name, _core.SOLVER_NUMBERS)}: "
                  f"a sweep varies the numeric ones ({', '.join(_core.SOLVER_NUMBERS)})", key)
    if not (isinstance(dist, dict) and len(dist) == 1):
        raise err(f"vary.{key}", "must be one distribution: { uniform = [a, b] }, { normal = [mean, sd] }, "
                  "{ loguniform = [a, b] } or { grid = [x1, x2, ...] }", key)
    (kind, args), = dist.items()
    if kind not in DISTRIBUTIONS:
        raise err(f"vary.{key}", f"unknown distribution {kind!r}{_did_you_mean(kind, list(DISTRIBUTIONS))} "
                  f"(one of {', '.join(DISTRIBUTIONS)})", key)
    if not isinstance(args, list) or not args or any(_number(a) is None for a in args):
        raise err(f"vary.{key}", f"{kind} needs a list of finite numbers, got {args!r}", key)
    args = [float(a) for a in args]
    n = DISTRIBUTIONS[kind]
    if n is not None and len(args) != n:
        raise err(f"vary.{key}", f"{kind} takes {n} numbers, got {len(args)}", key)
    if kind in ("uniform", "loguniform") and not args[0] < args[1]:
        raise err(f"vary.{key}", f"{kind} needs a < b, got {args}", key)
    if kind == "uniform" and not math.isfinite(args[1] - args[0]):
        raise err(f"vary.{key}", f"uniform needs b - a finite, got {args}", key)
    if kind == "loguniform" and args[0] <= 0:
        raise err(f"vary.{key}", "loguniform needs a > 0", key)
    if kind == "normal" and not args[1] > 0:
        raise err(f"vary.{key}", "normal needs a standard deviation > 0", key)
    return Variable(key, where, name, kind, args)


def check_names(spec: Spec, scene: Any) -> None:
    """Every varied name exists in the scene (a loaded ``Scene``): a parameter, a coordinate or a
    velocity with one value (hinge, slide, lagrangian), and a solver number the scene's method reads;
    else a located :class:`SweepError` (with the nearest valid name). A misspelt name would otherwise
    refuse every sample, or vary nothing."""
    text = Path(spec.path).read_text()
    # a coordinate with one value is its own velocity's name (hinge, slide, lagrangian); a ball or
    # free joint's components are not (``j.qw`` / ``j.wx``), whatever dots a joint's name holds
    single = [n for n in scene.q_names if n in set(scene.v_names)]
    have = {"parameters": [n for n, _ in scene.parameters],
            "initial.q": single,
            "initial.v": single}
    what = {"parameters": "parameter", "initial.q": "coordinate", "initial.v": "velocity"}
    st = scene.settings
    integ, drift = st["integrator"], st["drift"]["kind"]
    #: a solver number the scene's method would ignore: varying it would vary nothing
    ignored = {"step": integ != "rk4" and f"its integrator is {integ} (step is rk4's fixed step)",
               "max_step": integ == "rk4" and "its integrator is rk4, whose step is fixed",
               "projection_tol": drift != "projection" and f"its drift control is {drift}, not projection",
               "baumgarte_alpha": drift != "baumgarte" and f"its drift control is {drift}, not baumgarte",
               "baumgarte_beta": drift != "baumgarte" and f"its drift control is {drift}, not baumgarte"}
    for v in spec.variables:
        why = ignored.get(v.name) if v.where == "solver" else None
        if why:
            raise _located(spec.path, text, f"vary.{v.key}",
                           f"the scene {scene.path} ignores solver.{v.name}: {why}; "
                           "varying it would vary nothing", v.key)
        names = have.get(v.where)
        if names is not None and v.name not in names:
            raise _located(spec.path, text, f"vary.{v.key}",
                           f"the scene {scene.path} has no {what[v.where]} {v.name!r}"
                           f"{_did_you_mean(v.name, names)} (have: {', '.join(names) or 'none'})", v.key)


def spec_scene(spec: Spec) -> Path:
    """The scene a sweep file's ``scene`` names: a bare name (no folder, no other suffix than
    ``.toml``) not beside the sweep file is a bundled scene; a path is relative to the sweep
    file's folder and must resolve inside it, the robot path or $PROGMO_ALLOW_ROOTS (the path rule
    of scene files, src/scene/FORMAT.md "Files a scene reads")."""
    from ._core import SceneError, resolve_file

    assert spec.scene is not None
    folder = Path(spec.path).parent
    p = Path(spec.scene)
    try:
        if p.parent == Path(".") and p.suffix in ("", ".toml") and not (folder / p).exists():
            return data.scene_file(spec.scene)
        return Path(resolve_file(spec.scene, folder))
    except SceneError as e:
        line = _line_of(Path(spec.path).read_text(), "scene")
        raise SweepError(f"{spec.path}:{line}: scene: {e}") from None
    except OSError as e:  # a name the file system refuses (too long, ...): its reason, not the name
        line = _line_of(Path(spec.path).read_text(), "scene")
        raise SweepError(f"{spec.path}:{line}: scene: not a usable path: {e.strerror or type(e).__name__}") from None


def bundled_spec(scene_name: str) -> Path | None:
    p = data.references() / "sweeps" / f"{scene_name}.toml"
    return p if p.is_file() else None


# --- samples -------------------------------------------------------------------------------------
def sample_text(scene_text: str, scene_path: str, spec: Spec, i: int, values: dict[str, float]) -> str:
    """The scene of sample i: the scene file with the varied entries replaced (comments kept)."""
    import tomlkit

    doc = tomlkit.parse(scene_text)
    name = str(doc["name"])
    doc["name"] = f"{name}-{i:05d}"
    for v in spec.variables:
        x = values[v.key]
        if v.where == "parameters":
            if "parameters" not in doc or v.name not in doc["parameters"]:  # type: ignore[operator]
                raise SweepError(f"{spec.path}:{_line_of(Path(spec.path).read_text(), v.key)}: vary.{v.key}: "
                                 f"the scene {scene_path} has no parameter {v.name!r}")
            doc["parameters"][v.name] = x  # type: ignore[index]
        elif v.where in ("initial.q", "initial.v"):
            part = v.where.split(".")[1]
            init = doc["initial"]
            if part not in init:  # type: ignore[operator]
                init[part] = tomlkit.inline_table()  # type: ignore[index]
            init[part][v.name] = x  # type: ignore[index]
        else:
            if "solver" not in doc:
                doc["solver"] = tomlkit.table()
            doc["solver"][v.name] = x  # type: ignore[index]
    if spec.initial_state == "assemble":
        doc["initial"]["assemble"] = True  # type: ignore[index]
    # the check's settings travel in the reproducer, so `progmo check FILE` reruns the same check;
    # a horizon is the sample's own span (a check always replays a scene's whole span)
    if spec.horizon is not None:
        if "time" not in doc:
            doc["time"] = tomlkit.table()
        t0 = float(doc["time"].get("t0", 0.0))  # type: ignore[union-attr]
        doc["time"]["t1"] = t0 + spec.horizon  # type: ignore[index]
    for key, setting in (("replay_step", spec.step),):
        if setting is not None:
            if "checks" not in doc:
                doc["checks"] = tomlkit.table()
            t = tomlkit.inline_table()
            t.update({"value": setting, "reason": f"set by the sweep {Path(spec.path).name}"})
            doc["checks"][key] = t  # type: ignore[index]
    head = (f"# Sample {i} of the sweep {spec.path} (seed {spec.seed}) of {scene_path}:\n"
            + "".join(f"#   {k} = {values[k]!r}\n" for k in values)
            + "# Rerun: progmo check THIS_FILE\n")
    return head + tomlkit.dumps(doc)


@dataclass
class Sample:
    index: int
    scene: str  # the base scene's name
    path: str  # the sample's scene file
    values: dict[str, float]
    refused: str = ""  # why the solver refused the initial state ("" if accepted)


def make_samples(scene_file: Path, spec: Spec, out: Path) -> list[Sample]:
    from . import Scene, SceneError

    base = Scene(str(scene_file))
    check_names(spec, base)
    text = scene_file.read_text()
    d = out / "samples"
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise _files.WriteFailed(d, e) from None
    # sample files of an earlier, larger sweep of this scene must not pass for this one's
    keep = {f"{base.name}-{i:05d}.toml" for i in range(spec.total())}
    _files.remove([f for f in d.glob(f"{glob.escape(base.name)}-*.toml*") if f.name not in keep])
    samples = []
    for i in range(spec.total()):
        values = spec.values(i)
        st = sample_text(text, str(scene_file), spec, i, values)
        p = d / f"{base.name}-{i:05d}.toml"
        if not p.is_file() or p.read_text() != st:
            _files.write_text(p, st)  # whole, or `.partial` and exit 3
        s = Sample(i, base.name, str(p), values)
        try:
            sc = Scene(str(p))
            sc.check_initial()
        except SceneError as e:
            s.refused = last_line(e)
        samples.append(s)
    return samples


# --- results file --------------------------------------------------------------------------------
def read_results(path: Path) -> dict[tuple[str, int, str], dict[str, Any]]:
    """(scene, sample, simulator) -> record; the first complete line wins, a torn last line is
    ignored (an interrupted write)."""
    out: dict[tuple[str, int, str], dict[str, Any]] = {}
    if not path.is_file():
        return out
    for line in path.read_text().splitlines():
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            continue
        out.setdefault((rec["scene"], rec["sample"], rec["simulator"]), rec)
    return out


def drop_torn_tail(path: Path) -> None:
    """Cut a last line that an interrupted write left without its newline, so that appending
    starts on a line of its own (the torn record is rerun)."""
    if not path.is_file():
        return
    data = path.read_bytes()
    if data and not data.endswith(b"\n"):
        with open(path, "r+b") as f:
            f.truncate(data.rfind(b"\n") + 1)


def spec_digest(spec: Spec, scene_texts: dict[str, str]) -> str:
    h = hashlib.sha256()
    h.update(Path(spec.path).read_bytes())
    for k in sorted(scene_texts):
        h.update(k.encode() + scene_texts[k].encode())
    return h.hexdigest()[:16]


# --- aggregation ---------------------------------------------------------------------------------
def _nice_up(x: float) -> float:
    """The smallest of 1, 2, 5 x 10^k at or above x."""
    if not x > 0 or not math.isfinite(x):
        return x
    k = math.floor(math.log10(x))
    for m in (1, 2, 5, 10):
        if m * 10.0 ** k >= x * (1 - 1e-12):
            return m * 10.0 ** k
    return 10.0 ** (k + 1)  # pragma: no cover


def aggregate(samples: list[Sample], spec: Spec, records: dict[tuple[str, int, str], dict[str, Any]]) -> dict[str, Any]:
    """The tolerance report as data, in sample order (independent of how results arrived)."""
    sims = spec.simulators
    counts: dict[str, dict[str, int]] = {}
    metrics: dict[tuple[str, str, str], list[tuple[int, float, float | None, str]]] = {}
    reasons: dict[str, str] = {}
    warnings: dict[str, int] = {}
    for s in samples:
        for m in sims:
            c = counts.setdefault(f"{s.scene}/{m}", {})
            if s.refused:
                c["refused"] = c.get("refused", 0) + 1
                continue
            rec = records.get((s.scene, s.index, m))
            if rec is None:
                c["not run"] = c.get("not run", 0) + 1
                continue
            r = rec["result"]
            c[r["status"]] = c.get(r["status"], 0) + 1
            for w in r.get("warnings") or []:
                warnings[f"{s.scene}/{m}"] = warnings.get(f"{s.scene}/{m}", 0) + 1
                break
            budgets = {b["metric"]: (b["value"], b["reason"]) for b in r.get("budgets", [])}
            for k, v in (r.get("metrics") or {}).items():
                if k not in budgets:
                    continue
                val = math.nan if v is None else float(v)
                metrics.setdefault((s.scene, m, k), []).append((s.index, val, budgets[k][0], r["status"]))
                reasons[k] = budgets[k][1]
    rows = []
    for (scene, m, k), pts in sorted(metrics.items()):
        vals = np.array([p[1] for p in pts])
        finite = vals[np.isfinite(vals)]
        budget = pts[0][2]
        worst_i = int(np.nanargmax(np.where(np.isfinite(vals), vals, np.inf))) if len(vals) else 0
        worst = pts[worst_i]
        q = (np.quantile(finite, [0.5, 0.9, 0.99]).tolist() if finite.size else [math.nan] * 3)
        wv = float(vals[worst_i])
        suggested = _nice_up(SAFETY * wv) if math.isfinite(wv) and wv > 0 else None
        rows.append({
            "scene": scene, "simulator": m, "metric": k, "n": len(pts), "nonfinite": int(len(vals) - finite.size),
            "min": float(finite.min()) if finite.size else math.nan, "p50": q[0], "p90": q[1], "p99": q[2],
            "max": wv, "budget": budget, "budget_reason": reasons.get(k, ""),
            "margin": (budget / wv) if (budget and math.isfinite(wv) and wv > 0) else None,
            "over_budget": int(np.sum(~(vals <= budget))) if budget is not None else 0,
            "worst_sample": worst[0], "suggested_budget": suggested,
            "suggestion_reason": (f"{SAFETY:g} x the worst of {len(pts)} samples ({wv:.3g}), rounded up to 1, 2 or 5 "
                                  f"x 10^k: with n samples a new run exceeds the sampled maximum with probability "
                                  f"about 1/(n+1) = {1 / (len(pts) + 1):.2g}; the factor covers the tail beyond it"
                                  if suggested is not None else "no finite positive value sampled"),
            "points": [[p[0], p[1]] for p in pts],
        })
    failing = [{"scene": s.scene, "sample": s.index, "simulator": m, "path": s.path,
                "status": records[(s.scene, s.index, m)]["result"]["status"],
                "reason": records[(s.scene, s.index, m)]["result"].get("reason", "")}
               for s in samples for m in sims
               if not s.refused and (s.scene, s.index, m) in records
               and records[(s.scene, s.index, m)]["result"]["status"] != "pass"]
    return {
        "spec": {"path": spec.path, "samples": spec.samples, "seed": spec.seed, "simulators": sims,
                 "initial_state": spec.initial_state, "horizon": spec.horizon, "step": spec.step,
                 "variables": [dataclasses.asdict(v) for v in spec.variables]},
        "samples": [{"scene": s.scene, "index": s.index, "path": s.path, "values": s.values, "refused": s.refused}
                    for s in samples],
        "counts": counts, "warnings": warnings, "metrics": rows, "failing": failing,
    }


def ok(agg: dict[str, Any]) -> bool:
    """Every accepted sample passed in every simulator (refused samples are counted, not failed)."""
    return all(set(c) <= {"pass", "refused"} for c in agg["counts"].values()) and any(
        c.get("pass") for c in agg["counts"].values())


# --- report --------------------------------------------------------------------------------------
def _plot(row: dict[str, Any], agg: dict[str, Any]) -> str | None:
    from matplotlib.figure import Figure

    values = {(s["scene"], s["index"]): s["values"] for s in agg["samples"]}
    keys = [v["key"] for v in agg["spec"]["variables"]]
    pts = [(values[(row["scene"], i)], y) for i, y in row["points"]]
    if not pts or not keys:
        return None
    fig = Figure(figsize=(3.3 * len(keys), 2.5), dpi=90)
    axes = fig.subplots(1, len(keys), squeeze=False)[0]
    for ax, k in zip(axes, keys):
        xs = np.array([p[0][k] for p in pts])
        ys = np.array([p[1] for p in pts], dtype=float)
        pos = np.isfinite(ys) & (ys > 0)
        ax.scatter(xs[pos], ys[pos], s=12, color="#1f5fa8", label="samples")
        zero = np.isfinite(ys) & (ys <= 0)
        if zero.any():  # exact zeros: marked on the axis floor, not clamped into the data
            floor = ys[pos].min() / 10 if pos.any() else 1e-300
            ax.scatter(xs[zero], np.full(zero.sum(), floor), marker="v", color="#888", label="exactly 0")
        ax.set_yscale("log")
        if row["budget"]:
            ax.axhline(row["budget"], color="#b3261e", lw=1, ls="--", label="budget")
        ax.set_xlabel(k)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel(row["metric"])
    axes[0].legend(fontsize=7, loc="best")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def render_html(agg: dict[str, Any], meta: dict[str, Any]) -> str:
    from .htmlstyle import CSS
    from .htmlstyle import esc as _e
    from .report import fmt

    good = ok(agg)
    h: list[str] = []
    a = h.append
    a("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>")
    a("<meta name='viewport' content='width=device-width,initial-scale=1'>")
    a(f"<title>progmo sweep: {'pass' if good else 'FAIL'}</title><style>{CSS}</style></head><body><main>")
    a("<h1>progmo tolerance sweep</h1>")
    sp = agg["spec"]
    a(f"<p class='sub'>{len(agg['samples'])} sample(s) of <code>{_e(sp['path'])}</code> (seed {sp['seed']}), "
      f"checked in {_e(', '.join(sp['simulators']))} on the {_e(meta.get('executor', 'local'))} executor; "
      f"{_e(meta.get('date', ''))}.</p>")
    a(f"<div class='banner {'b-ok' if good else 'b-bad'}' id='overall'>{_e(summary_line(agg))}</div>")
    a("<h2>Outcomes</h2><table id='counts'><tr><th>scene / simulator</th><th>pass</th><th>fail</th><th>error</th>"
      "<th>not checked</th><th>refused</th><th>not run</th><th>with solver warnings</th></tr>")
    for k, c in agg["counts"].items():
        cells = "".join(f"<td class='num{' bad' if n and st in ('fail', 'error', 'not_checked', 'not run') else ''}'>{n}</td>"
                        for st in ("pass", "fail", "error", "not_checked", "refused", "not run") for n in [c.get(st, 0)])
        a(f"<tr><td>{_e(k)}</td>{cells}<td class='num'>{agg['warnings'].get(k, 0)}</td></tr>")
    a("</table>")
    a("<h2>Metrics</h2><table id='metrics'><tr><th>scene / simulator</th><th>metric</th><th>n</th><th>median</th>"
      "<th>90%</th><th>99%</th><th>worst</th><th>budget</th><th>margin</th><th>suggested budget</th>"
      "<th>worst sample (rerun)</th></tr>")
    for r in agg["metrics"]:
        cls = "bad" if r["over_budget"] else ""
        margin = "" if r["margin"] is None else f"{r['margin']:.3g}&times;"
        a(f"<tr class='metric {'m-over' if r['over_budget'] else 'm-ok'}'><td>{_e(r['scene'])} / {_e(r['simulator'])}</td>"
          f"<td>{_e(r['metric'])}</td><td class='num'>{r['n']}</td>"
          + "".join(f"<td class='num'>{fmt(r[k])}</td>" for k in ("p50", "p90", "p99"))
          + f"<td class='num {cls}'>{fmt(r['max'])}</td><td class='num' title='{_e(r['budget_reason'])}'>{fmt(r['budget'])}</td>"
          f"<td class='num {cls}'>{margin}</td>"
          f"<td class='num' title='{_e(r['suggestion_reason'])}'>{fmt(r['suggested_budget'])}</td>"
          f"<td class='small'><code>progmo check {_e(_sample_path(agg, r['scene'], r['worst_sample']))} -s {_e(r['simulator'])}</code></td></tr>")
    a("</table>")
    a(f"<p class='small'>Suggested budget: {SAFETY:g} &times; the worst sampled value, rounded up to 1, 2 or 5 "
      "&times; 10<sup>k</sup>; with n samples a new run exceeds the sampled maximum with probability about "
      "1/(n+1), and the factor covers the tail beyond it (hover a value for its reasoning). Margin: budget / worst.</p>")
    if agg["failing"]:
        a("<h2 id='failing'>Failing samples (reproducers)</h2><table><tr><th>sample</th><th>simulator</th>"
          "<th>status</th><th>why</th><th>rerun</th></tr>")
        for f in agg["failing"]:
            a(f"<tr><td>{_e(f['scene'])} #{f['sample']}</td><td>{_e(f['simulator'])}</td><td class='bad'>{_e(f['status'])}</td>"
              f"<td class='small'>{_e(f['reason'])}</td><td class='small'><code>progmo check {_e(f['path'])} -s {_e(f['simulator'])}</code></td></tr>")
        a("</table>")
    refused = [s for s in agg["samples"] if s["refused"]]
    if refused:
        a(f"<h2 id='refused'>Refused samples ({len(refused)})</h2><p class='small'>initial_state = \"refuse\": "
          "these initial states leave the programme; set initial_state = \"assemble\" to project them onto it.</p><ul class='small'>")
        for s in refused[:50]:
            a(f"<li>{_e(s['scene'])} #{s['index']}: {_e(s['refused'])}</li>")
        a("</ul>")
    if meta.get("plots", True):
        a("<h2>Metrics against the varied quantities</h2>")
        for r in agg["metrics"]:
            img = _plot(r, agg)
            if img:
                a(f"<h3>{_e(r['scene'])} / {_e(r['simulator'])}: {_e(r['metric'])}</h3>"
                  f"<img class='plot' alt='{_e(r['metric'])}' src='{img}'>")
    a("<footer id='provenance'><h2>How to rerun</h2>")
    a(f"<pre id='rerun'><code>{_e(meta.get('command', ''))}</code></pre>")
    a("<table>" + "".join(f"<tr><th>{_e(k)}</th><td><code>{_e(v)}</code></td></tr>" for k, v in meta.items()
                          if k not in ("command", "plots")) + "</table>")
    a("</footer></main></body></html>")
    return "\n".join(h)


def _sample_path(agg: dict[str, Any], scene: str, index: int) -> str:
    for s in agg["samples"]:
        if s["scene"] == scene and s["index"] == index:
            return str(s["path"])
    return "?"


def summary_line(agg: dict[str, Any]) -> str:
    tot: dict[str, int] = {}
    for c in agg["counts"].values():
        for k, n in c.items():
            tot[k] = tot.get(k, 0) + n
    n = sum(tot.values())
    head = ("PASS" if ok(agg) else "FAIL") + f": {tot.get('pass', 0)} of {n} (sample x simulator) checks passed"
    rest = [f"{v} {k}" for k, v in sorted(tot.items()) if k != "pass" and v]
    over = [f"{r['scene']}/{r['simulator']} {r['metric']} ({r['over_budget']} over budget)"
            for r in agg["metrics"] if r["over_budget"]]
    if over:
        rest.append("metrics beyond budget: " + ", ".join(over))
    return head + ("; " + "; ".join(rest) if rest else "")


def render_markdown(agg: dict[str, Any], meta: dict[str, Any]) -> str:
    from .report import fmt

    lines = [f"# progmo sweep: {'PASS' if ok(agg) else 'FAIL'}", "", summary_line(agg), "",
             "| scene / simulator | metric | n | median | 90% | 99% | worst | budget | margin | suggested | worst sample |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in agg["metrics"]:
        lines.append(f"| {r['scene']} / {r['simulator']} | {r['metric']} | {r['n']} | {fmt(r['p50'])} | {fmt(r['p90'])} | "
                     f"{fmt(r['p99'])} | {fmt(r['max'])} | {fmt(r['budget'])} | "
                     f"{'' if r['margin'] is None else format(r['margin'], '.3g')} | {fmt(r['suggested_budget'])} | "
                     f"`{_sample_path(agg, r['scene'], r['worst_sample'])}` |")
    lines += ["", "## Rerun", "", "```", str(meta.get("command", "")), "```"]
    return "\n".join(lines) + "\n"


def write_report(agg: dict[str, Any], meta: dict[str, Any], out: Path) -> dict[str, Path]:
    paths = {"json": out / "sweep.json", "html": out / "sweep.html", "md": out / "sweep.md"}
    # each whole under its name, or `.partial` and WriteFailed (exit 3)
    _files.write_text(paths["json"], json.dumps({**agg, "meta": {k: v for k, v in meta.items() if k != "plots"}},
                                                indent=1, default=str, allow_nan=True) + "\n")
    _files.write_text(paths["html"], render_html(agg, meta), errors="backslashreplace")
    _files.write_text(paths["md"], render_markdown(agg, meta), errors="backslashreplace")
    return paths


# --- command -------------------------------------------------------------------------------------
EPILOG = """\
exit codes: 0 every accepted sample passed in every simulator (refused samples are counted, not
failures); 1 a sample failed, errored or did not run; 2 bad usage or a bad sweep file (also one of
more than MAX_SAMPLES samples); 3 a result file cannot be written (one line naming it; it keeps its
.partial name); 130 interrupted (rerun the same command to resume: finished checks are kept in
OUT/results.jsonl).
Outputs in --out: samples/*.toml (one reproducer per sample: progmo check FILE), results.jsonl,
sweep.json, sweep.html, sweep.md. Sweep file format: python -m progmo.sweep --help-format."""


def parser() -> argparse.ArgumentParser:
    from .cli import executor_options

    p = cliutil.parser("progmo sweep", "Tolerance report over distributions of runs: each sample of the sweep "
                       "file is a scene checked in the simulators; per metric the quantiles, the worst "
                       "sample (a reproducer), the budget margin and a suggested budget.")
    p.epilog = EPILOG
    p.formatter_class = cliutil.HelpFormatter
    p.add_argument("scenes", nargs="*", metavar="SCENE",
                   help="scene files or bundled names (default: the sweep file's `scene`)")
    p.add_argument("--spec", metavar="FILE", default=None,
                   help="sweep file (default: the bundled references/sweeps/<scene>.toml)")
    p.add_argument("-o", "--out", default="out/sweep", metavar="DIR", help="output folder (default: out/sweep)")
    p.add_argument("-j", "--jobs", type=int, default=None, metavar="N",
                   help="checks at once on the local executor (default: number of CPUs)")
    executor_options(p)
    p.add_argument("--samples", type=int, default=None, metavar="N", help="override the sweep file's samples")
    p.add_argument("--fresh", action="store_true", help="discard OUT/results.jsonl instead of resuming")
    p.add_argument("--no-plots", action="store_true", help="leave the plots out of sweep.html")
    p.add_argument("--help-format", action="store_true", help="print the sweep file format and exit")
    return p


def _say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def main(argv: list[str] | None = None) -> int:
    from .checks import CheckOptions

    argv = list(sys.argv[1:] if argv is None else argv)
    ns = parser().parse_args(argv)
    if ns.help_format:
        print(__doc__)
        return EXIT_OK
    out = Path(ns.out)
    try:
        spec, samples, texts = _prepare(ns, out)
    except (SweepError, ValueError, OSError) as e:
        _say(f"progmo sweep: error: {last_line(e) if not isinstance(e, SweepError) else e}")
        return EXIT_USAGE

    results_path = out / "results.jsonl"
    records = _resume(ns, out, spec, texts, results_path)
    by_path = {s.path: s for s in samples}
    tasks = [Task(s.path, s.scene, m) for s in samples if not s.refused for m in spec.simulators
             if (s.scene, s.index, m) not in records]
    total = sum(1 for s in samples if not s.refused) * len(spec.simulators)
    _say(f"progmo sweep: {len(samples)} sample(s) ({sum(1 for s in samples if s.refused)} refused) x "
         f"{len(spec.simulators)} simulator(s): {total} check(s), {total - len(tasks)} already done, "
         f"{len(tasks)} to run on the {ns.executor} executor")
    options = CheckOptions()  # the replay step is in each sample's [checks], the horizon its [time] t1
    jobs = ns.jobs if ns.jobs is not None else default_jobs()
    t0 = time.perf_counter()
    done, interrupted, usage = _run_samples(ns, tasks, options, jobs, by_path, records, results_path, total)
    wall = time.perf_counter() - t0
    agg = aggregate(samples, spec, records)
    import shlex

    from .report import provenance

    meta = provenance(Path.cwd(), "progmo sweep " + shlex.join(argv))
    meta.update(executor=ns.executor, address=ns.address or os.environ.get("RAY_ADDRESS") or "",
                wall_seconds=round(wall, 2), checks_this_run=done,
                checks_per_second=round(done / wall, 3) if wall > 0 and done else None,
                plots=not ns.no_plots)
    paths = write_report(agg, meta, out)
    print(f"progmo sweep: {summary_line(agg)}")
    print(f"report: {paths['html']}  (summary: {paths['md']}; data: {paths['json']}; results: {results_path})")
    if interrupted:
        return EXIT_INTERRUPTED
    if usage:
        return EXIT_USAGE
    return EXIT_OK if ok(agg) else EXIT_FAIL


def _prepare(ns: argparse.Namespace, out: Path) -> tuple[Spec, list[Sample], dict[str, str]]:
    """The sweep file (given, or the scene's bundled one; --samples applied), its samples written
    into OUT, and the scenes' texts; bad usage raises (SweepError, ValueError, OSError)."""
    scene_args = list(ns.scenes)
    spec_path = Path(ns.spec) if ns.spec else None
    if spec_path is None:
        if not scene_args:
            raise SweepError("give a SCENE (with a bundled sweep) or --spec FILE")
        found = bundled_spec(Path(scene_args[0]).stem)
        if found is None:
            raise SweepError(f"no bundled sweep for {scene_args[0]!r} (references/sweeps/): give --spec FILE")
        spec_path = found
    spec = load_spec(spec_path)
    if ns.samples is not None:
        if ns.samples < 1:
            raise SweepError("--samples must be >= 1")
        if ns.samples * spec.grid_points() > MAX_SAMPLES:
            raise SweepError(f"--samples {ns.samples} x {spec.grid_points()} grid point(s) = "
                             f"{ns.samples * spec.grid_points():.4g} samples, more than the {MAX_SAMPLES} "
                             "a sweep runs (progmo.sweep.MAX_SAMPLES)")
        spec.samples = ns.samples
    scene_files = []
    if not scene_args:
        if spec.scene is None:
            raise SweepError(f"{spec_path}: no SCENE given and the sweep file names no `scene`")
        scene_files.append(spec_scene(spec))
    for s in scene_args:
        scene_files.append(data.scene_file(s))
    out.mkdir(parents=True, exist_ok=True)
    samples: list[Sample] = []
    texts: dict[str, str] = {}
    for f in scene_files:
        samples += make_samples(Path(f), spec, out)  # loads the scene through the core's door
        texts[str(f)] = f.read_text()
    return spec, samples, texts


def _resume(ns: argparse.Namespace, out: Path, spec: Spec, texts: dict[str, str], results_path: Path) -> dict[tuple[str, int, str], dict[str, Any]]:
    """The results already in OUT (none with --fresh, or when the sweep file or a scene changed:
    the digest in OUT/sweep.digest), keyed by (scene, sample, simulator)."""
    digest = spec_digest(spec, texts)
    stamp = out / "sweep.digest"
    if ns.fresh or (stamp.is_file() and stamp.read_text().strip() != digest):
        if results_path.is_file() and not ns.fresh:
            _say("progmo sweep: the sweep file or a scene changed since the results in OUT: starting afresh")
        _files.remove([results_path])
    _files.write_text(stamp, digest + "\n")
    drop_torn_tail(results_path)
    return read_results(results_path)


def _run_samples(ns: argparse.Namespace, tasks: list[Task], options: Any, jobs: int, by_path: dict[str, Sample],
                 records: dict[tuple[str, int, str], dict[str, Any]], results_path: Path, total: int) -> tuple[int, bool, bool]:
    """Run the checks, each result appended to results.jsonl as it comes (and into `records`);
    (checks done, interrupted, an executor error)."""
    interrupted = usage = False
    done = 0
    try:
        sink = open(results_path, "a")
    except OSError as e:
        raise _files.WriteFailed(results_path, e) from None
    try:
        with sink:
            for task, r in executors.run(tasks, options, executor=ns.executor, jobs=jobs, address=ns.address):
                s = by_path[task.scene_path]
                rec = {"scene": s.scene, "sample": s.index, "simulator": task.simulator,
                       "result": {k: v for k, v in r.to_json().items() if k != "series"}}
                sink.write(json.dumps(rec) + "\n")
                sink.flush()
                records.setdefault((s.scene, s.index, task.simulator), rec)
                done += 1
                _say(f"[{total - len(tasks) + done}/{total}] {s.scene} #{s.index} / {task.simulator}: {r.status} "
                     f"({r.wall_seconds:.1f} s){': ' + r.reason[:160] if r.reason and r.status != 'pass' else ''}")
    except executors.ExecutorError as e:
        usage = True
        _say(f"progmo sweep: error: {e}")
    except KeyboardInterrupt:
        interrupted = True
        _say(f"progmo sweep: interrupted after {done} of {len(tasks)} checks; rerun the same command to resume")
    except OSError as e:  # appending a result (a torn last line is dropped when resuming)
        raise _files.WriteFailed(results_path, e) from None
    return done, interrupted, usage


if __name__ == "__main__":
    from ._stdio import run

    sys.exit(run(main, "progmo sweep"))
