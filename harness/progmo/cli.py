"""Command line of the harness: ``python -m progmo.cli check|debug|report ...``.

The Rust ``progmo`` command forwards ``progmo check ...`` and ``progmo debug ...`` here, so the
help speaks of ``progmo``. Exit codes of ``check`` (stable; the nightly job branches on them):

* 0: every check passed (or is a not_checked the scene declares), at least one passed, and no metric
  regressed against its baseline;
* 1: a check failed (a metric beyond its budget), errored, was not checked without the scene
  declaring it, did not run, or regressed;
* 2: bad usage, an unknown scene or simulator, a scene file that does not load or whose initial
  state the solver refuses (the same located message as ``progmo solve``), or an unreadable
  baseline (the other scenes still run; 2 wins over 1);
* 130: interrupted (the results so far and the report are still written, marked INTERRUPTED);
* 3: a result file or standard output could not be written (a full device): one line naming the
  file, which keeps its ``.partial`` name (:mod:`progmo._files`); 141: standard output was closed
  early (``| head``); see :mod:`progmo._stdio`.
"""

from __future__ import annotations

import argparse
import json
import importlib
import importlib.util
import os
import shlex
import signal
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from . import baselines as bl
from . import cliutil, data, executors
from . import history as hist
from . import report as rp
from .parallel import Task, default_jobs, error_result, last_line
from .results import CheckResult, save

if TYPE_CHECKING:
    from .checks import CheckOptions

EXIT_OK, EXIT_FAIL, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130

EPILOG = """\
exit codes: 0 all pass (or declared not_checked) and no regression; 1 a fail, error,
undeclared not_checked or regression; 2 bad usage, or a scene that does not load or that the
solver refuses (the rest still runs); 3 a result file cannot be written (one line naming it; it
keeps its .partial name); 130 interrupted (the results so far and the report, marked INTERRUPTED).
Outputs in --out: results.json (every CheckResult), run.json, report.html (self-contained),
summary.md, summary.csv; written even when the run fails or is interrupted.
Baselines: <scene>.<simulator>.json in the package's references/baselines (progmo.data), or
--baselines DIR; format: references/baselines/README.md."""


def repo_root() -> Path:
    """The folder paths in the report are shown relative to: the checkout this package runs from,
    else the working directory."""
    return data.checkout() or Path.cwd()


def executor_options(p: argparse.ArgumentParser) -> None:
    """--executor and --address (check and sweep)."""
    from .executors import EXECUTORS

    p.add_argument("--executor", choices=EXECUTORS, default="local", metavar="NAME",
                   help="where checks run: local (this machine's cores, --jobs) or ray (a Ray cluster: "
                   "--address, else $RAY_ADDRESS, else a Ray instance started for the run)")
    p.add_argument("--address", metavar="HOST:PORT", default=None,
                   help="the Ray cluster of --executor ray (default: $RAY_ADDRESS)")


def parser() -> argparse.ArgumentParser:
    from .checks import CHECKERS, SIMULATORS

    p = cliutil.parser("progmo", "Cross-simulator checks of progmo (also: python -m progmo.cli).")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)
    c = sub.add_parser(
        "check",
        help="replay the control forces of scenes open-loop in MuJoCo, Pinocchio and Drake; write a report",
        description="Check scenes in simulators, in parallel: each (scene, simulator) pair proves that "
        "the control forces u computed by progmo keep the simulated motion on the programme. Compares "
        "metrics with their budgets (scene [tolerances]) and accepted baselines; writes the report.",
        epilog=EPILOG,
        formatter_class=cliutil.HelpFormatter,
    )
    cliutil.styled(c)
    c.add_argument("scenes", nargs="*", metavar="SCENE",
                   help="scene files (TOML), folders of them, or names of bundled scenes "
                   "(default: every bundled scene)")
    c.add_argument("-s", "--simulator", action="append", choices=CHECKERS, metavar="NAME",
                   help=f"simulator to check in, repeatable: {', '.join(SIMULATORS)} (default: every one "
                   "installed; one not installed is named in the report), or "
                   "solver_only (a second formulation and the scene's [[reference]] values; every "
                   "lagrangian scene is checked this way, whatever the simulators)")
    c.add_argument("-j", "--jobs", type=int, default=None, metavar="N",
                   help="checks run at once, one process each (default: number of CPUs; 1 runs in this process)")
    c.add_argument("-o", "--out", default="out/check", metavar="DIR", help="output folder (default: out/check)")
    executor_options(c)
    c.add_argument("--accept", action="store_true",
                   help="write the metrics of every passing check as its new baseline (prints what changed)")
    c.add_argument("--baselines", metavar="DIR", default=None,
                   help="baseline folder (default: the bundled references/baselines)")
    c.add_argument("--step", type=float, default=None, metavar="H",
                   help="replay step (default: the scene's [checks] replay_step, else a convergence check)")
    c.add_argument("--horizon", type=float, default=None, metavar="T",
                   help="replay horizon in seconds (default: the scene's whole time span)")
    c.add_argument("--samples", type=int, default=8, metavar="N",
                   help="sample states of the parity and instantaneous checks (default: 8)")
    c.add_argument("--history", metavar="DIR", default=None,
                   help="keep this run's record in DIR (one JSON per run) and draw every metric's trend "
                   "over the recorded runs in the report, naming the run each failure started")
    c.add_argument("--json", action="store_true",
                   help="print the outcome as one JSON object on stdout (coverage, ok, and every result "
                   "without its plot series); the lines for people go to stderr")
    c.add_argument("--no-plots", action="store_true",
                   help="leave the plots out of report.html (faster; tables and verdicts unchanged)")
    sub.add_parser("debug", help="debugging run of one scene (progmo.debug; its own --help)", add_help=False)
    r = cliutil.styled(sub.add_parser(
        "report", help="re-render the report of a saved run from its results.json and run.json",
        description="Re-render report.html, summary.md and summary.csv of a saved check run from its "
        "results.json and run.json (exit 0 if the run passed, 1 if not, 2 if they cannot be read)."))
    r.add_argument("dir", metavar="DIR", help="output folder of a check run (default layout: out/check)")
    return p


