"""The C++ anchor: Pinocchio's own algorithms in C++ on the same n-link chains and programme rows.

bench/cpp/anchor.cpp is compiled at run time against the headers the installed `pin` wheel ships
(site-packages/cmeel.prefix/include: Pinocchio and Boost) plus Eigen (Debian's libeigen3-dev,
/usr/include/eigen3; harness/setup.sh installs it through bench/cpp/install_eigen.sh), header-only
(nothing linked from the wheel), with g++ -O3 and no -march=native: the same x86-64 baseline as
progmo's release build. The binary is cached in ~/.cache/progmo (or $PROGMO_CACHE_DIR), keyed by
the source, the flags, the compiler, Pinocchio's and Eigen's versions. Without a C++ compiler or
Eigen headers the part is skipped and the page says why; a failed build or a disagreement with
progmo fails the part (and the bench's exit code).

Per call, on the chains of common.chain_toml (rows tip_height and shoulder):
- ABA: aba(q, v, 0), no rows (the floor);
- KKT: forwardDynamics(q, v, 0, J, gamma) with J and gamma given (progmo's B and -gamma at the
  state: not rebuilt), u = J^T lambda;
- same work as progmo's right-hand side: J and gamma of the rows rebuilt from the kinematics at
  (t, q, v) (frame Jacobian row and classical drift of the tip, the shoulder's joint row), dv/dt
  solved and u = J^T lambda formed. Four sequences of Pinocchio calls (anchor.cpp names them:
  computeAllTerms + KKT, separate algorithms + KKT, ABA + M^-1 from the ABA factorization + Schur,
  1 + s ABA passes + Schur); "best" is the fastest of them at each n.
Before timing, dv/dt and u of every C++ variant are compared with progmo's kkt formulation
(`Scene.accelerations`) at the initial state and at random states (and ABA with pin.aba): more than
1e-10 relative (to max |dv/dt|, max |u|) fails the part.
Timing: `rounds` rounds, each visiting every n (so each n's samples spread over the whole run), of
5 short loops per figure, progmo and C++ strictly alternated (progmo first, then C++ first, ...);
every loop is the same number of calls (progmo: Scene.rhs_benchmark,
a Rust loop; C++: a C++ loop), both alternating q and q + 1e-9 and both measured in thread CPU
time (the machine is shared: wall time would add the time spent waiting for a core); the table
holds the minimum over all loops and the ratios are taken from those minima (short loops and
minima: the figures least disturbed by the other processes).
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .common import Provenance, SceneDir, chain_toml, log, write_csv

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "cpp" / "anchor.cpp"
INSTALL_EIGEN = HERE / "cpp" / "install_eigen.sh"
#: the chain lengths of issue 15 (the targets read n = 2, 4, 7, 30 and 128)
NS = (2, 4, 7, 16, 30, 64, 128)
#: the C++ variants doing the same work as progmo's right-hand side (anchor.cpp)
SAME = ("same_cat", "same_sep", "same_minv", "same_abaunit")
VARIANTS = ("aba", "kkt") + SAME
#: Pinocchio's O(n + m) constrained dynamics on a frame welded to the world, timed when the rows
#: hold one frame in all six directions (anchor.cpp: the Panda's task); checked against weld_kkt
WELD = ("weld_cd", "weld_lcaba")
#: relative disagreement of dv/dt (and u) with progmo that fails the part; where eps cond(A) is
#: larger (long chains: cond(A) is 1e4 at n = 7, 3e6 at n = 30, 1e9 at n = 128) that bound applies:
#: progmo's own formulations differ from each other by about that much
AGREEMENT = 1e-10
# Pinocchio's exported compile definitions (lib/cmake/pinocchio/pinocchioTargets.cmake), minus the
# template instantiation one: header-only
DEFINES = ("-DBOOST_MPL_LIMIT_LIST_SIZE=30", "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30",
           "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS", "-DBOOST_FUSION_INVOKE_MAX_ARITY=12")
CXXFLAGS = ("-std=c++17", "-O3", "-DNDEBUG", "-Wno-deprecated-declarations")


class Unavailable(Exception):
    """The anchor cannot be built here (no compiler, no Eigen, no Pinocchio headers): skip, say why."""


class AnchorFailed(Exception):
    """The anchor was built but is wrong or broken (build error, crash, disagreement): fail loudly."""


@dataclass(frozen=True)
class Toolchain:
    cxx: str
    cxx_version: str
    flags: tuple[str, ...]
    pin_include: Path
    eigen_include: Path
    pin_version: str
    eigen_version: str

    def command(self, out: Path) -> list[str]:
        return [self.cxx, *self.flags, *DEFINES, "-isystem", str(self.pin_include), "-isystem",
                str(self.eigen_include), str(SOURCE), "-o", str(out)]

    def key(self) -> str:
        h = hashlib.sha256(SOURCE.read_bytes())
        for part in (self.cxx, self.cxx_version, " ".join(self.flags), " ".join(DEFINES), str(self.pin_include),
                     self.pin_version, self.eigen_version):
            h.update(b"\0" + part.encode())
        return h.hexdigest()[:16]


def eigen_include() -> Path | None:
    for d in (os.environ.get("EIGEN_INCLUDE_DIR"), "/usr/include/eigen3", "/usr/local/include/eigen3"):
        if d and (Path(d) / "Eigen" / "Core").is_file():
            return Path(d)
    return None


def _eigen_version(d: Path) -> str:
    text = (d / "Eigen" / "src" / "Core" / "util" / "Macros.h").read_text(errors="replace")
    nums = []
    for k in ("EIGEN_WORLD_VERSION", "EIGEN_MAJOR_VERSION", "EIGEN_MINOR_VERSION"):
        line = next((ln for ln in text.splitlines() if ln.startswith(f"#define {k} ")), None)
        nums.append(line.split()[2] if line else "?")
    return ".".join(nums)


def pinocchio_include() -> tuple[Path, str]:
    """cmeel.prefix/include of the installed `pin` wheel (Pinocchio's and Boost's headers)."""
    try:
        import pinocchio
    except ImportError as e:
        raise Unavailable(f"Pinocchio (the `pin` wheel) is not importable: {e}") from None
    for parent in Path(pinocchio.__file__).resolve().parents:
        inc = parent / "include"
        if parent.name == "cmeel.prefix" and (inc / "pinocchio" / "config.hpp").is_file():
            if not (inc / "boost" / "version.hpp").is_file():
                raise Unavailable(f"no Boost headers beside Pinocchio's in {inc}")
            return inc, str(pinocchio.__version__)
    raise Unavailable(f"the installed Pinocchio ({pinocchio.__file__}) ships no C++ headers "
                      "(expected site-packages/cmeel.prefix/include/pinocchio, as in the `pin` wheel)")


def toolchain() -> Toolchain:
    """What the build needs, or Unavailable with the reason (and the way to fix it)."""
    cxx = os.environ.get("CXX") or shutil.which("g++") or shutil.which("c++")
    if not cxx or not shutil.which(cxx):
        raise Unavailable("no C++ compiler (g++ or $CXX) on PATH")
    eig = eigen_include()
    if eig is None:
        raise Unavailable(f"no Eigen headers (/usr/include/eigen3 or $EIGEN_INCLUDE_DIR); install them with "
                          f"`bash {INSTALL_EIGEN}` (apt-get install libeigen3-dev; harness/setup.sh does it)")
    pin_inc, pin_version = pinocchio_include()
    try:
        ver = subprocess.run([cxx, "--version"], capture_output=True, text=True, timeout=60).stdout.splitlines()
    except (OSError, subprocess.SubprocessError) as e:
        raise Unavailable(f"C++ compiler {cxx} does not run: {e}") from None
    extra = os.environ.get("PROGMO_ANCHOR_CXXFLAGS")
    flags = tuple(shlex.split(extra)) if extra else CXXFLAGS
    return Toolchain(cxx, ver[0] if ver else "?", flags, pin_inc, eig, pin_version, _eigen_version(eig))


def cache_dir() -> Path:
    base = os.environ.get("PROGMO_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "progmo")
    return Path(base)


def build(tc: Toolchain | None = None, cache: Path | None = None) -> tuple[Path, bool]:
    """The anchor binary (built when not cached) and whether it was cached. Raises Unavailable,
    or AnchorFailed with the compiler's output when the build fails."""
    tc = tc or toolchain()
    d = (cache or cache_dir()) / f"anchor-{tc.key()}"
    exe = d / "anchor"
    if exe.is_file() and os.access(exe, os.X_OK):
        return exe, True
    d.mkdir(parents=True, exist_ok=True)
    # One build at a time per key: a second caller (harness/test.sh builds it beside the tests
    # that use it) waits here for the first and then finds it cached.
    with open(d / "build.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if exe.is_file() and os.access(exe, os.X_OK):
            return exe, True
        return _build_locked(tc, d, exe), False


def _build_locked(tc: Toolchain, d: Path, exe: Path) -> Path:
    tmp = d / f"anchor.tmp{os.getpid()}"
    cmd = tc.command(tmp)
    log(f"[anchor] building (first use: about 5 min of CPU; cached afterwards): {' '.join(shlex.quote(c) for c in cmd)}")
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=1800)
    except (OSError, subprocess.SubprocessError) as e:
        raise AnchorFailed(f"building {SOURCE.name} failed: {e}") from None
    if r.returncode != 0 or not tmp.is_file():
        tmp.unlink(missing_ok=True)
        tail = "\n".join(r.stderr.splitlines()[-30:])
        raise AnchorFailed(f"building {SOURCE.name} failed (exit {r.returncode}):\n{tail}")
    os.replace(tmp, exe)  # atomic: a reader never sees half a binary
    (d / "build.json").write_text(json.dumps(dict(command=cmd[:-1] + [str(exe)], compiler=tc.cxx_version,
                                                   pin=tc.pin_version, eigen=tc.eigen_version), indent=1))
    return exe


