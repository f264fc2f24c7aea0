"""Shared pieces of `progmo bench`: provenance (rerun command, versions), generated chain scenes,
Pinocchio models from our URDF export, CPU timing and the log-log interpolation at equal error."""

from __future__ import annotations

import csv
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from .._core import FORMULATIONS as _FORMULATIONS, INTEGRATORS as _INTEGRATORS

#: the core's vocabulary (progmo::solve); the sweeps use every formulation (not `auto`, which names
#: one of them) and the adaptive integrators
FORMULATIONS = tuple(n for n in _FORMULATIONS if n != "auto")
INTEGRATORS = tuple(n for n in _INTEGRATORS if n != "rk4")


def repo_root() -> Path:
    """Where the benchmark is run from: the checkout, else the working directory (provenance)."""
    from .. import data

    return data.checkout() or Path.cwd()


def scene_path(name: str) -> Path:
    from .. import data

    return data.scenes_dir() / f"{name}.toml"


# ---------------------------------------------------------------------------------------------
# Provenance


class Provenance:
    """The command that reproduces a run and the versions that produced it."""

    def __init__(self, argv: Sequence[str]):
        # printable: an argument that is not UTF-8 (a path) shows as escapes (`\udcff`)
        args = " ".join(a.encode("utf-8", "backslashreplace").decode("utf-8") for a in argv)
        self.command = f"progmo bench {args}".strip()
        self.python_command = f"python -m progmo.bench.main {args}".strip()
        self.versions = versions()

    def lines(self) -> list[str]:
        v = ", ".join(f"{k} {val}" for k, val in self.versions.items())
        return [
            f"rerun: {self.command}   (equivalently: {self.python_command}, from {repo_root()})",
            f"versions: {v}",
        ]

    def footer(self) -> str:
        """Short text for the bottom of a figure."""
        keys = ("progmo", "commit", "numpy", "scipy", "pin", "mpmath", "python")
        v = ", ".join(f"{k} {self.versions[k]}" for k in keys if k in self.versions)
        return f"rerun: {self.command}\n{v}"


def versions() -> dict[str, str]:
    from .. import _core

    out = {"progmo": _core.version(), "commit": _git_commit(), "python": platform.python_version()}
    for mod, name in (("numpy", "numpy"), ("scipy", "scipy"), ("pinocchio", "pin"),
                      ("mpmath", "mpmath"), ("matplotlib", "matplotlib")):
        try:
            m = __import__(mod)
            out[name] = getattr(m, "__version__", "?")
        except Exception:  # noqa: BLE001 - an absent optional tool is reported, not fatal
            out[name] = "absent"
    out["machine"] = f"{platform.machine()} {os.cpu_count()} cpu ({platform.processor() or 'unknown'})"
    return out


def _git_commit() -> str:
    from .. import data

    return data.git_revision() or "unknown"


def write_csv(path: Path, prov: Provenance, header: Sequence[str], rows: Iterable[Sequence]) -> Path:
    """CSV whose first lines are `# rerun: ...` and `# versions: ...` comments."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as fh:
        for line in prov.lines():
            fh.write(f"# {line}\n")
        w = csv.writer(fh)
        w.writerow(header)
        for r in rows:
            w.writerow([_fmt(x) for x in r])
    return path


def _fmt(x):
    if isinstance(x, float):
        return f"{x:.6e}"
    return x


ZERO_LABEL = "exactly 0 (marked on the axis floor)"


def log_plot(ax, x, y, *args, logx: bool = True, **kw) -> int:
    """Plot y > 0 on log axes (loglog, or semilogy with logx=False) without hiding zeros: a value of
    exactly 0 has no place on a log axis, so it breaks the line and is drawn as a triangle on the
    axis floor (labelled once per axis, ZERO_LABEL), not clamped to a tiny number. Returns the number
    of zeros."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    zero = y == 0
    line = ax.loglog if logx else ax.semilogy
    (h,) = line(x, np.where(zero, np.nan, y), *args, **kw)
    if zero.any():
        labelled = any(t.get_label() == ZERO_LABEL for t in ax.get_lines())
        ax.plot(x[zero], np.zeros(int(zero.sum())), "v", color=h.get_color(), ms=6, clip_on=False,
                transform=ax.get_xaxis_transform(), label="_" if labelled else ZERO_LABEL)
    return int(zero.sum())


def count_zeros(values) -> int:
    """How many values are exactly 0 (what log_plot marks on the axis floor)."""
    return int(np.sum(np.asarray(list(values), dtype=float) == 0))