# --- check ---------------------------------------------------------------------------------------
def _scene_files(args: list[str]) -> tuple[list[Path], list[str]]:
    """Scene files named by the arguments (files, folders, bundled names) and the problems."""
    from ._core import SceneError, resolve_file

    scenes_dir = data.scenes_dir()
    if not args:
        return sorted(scenes_dir.glob("*.toml")), ([] if scenes_dir.is_dir() else [f"no bundled scenes in {scenes_dir}"])
    files, problems = [], []
    for a in args:
        p = Path(a)
        if p.is_file():
            files.append(p)
        elif p.is_dir():
            found = sorted(p.glob("*.toml"))
            for f in found:
                # a file of the folder that resolves outside it (a symlink) is refused, not read
                try:
                    resolve_file(f.name, p)
                    files.append(f)
                except SceneError as e:
                    problems.append(f"{f}: {e}")
            if not found:
                problems.append(f"{a}: folder holds no *.toml scene")
        else:
            try:
                files.append(data.scene_file(a))
            except ValueError as e:
                problems.append(str(e))
    return files, problems


def rerun_command(argv: list[str], cwd: Path, root: Path) -> str:
    """The command that reruns this check (without --accept: rerunning must not re-accept)."""
    args = shlex.join(a for a in argv if a != "--accept")
    lines = [f"progmo check {args}".rstrip()]
    if data.checkout() is not None:
        lines.append(f"# on a fresh machine: bash harness/nightly.sh {args}".rstrip())
    lines.append(f"# equivalently: python -m progmo.cli check {args}".rstrip())
    if cwd.resolve() != root.resolve():
        lines.insert(0, f"cd {shlex.quote(str(cwd))}")
    return "\n".join(lines)


def _save_atomic(results: list[CheckResult], path: Path, encoded: dict[int, str] | None = None) -> None:
    save(results, str(path), encoded)  # through results.json.partial: whole or WriteFailed (exit 3)


def _say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


@dataclass
class _CheckRun:
    """What the steps of one `progmo check` share: the options, where results go, and what they
    collect (the results, the report's notes, the plan of (scene, simulator) checks)."""

    ns: argparse.Namespace
    root: Path
    out: Path
    base_dir: Path
    sims: list[str]
    notes: list[str] = field(default_factory=list)
    results: list[CheckResult] = field(default_factory=list)
    usage_problem: bool = False  # exit 2 (wins over 1)
    tasks: list[Task] = field(default_factory=list)
    planned: list[tuple[str, str]] = field(default_factory=list)
    scenes: dict[str, dict[str, str]] = field(default_factory=dict)
    done: int = 0
    interrupted: bool = False
    other_versions: dict[str, list[str]] = field(default_factory=dict)
    #: each taken result's results.json text, so the save after every check encodes only the new one
    encoded: dict[int, str] = field(default_factory=dict)