# ---------------------------------------------------------------------------------------------
# The model file and the running process


def model_text(scene) -> str:
    """The scene as anchor.cpp reads it: Pinocchio's model from the scene's URDF export (joint
    types, placements, inertias, gravity) and the programme rows with their time laws (the
    hand-written rows of the scipy pipeline: joint rows and the tip height of a planar chain)."""
    from .scipy_pipeline import pipeline_for

    pipe = pipeline_for(scene)  # NotImplementedError: not a chain / double pendulum
    model: Any = pipe.model
    lines = ["progmo-anchor 1", f"joints {model.njoints - 1}",
             "gravity " + " ".join(repr(float(x)) for x in model.gravity.linear)]
    for i in range(1, model.njoints):
        jm = model.joints[i]
        kind = jm.shortname()
        if kind not in ("JointModelRX", "JointModelRY", "JointModelRZ", "JointModelPX", "JointModelPY", "JointModelPZ"):
            raise NotImplementedError(f"{scene.name}: joint type {kind} not supported by the C++ anchor")
        if jm.idx_v != i - 1:
            raise NotImplementedError(f"{scene.name}: joints not in velocity order")
        M, Y = model.jointPlacements[i], model.inertias[i]
        nums = [*np.asarray(M.rotation).ravel(), *np.asarray(M.translation), Y.mass, *np.asarray(Y.lever),
                *np.asarray(Y.inertia).ravel()]
        lines.append(f"joint {kind} {model.parents[i]} " + " ".join(repr(float(x)) for x in nums))
    lines.append(f"rows {len(pipe.rows)}")
    for r in pipe.rows:
        if r.law is None:
            raise NotImplementedError(f"{scene.name}: row without a known time law")
        law, amp, w = r.law
        if r.kind == "tip_z":  # the tip of the last link, l below its joint (scipy_pipeline checks)
            where = f"tip {model.njoints - 1} 0.0 0.0 {-r.length!r} 2"
        else:
            where = f"joint {r.k}"
        lines.append(f"row {where} {law} {float(amp)!r} {float(w)!r}")
    return "\n".join(lines) + "\n"