def save_figure(fig, path: Path, prov: Provenance) -> Path:
    from matplotlib.ticker import NullFormatter

    for ax in fig.axes:  # minor tick labels of log axes overlap: drop them
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.yaxis.set_minor_formatter(NullFormatter())
    fig.text(0.01, 0.005, prov.footer(), fontsize=6, va="bottom", ha="left", family="monospace")
    fig.savefig(path, dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path


# ---------------------------------------------------------------------------------------------
# Timing


def cpu_time(fn: Callable[[], Any], repeats: int, budget_s: float = 1.0) -> tuple[float, Any]:
    """Median process CPU time of up to `repeats` calls of fn (fewer once `budget_s` of CPU is
    spent: slow solves are timed once or twice), and the last result."""
    times = []
    result = None
    for _ in range(max(1, repeats)):
        t = time.process_time()
        result = fn()
        times.append(time.process_time() - t)
        if sum(times) > budget_s:
            break
    return statistics.median(times), result


def pareto(errors: Sequence[float], times: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Lower-left envelope of (error, time): the runs a user would pick. Sorted by error ascending,
    time strictly decreasing. Non-finite or zero errors are dropped (zero is clamped to 1e-17)."""
    pts = sorted((max(e, 1e-17), t) for e, t in zip(errors, times) if np.isfinite(e) and t > 0)
    front: list[tuple[float, float]] = []
    for e, t in pts:
        if not front or t < front[-1][1]:
            front.append((e, t))
    return np.array([p[0] for p in front]), np.array([p[1] for p in front])


def time_at_error(errors, times, target: float) -> float:
    """CPU time needed for error `target`, interpolated in log-log on the Pareto front; NaN if the
    front does not cover the target."""
    e, t = pareto(errors, times)
    if len(e) == 0 or not (e[0] <= target <= e[-1]):
        return float("nan")
    if len(e) == 1:
        return float(t[0])
    return float(np.exp(np.interp(np.log(target), np.log(e), np.log(t))))


def common_error_levels(curves: Sequence[tuple[Sequence[float], Sequence[float]]]) -> list[float]:
    """Decades inside the error range every curve's Pareto front covers; the geometric middle of the
    overlap if no decade fits."""
    lo, hi = 0.0, np.inf
    for errs, ts in curves:
        e, _ = pareto(errs, ts)
        if len(e) == 0:
            return []
        lo, hi = max(lo, e[0]), min(hi, e[-1])
    if not lo <= hi:
        return []
    decades = [10.0 ** k for k in range(-14, 0) if lo <= 10.0 ** k <= hi]
    return decades or [float(np.sqrt(lo * hi))]


# ---------------------------------------------------------------------------------------------
# Generated scenes


def chain_toml(n: int, *, masses: Sequence[float] | None = None, length: float = 0.25,
               q0: float | None = None, name: str | None = None, t1: float = 2.0) -> str:
    """An n-link planar chain (hinges about y) in the layout of references/scenes/chain_8.toml:
    programme rows tip_height and, for n >= 3, shoulder. The generator lives in the core
    (progmo::scene::chain, shared with the Rust benchmarks and tests); see its docs."""
    from .._core import chain_toml as core_chain_toml

    return core_chain_toml(n, masses=None if masses is None else [float(m) for m in masses],
                           length=length, q0=q0, name=name, t1=t1)


class SceneDir:
    """A temporary directory of generated scene files (removed on close)."""

    def __init__(self):
        self._tmp = tempfile.TemporaryDirectory(prefix="progmo-bench-")
        self.path = Path(self._tmp.name)

    def write(self, name: str, text: str) -> Path:
        p = self.path / f"{name}.toml"
        p.write_text(text)
        return p

    def close(self):
        self._tmp.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def pinocchio_model(scene):
    """Pinocchio model and data from the scene's URDF export (gravity set from the report). The
    exported coordinates must map one to one (hinge/slide trees); anything else raises."""
    import pinocchio as pin

    doc, rep = scene.export("urdf")
    for c in rep["q_map"] + rep["v_map"]:
        if c["conversion"] != "same" or c["index"] != c["sim_index"]:
            raise ValueError(f"{scene.name}: coordinates do not map one to one ({c})")
    if rep.get("root_joint") or rep.get("harness_forces"):
        raise ValueError(f"{scene.name}: root joints / harness forces not supported by the bench")
    with tempfile.NamedTemporaryFile("w", suffix=".urdf", delete=False) as fh:
        fh.write(doc)
        path = fh.name
    try:
        model = pin.buildModelFromUrdf(path)
    finally:
        os.unlink(path)
    model.gravity.linear = np.array(rep["gravity"], dtype=float)
    return model, model.createData()


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)