def default_simulators(asked: list[str] | None) -> tuple[list[str], list[str]]:
    """(the simulators to check in, notes): those asked for (``--simulator``), else every simulator
    whose package imports; one that does not is left out of the default set with a note naming it
    and how to install it (asked for explicitly, its checks are errors saying the same)."""
    from .checks import SIMULATORS, available

    if asked:
        return list(dict.fromkeys(asked)), []
    sims, notes = [], []
    for m in SIMULATORS:
        why = available(m)
        if why is None:
            sims.append(m)
        else:
            notes.append(f"{m} NOT CHECKED: its package is not installed ({why}); the other simulators ran")
    return sims, notes


def cmd_check(ns: argparse.Namespace, argv: list[str]) -> int:
    from .checks import CheckOptions
    from .results import SOLVER_ONLY

    t_start = time.perf_counter()
    root = repo_root()
    sims, missing = default_simulators(ns.simulator)
    jobs = ns.jobs if ns.jobs is not None else default_jobs()
    problem = CheckOptions(step=ns.step, horizon=ns.horizon, samples=ns.samples).problem()
    if problem is None and jobs < 1:
        problem = f"jobs: must be >= 1, got {jobs}"
    if problem is not None:  # the message of progmo.check, named by the flag
        _say(f"progmo check: error: --{problem}")
        return EXIT_USAGE
    out = Path(ns.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        _say(f"progmo check: error: cannot create output folder {out}: {e}")
        return EXIT_USAGE
    base_dir = Path(ns.baselines) if ns.baselines else data.baselines_dir()

    c = _CheckRun(ns, root, out, base_dir, sims)
    for note in missing:  # a simulator left out of the default set says so (report and stderr)
        _say(f"progmo check: {note}")
        c.notes.append(note)
    _plan_checks(c)
    columns = sims + [SOLVER_ONLY] if SOLVER_ONLY not in sims and any(m == SOLVER_ONLY for _, m in c.planned) else sims

    options = CheckOptions(step=ns.step, horizon=ns.horizon, samples=ns.samples)
    prov = rp.provenance(root, rerun_command(argv, Path.cwd(), root))
    prov["jobs"] = jobs if ns.executor == "local" else f"ray ({ns.address or os.environ.get('RAY_ADDRESS') or 'local instance'})"
    prov["baselines"] = _rel(base_dir, root)
    run = rp.Run(results=c.results, simulators=columns, provenance=prov, scenes=c.scenes, notes=c.notes,
                 plots=not ns.no_plots, planned=c.planned)
    paths = _run_checks(c, run, options, jobs, columns, t_start)
    return _check_outcome(c, run, paths)


def _plan_checks(c: _CheckRun) -> None:
    """The (scene, simulator) checks to run, from the scene arguments; a scene that does not load
    or that the solver refuses is an error result (exit 2) and the rest still runs."""
    files, problems = _scene_files(c.ns.scenes)
    for pr in problems:
        _say(f"progmo check: error: {pr}")
        c.notes.append(pr)
        c.usage_problem = True
    for f in files:
        try:
            _plan_scene(c, f)
        except Exception as e:  # noqa: BLE001 - SceneError or worse: report it, run the rest
            msg = f"scene does not load: {last_line(e)}"
            _say(f"progmo check: error: {f}: {msg}")
            c.notes.append(f"{_rel(f, c.root)}: {msg}")
            c.usage_problem = True
            name = f.stem if f.stem not in c.scenes else f"{f.stem} ({f})"
            c.scenes[name] = {"path": _rel(f, c.root)}
            c.results += [error_result(Task(str(f), name, m), msg) for m in c.sims]
            c.planned += [(name, m) for m in c.sims]


def _plan_scene(c: _CheckRun, f: Path) -> None:
    """One scene file's checks (raises when the scene does not load)."""
    from . import Scene, SceneError
    from .results import SOLVER_ONLY

    sc = Scene(str(f))
    name = sc.name
    if name in c.scenes:
        raise ValueError(f"scene name {name!r} already used by {c.scenes[name]['path']}")
    c.scenes[name] = {"path": _rel(f, c.root), "description": sc.description, "purpose": sc.purpose}
    # A model no simulator document describes is checked solver-only, never skipped.
    targets = c.sims
    if sc.kind == "lagrangian":
        targets = [SOLVER_ONLY]
        c.scenes[name]["solver_only"] = "a lagrangian model: no MJCF/URDF element describes it"
    c.planned += [(name, m) for m in targets]
    try:
        sc.check_initial()
    except SceneError as e:
        # the solver refuses the scene: the located message of `progmo solve`, exit 2
        _say(str(e))
        c.notes.append(f"{_rel(f, c.root)}: the solver refuses the scene: {last_line(e)}")
        c.usage_problem = True
        c.results += [error_result(Task(str(f), name, m), f"the solver refuses the scene: {e}")
                      for m in targets]
        return
    c.tasks += [Task(str(f), name, m) for m in targets]


def _run_checks(c: _CheckRun, run: rp.Run, options: CheckOptions, jobs: int, columns: list[str],
                t_start: float) -> dict[str, Path] | None:
    """Run the planned checks (each result compared with its baseline and saved as it comes), then
    write what was done, even when interrupted; the report's paths (None when writing it failed)."""
    order = {(t.scene, t.simulator): i for i, t in enumerate(c.tasks)}
    n_total = len(c.tasks)
    old_term = signal.getsignal(signal.SIGTERM)
    if _main_thread():
        signal.signal(signal.SIGTERM, _raise_interrupt)
    _say(f"progmo check: {len(c.scenes)} scene(s), {n_total} check(s) ({', '.join(columns)}), {jobs} job(s)")
    try:
        for task, r in executors.run(c.tasks, options, executor=c.ns.executor, jobs=jobs, address=c.ns.address):
            _take_result(c, run, task, r, n_total)
    except executors.ExecutorError as e:
        c.usage_problem = True
        c.notes.insert(0, f"executor {c.ns.executor}: {e}; {n_total - c.done} check(s) did not run")
        _say(f"progmo check: error: {e}")
    except KeyboardInterrupt:
        c.interrupted = True
        c.notes.insert(0, f"INTERRUPTED after {c.done} of {n_total} checks; the others did not run")
        _say(f"progmo check: interrupted after {c.done} of {n_total} checks; writing what was done")
    finally:
        if _main_thread():
            signal.signal(signal.SIGTERM, old_term)
        paths = _write_run(c, run, order, t_start)
    return paths


def _take_result(c: _CheckRun, run: rp.Run, task: Task, r: CheckResult, n_total: int) -> None:
    """One finished check: named by its task, compared with its baseline, saved, its progress line."""
    c.done += 1
    if (r.scene, r.simulator) != (task.scene, task.simulator):
        r.notes.append(f"run_check named this result {r.scene} / {r.simulator}")
        r.scene, r.simulator = task.scene, task.simulator
    c.results.append(r)
    try:
        baseline = bl.load(c.base_dir, r.scene, r.simulator)
        run.comparisons[(r.scene, r.simulator)] = rp.comparisons_as_dicts(bl.compare(r, baseline))
        for d in bl.version_differences(baseline, run.provenance, r.simulator):
            c.other_versions.setdefault(d, []).append(f"{r.scene}/{r.simulator}")
    except ValueError as e:
        c.notes.append(str(e))
        c.usage_problem = True
    _save_atomic(c.results, c.out / "results.json", c.encoded)  # taken results stay as they are
    _say(_progress(c.done, n_total, r, run))


def _write_run(c: _CheckRun, run: rp.Run, order: dict[tuple[str, str], int], t_start: float) -> dict[str, Path] | None:
    """What was done, written: results.json in the planned order, the accepted baselines (--accept),
    the history record (--history) and the report; the report's paths (None when writing it failed)."""
    ns, prov = c.ns, run.provenance
    for d, pairs in c.other_versions.items():
        c.notes.append(f"baselines accepted with other versions: {d} for {len(pairs)} check(s) "
                       f"({', '.join(pairs[:6])}{' ...' if len(pairs) > 6 else ''}); "
                       "their comparison may reflect the version change")
    c.results.sort(key=lambda r: order.get((r.scene, r.simulator), -1))
    _save_atomic(c.results, c.out / "results.json")
    if ns.accept:
        _accept(run, c.base_dir, prov)
    prov["wall_seconds"] = round(time.perf_counter() - t_start, 1)
    if ns.history:
        try:
            _say(f"progmo check: history record {hist.save(run, ns.history)}")
            run.history, problems = hist.load(ns.history)
            c.notes.extend(problems)
        except OSError as e:
            c.notes.append(f"history: cannot write or read {ns.history}: {e}")
            _say(f"progmo check: error: history: {e}")
    try:
        return rp.write(run, c.out)
    except Exception as e:  # noqa: BLE001 - keep results.json; say what broke
        _say(f"progmo check: error: writing the report failed: {last_line(e)}")
        return None


def _check_outcome(c: _CheckRun, run: rp.Run, paths: dict[str, Path] | None) -> int:
    """The closing lines (coverage, the report's paths, --json) and the exit code."""
    ns, out, results = c.ns, c.out, c.results
    report_ok = paths is not None
    human = sys.stderr if ns.json else sys.stdout
    print(f"progmo check: {run.coverage()}", file=human)
    if paths is not None:
        print(f"report: {paths['html']}  (summary: {paths['md']}, {paths['csv']}; results: {out / 'results.json'})",
              file=human)
    if ns.json:
        print(json.dumps({
            "coverage": run.coverage(), "ok": run.ok(), "interrupted": c.interrupted,
            "report": str(paths["html"]) if paths is not None else None, "results_file": str(out / "results.json"),
            "notes": c.notes,
            "results": [{**{k: v for k, v in r.to_json().items() if k != "series"},
                         "verdict": run.verdict(r)} for r in results],
        }, indent=1))
    if c.interrupted:
        return EXIT_INTERRUPTED
    if c.usage_problem:
        return EXIT_USAGE
    return EXIT_OK if run.ok() and report_ok else EXIT_FAIL


def _accept(run: rp.Run, base_dir: Path, prov: dict) -> None:
    """Write baselines of every passing result; print what changed."""
    keep = {k: prov[k] for k in ("date", "git_revision", "progmo", "mujoco", "pinocchio", "drake", "numpy", "python",
                                 "platform")}
    for r in run.results:
        if r.status != "pass":
            if r.status in ("fail", "error"):
                print(f"accept: {r.scene} / {r.simulator}: {r.status}, baseline not updated")
            continue
        accepted = bl.accept(base_dir, r, keep)
        if accepted is None:  # pragma: no cover - accept() writes every pass
            continue
        path, changes = accepted
        run.accepted.append((r.scene, r.simulator))
        print(f"accept: {r.scene} / {r.simulator} -> {path}: " + ("; ".join(changes) if changes else "unchanged"))
    if run.accepted:
        run.notes.append(f"--accept: baselines written for {len(run.accepted)} passing check(s)")


def _progress(i: int, n: int, r: CheckResult, run: rp.Run) -> str:
    v = run.verdict(r)
    line = f"[{i}/{n}] {r.scene} / {r.simulator}: {rp.label(v)} ({r.wall_seconds:.1f} s)"
    why = r.reason or "; ".join(b.text(rp.fmt) for b in r.breaches)
    if v == "regression":
        why = "; ".join(f"{c['metric']} {rp.fmt(c['value'])} > {rp.fmt(c['threshold'])}" for c in run.regressed(r))
    if why and v != "pass":
        line += f": {why[:200]}"
    if r.span and r.span[0] < r.span[1]:
        line += f" [checked {r.span_text()}]"
    if r.warnings:
        line += f" [{len(r.warnings)} solver warning(s)]"
    if r.supplied:
        line += f" [reactions of {', '.join(r.supplied)} supplied by progmo]"
    return line


def _rel(p: Path, root: Path) -> str:
    try:
        return str(Path(p).resolve().relative_to(root.resolve()))
    except ValueError:
        return str(p)


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


def _raise_interrupt(signum, frame):  # noqa: ARG001
    raise KeyboardInterrupt


# --- debug, report -------------------------------------------------------------------------------
def cmd_debug(args: list[str]) -> int:
    if importlib.util.find_spec("progmo.debug") is None:
        _say("progmo debug: not available in this build (progmo.debug is missing)")
        return EXIT_USAGE
    debug = importlib.import_module("progmo.debug")  # via sys.modules (tests substitute it)
    rc = debug.main(args)
    return int(rc or 0)


def cmd_report(ns: argparse.Namespace) -> int:
    from .results import load

    d = Path(ns.dir)
    try:
        results = load(str(d / "results.json"))
        meta = json.loads((d / "run.json").read_text()) if (d / "run.json").is_file() else {}
    except (OSError, ValueError, TypeError) as e:
        _say(f"progmo report: error: {last_line(e)}")
        return EXIT_USAGE
    run = rp.Run.from_json(meta, results)
    if not run.simulators:
        run.simulators = list(dict.fromkeys(r.simulator for r in results))
    paths = rp.write(run, d)
    print(f"report: {paths['html']}")
    return EXIT_OK if run.ok() else EXIT_FAIL


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "debug":  # everything after `debug` belongs to the debug command
        return cmd_debug(argv[1:])
    ns = parser().parse_args(argv)  # exits 2 on bad usage
    if ns.command == "check":
        return cmd_check(ns, argv[1:])
    if ns.command == "report":
        return cmd_report(ns)
    return EXIT_USAGE  # pragma: no cover


if __name__ == "__main__":
    from ._stdio import run

    sub = sys.argv[1] if len(sys.argv) > 1 and sys.argv[1] in ("check", "debug", "report") else ""
    sys.exit(run(main, f"progmo {sub}".strip()))