def _nums(x) -> str:
    return " ".join(repr(float(v)) for v in np.asarray(x, dtype=float).ravel())


class Process:
    """One running anchor on one scene (context manager)."""

    def __init__(self, exe: Path, scene, workdir: Path, text: str | None = None):
        """`text`: the model file (default model_text(scene): the chains)."""
        self.scene = scene
        self.path = workdir / f"{scene.name}.anchor"
        self.path.write_text(model_text(scene) if text is None else text)
        self.proc = subprocess.Popen([str(exe), str(self.path)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        self.header = self._line()
        if not self.header.startswith("ready"):
            raise self._died(f"unexpected first line {self.header!r}")

    def _died(self, what: str) -> AnchorFailed:
        self.proc.kill()
        err = self.proc.stderr.read() if self.proc.stderr else ""
        return AnchorFailed(f"anchor on {self.scene.name}: {what}; stderr: {err.strip()[-2000:]}")

    def _line(self) -> str:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line:
            raise self._died(f"exited with code {self.proc.wait()}")
        return line.strip()

    def _ask(self, cmd: str) -> list[list[str]]:
        assert self.proc.stdin is not None
        self.proc.stdin.write(cmd + "\n")
        self.proc.stdin.flush()
        out = []
        while (line := self._line()) != "end":
            out.append(line.split())
        return out

    def _state(self, t, q, v) -> str:
        d = self.scene.dynamics(t, np.asarray(q, float), np.asarray(v, float))
        # Pinocchio's convention J a + gamma = 0: progmo's B a = gamma, so gamma_pin = -gamma
        return f"{float(t)!r} {_nums(q)} {_nums(v)} {_nums(d['B'])} {_nums(-np.asarray(d['gamma']))}"

    def check(self, t, q, v) -> dict[tuple[str, str], np.ndarray]:
        """{("a" | "u", variant): vector} at (t, q, v)."""
        return {(r[0], r[1]): np.array([float(x) for x in r[2:]]) for r in self._ask("check " + self._state(t, q, v))}

    def bench(self, iters: int, t, q, v) -> dict[str, float]:
        """Seconds per call of every variant (one loop of `iters` calls each)."""
        return {r[1]: float(r[2]) for r in self._ask(f"bench {int(iters)} " + self._state(t, q, v))}

    def close(self):
        if self.proc.poll() is None:
            try:
                assert self.proc.stdin is not None
                self.proc.stdin.write("quit\n")
                self.proc.stdin.close()
                self.proc.wait(timeout=10)
            except (OSError, subprocess.SubprocessError):
                self.proc.kill()
        for s in (self.proc.stdout, self.proc.stderr):
            if s:
                s.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# ---------------------------------------------------------------------------------------------
# Agreement and timing


def states(scene, count: int, seed: int = 15) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """The initial state and count - 1 random ones near it (non-zero velocities: the drift terms)."""
    rng = np.random.default_rng(seed)
    q0, v0 = np.array(scene.q0), np.array(scene.v0)
    out = [(scene.t0, q0, v0)]
    for _ in range(count - 1):
        out.append((float(rng.uniform(scene.t0, scene.t1)), q0 + rng.uniform(-0.2, 0.2, len(q0)),
                    rng.uniform(-1.0, 1.0, len(v0))))
    return out


def agreement(scene, proc: Process, count: int = 3) -> tuple[dict[str, float], float]:
    """Largest relative disagreement per variant with progmo's kkt (dv/dt and u; ABA against
    pin.aba) over `count` states, and the tolerance applied (AGREEMENT, or eps cond(A) where
    larger). Raises AnchorFailed beyond the tolerance."""
    import pinocchio as pin

    from .scipy_pipeline import pipeline_for

    pipe = pipeline_for(scene)
    worst = {v: 0.0 for v in VARIANTS}
    tol = AGREEMENT
    for t, q, v in states(scene, count):
        got = proc.check(t, q, v)
        ref = scene.accelerations(t, q, v, "kkt")
        cond = float(np.linalg.cond(scene.dynamics(t, q, v)["mass"]))
        tol = max(tol, float(np.finfo(float).eps) * cond)
        a_aba = np.asarray(pin.aba(pipe.model, pipe.data, q, v, np.zeros(len(v))))
        for var in VARIANTS:
            if var == "aba":
                errs = [_rel(got[("a", var)], a_aba)]
            else:
                errs = [_rel(got[(k, var)], ref[k]) for k in ("a", "u")]
            worst[var] = max(worst[var], *errs)
    bad = {k: e for k, e in worst.items() if not e <= tol}
    if bad:
        raise AnchorFailed(f"{scene.name}: C++ and progmo disagree beyond {tol:.1e} relative: "
                           + ", ".join(f"{k} {e:.1e}" for k, e in bad.items())
                           + " (dv/dt and u against progmo's kkt; aba against pin.aba)")
    return worst, tol


def _rel(x, ref) -> float:
    """max |x - ref| / max |ref| (NaN-safe: a NaN is infinitely wrong)."""
    x, ref = np.asarray(x, float), np.asarray(ref, float)
    if x.shape != ref.shape or not np.all(np.isfinite(x)):
        return float("inf")
    return float(np.abs(x - ref).max() / max(np.abs(ref).max(), 1e-300))


def rhs_cpu(scene, iters: int, formulation: str) -> float:
    """Thread CPU seconds per call of progmo's RHS: Scene.rhs_benchmark's Rust loop runs on this
    thread (GIL released), timed with time.thread_time as anchor.cpp times its loops."""
    t = time.thread_time()
    scene.rhs_benchmark(iters, formulation)
    return (time.thread_time() - t) / iters


#: progmo's formulations timed: the paper's null-space form, KKT, the articulated-body form
#: (O(n) per row on trees) and `auto`, the default (null_space below AUTO_ARTICULATED_NV velocities,
#: articulated_body from there on), which the targets judge
PROGMO = ("null_space", "kkt", "articulated_body", "auto")


class Timing:
    """Per-call seconds of progmo's right-hand sides (PROGMO) and of every C++ variant on one scene
    at its initial state: the minimum over every loop of every round. A round is `reps` short loops
    of each side, strictly alternated; each figure spends about `budget_s` per round."""

    def __init__(self, scene, proc: Process, budget_s: float, reps: int = 5):
        self.scene, self.proc, self.reps = scene, proc, reps
        probe = min(rhs_cpu(scene, 20, "null_space") for _ in range(3))
        self.iters = int(max(10, min(200000, budget_s / reps / max(probe, 1e-9))))
        self.best: dict[str, float] = {}
        self.rounds = 0

    def _keep(self, k: str, x: float):
        self.best[k] = min(self.best.get(k, np.inf), x)

    def round(self):
        sc = self.scene
        t, q, v = sc.t0, np.array(sc.q0), np.array(sc.v0)

        def progmo():
            for f in PROGMO:
                self._keep(f"progmo_{f}", rhs_cpu(sc, self.iters, f))

        def cpp():
            for k, x in self.proc.bench(self.iters, t, q, v).items():
                self._keep(k, x)

        for i in range(self.reps):
            for step in ((progmo, cpp) if i % 2 == 0 else (cpp, progmo)):
                step()
        self.rounds += 1

    def row(self) -> dict[str, Any]:
        best = self.best
        row: dict[str, Any] = dict(n=len(self.scene.v0), iterations=self.iters, rounds=self.rounds,
                                   loops_per_round=self.reps)
        row.update({f"{k}_s": x for k, x in best.items()})
        row["same_best"] = min(SAME, key=lambda k: best[k])
        row["same_best_s"] = best[row["same_best"]]
        for f in PROGMO:
            row[f"ratio_{f}"] = best[f"progmo_{f}"] / row["same_best_s"]
        row["ratio_null_space_kkt"] = best["progmo_null_space"] / best["kkt"]
        row["ratio_auto_kkt"] = best["progmo_auto"] / best["kkt"]
        welds = [k for k in WELD if k in best]
        if welds:
            row["weld_best"] = min(welds, key=lambda k: best[k])
            row["weld_best_s"] = best[row["weld_best"]]
            for f in PROGMO:
                row[f"ratio_{f}_weld"] = best[f"progmo_{f}"] / row["weld_best_s"]
        return row


HEADER = ["n", "aba_s", "kkt_s", "same_cat_s", "same_sep_s", "same_minv_s", "same_abaunit_s", "same_best",
          "same_best_s", "progmo_null_space_s", "progmo_kkt_s", "progmo_articulated_body_s", "progmo_auto_s",
          "ratio_null_space", "ratio_kkt", "ratio_articulated_body", "ratio_auto", "ratio_null_space_kkt",
          "ratio_auto_kkt", "agreement", "agreement_tol", "iterations", "rounds", "loops_per_round"]


def run(out: Path, prov: Provenance, ns: Sequence[int] = NS, rounds: int = 7, budget_s: float = 0.05,
        check_states: int = 3) -> dict[str, Any]:
    """Builds (or reuses) the anchor, checks agreement on every chain, then times them all round by
    round (a round visits every n, so each n's samples spread over the whole run rather than one
    stretch of a neighbour's load). Returns dict(rows, build): raises Unavailable (skip with the
    reason) or AnchorFailed (fail loudly)."""
    from contextlib import ExitStack

    from .. import Scene

    tc = toolchain()
    exe, cached = build(tc)
    build_info = dict(compiler=tc.cxx_version, flags=" ".join(tc.flags), pin=tc.pin_version, eigen=tc.eigen_version,
                      binary=str(exe), cached=cached, command=" ".join(shlex.quote(c) for c in tc.command(exe)))
    checks, timings = [], []
    with SceneDir() as d, tempfile.TemporaryDirectory(prefix="progmo-anchor-") as work, ExitStack() as stack:
        for n in ns:
            scene = Scene(str(d.write(f"chain_{n}", chain_toml(n, name=f"chain_{n}"))))
            proc = stack.enter_context(Process(exe, scene, Path(work)))
            worst, tol = agreement(scene, proc, check_states)
            log(f"[anchor] n = {n}: agreement {max(worst.values()):.1e} (tolerance {tol:.1e})")
            checks.append((worst, tol))
            timings.append(Timing(scene, proc, budget_s))
        for r in range(rounds):
            log(f"[anchor] timing round {r + 1} of {rounds} (n = {', '.join(map(str, ns))})")
            for tm in timings:
                tm.round()
    rows = []
    for tm, (worst, tol) in zip(timings, checks):
        row = tm.row()
        row.update(agreement=max(worst.values()), agreement_tol=tol, agreement_by_variant=worst)
        rows.append(row)
    write_csv(out / "anchor.csv", prov, HEADER, ([r[h] for h in HEADER] for r in rows))
    return dict(rows=rows, build=build_info)


def at(rows, n: int) -> dict | None:
    return next((r for r in rows if r["n"] == n), None)


if __name__ == "__main__":  # a quick manual run: python -m progmo.bench.anchor [n ...]
    import argparse

    ap = argparse.ArgumentParser(description="build and run the C++ anchor on n-link chains")
    ap.add_argument("n", nargs="*", type=int, default=[2, 7])
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as o:
        res = run(Path(o), Provenance(sys.argv[1:]), a.n, a.rounds, 0.02)
    for r in res["rows"]:
        print({k: (f"{x * 1e6:.2f}us" if k.endswith("_s") else x) for k, x in r.items() if k != "agreement_by_variant"})
