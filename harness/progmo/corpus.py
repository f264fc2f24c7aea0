"""``progmo corpus``: import every robot file of public collections and judge the dynamics of each
import against MuJoCo's and Pinocchio's own reading of the same file (issue 30, item 3).

Collections: example-robot-data's URDFs (``robots/**/*.urdf``), pybullet_data's URDFs (its 1000
generated objects, ``random_urdfs/``, a collection of their own), gymnasium's MuJoCo environments
(``gymnasium/envs/mujoco/assets/*.xml``), dm_control's suite (``dm_control/suite/*.xml``),
robosuite's robots (``robosuite/models/assets/robots/*/robot.xml``) and MuJoCo Menagerie (each robot
folder's ``scene.xml`` and the model files it includes), found in ``--data
DIR`` (unzipped wheels: ``DIR/<package>/...``) or the installed packages. A collection not found is
listed as not installed with the command that provides it.

Each file is imported through a minimal scene (``[model] kind, file``; a URDF twice: ``root_joint =
"fixed"`` and ``"free"``, unless its root link is ``world``), recording success or the error's
kind, location and first line. Every import is then compared with each simulator's reading
of the file (``simulators.robot_file``, through the check's back-ends: joints mapped by name,
contact off, the file's actuators inert, every unmodelled kind the file holds declared ignored so
limits, friction loss, equalities, tendons and fluid forces are off): A(q) and G + Q at a few
random states (q0 +- 0.5, |v| <= 1), relative to max|A| and max(max|G + Q|, max|A| x 1 m/s^2). Free bases (a URDF's free
root, an MJCF ``<freejoint>``) are compared too: the back-ends map each simulator's quaternion
order and angular-velocity frame onto progmo's coordinates, as the check does for the catalog's
floating-base scenes; the table counts them.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import re
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
import zlib
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from . import cliutil

#: parity within this (relative) counts as agreement
PARITY_TOL = 1e-12
#: random states of each parity comparison (default of --states)
STATES = 3
SIMULATORS = ("mujoco", "pinocchio")
FREE_BASE = "free base: compared through the back-ends' coordinate maps (quaternion order, angular-velocity frame)"


@dataclass(frozen=True)
class Collection:
    name: str
    kind: str  # "urdf" or "mjcf"
    package: str  # the import name of the installed package
    folder: str  # the package's folder inside the collection's root
    pip: str  # the command that provides it
    pattern: str = ""  # the files inside ``folder`` (default: ``**/*.urdf`` or ``*.xml``)
    exclude: str = ""  # a sub-folder of ``folder`` counted as its own collection


COLLECTIONS = (
    Collection("example-robot-data", "urdf", "example_robot_data", "example-robot-data/robots",
               "pip install example-robot-data"),
    Collection("gymnasium", "mjcf", "gymnasium", "gymnasium/envs/mujoco/assets", "pip install 'gymnasium[mujoco]'"),
    Collection("dm_control", "mjcf", "dm_control", "dm_control/suite", "pip install dm-control"),
    Collection("pybullet_data", "urdf", "pybullet_data", "pybullet_data", "pip install pybullet",
               exclude="random_urdfs"),
    Collection("pybullet_data/random_urdfs", "urdf", "pybullet_data", "pybullet_data/random_urdfs",
               "pip install pybullet"),
    Collection("robosuite", "mjcf", "robosuite", "robosuite/models/assets/robots", "pip install robosuite",
               pattern="*/robot.xml"),
    Collection("mujoco_menagerie", "mjcf", "mujoco_menagerie", "",
               "pip install mujoco-menagerie && mujoco-menagerie prefetch (or git clone "
               "https://github.com/google-deepmind/mujoco_menagerie and pass --data)"),
)
NAMES = [c.name for c in COLLECTIONS]


# --- finding the files -----------------------------------------------------------------------------
def _package_dir(package: str) -> Path | None:
    """The folder of an installed package, without importing it."""
    try:
        spec = importlib.util.find_spec(package)
    except (ImportError, ValueError):
        return None
    locs = list(spec.submodule_search_locations or []) if spec else []
    return Path(locs[0]) if locs else None


def _candidates(c: Collection, data: Path | None, installed: bool) -> list[Path]:
    """Folders that may hold the collection's ``folder``: under --data (``DIR/<name>``, an unzipped
    wheel, or DIR itself), then the installed package."""
    out: list[Path] = []
    if data is not None:
        for name in {c.name, c.name.replace("_", "-"), c.package}:
            out += [data / name, data / name / "cmeel.prefix" / "share"]
        out.append(data)
    if installed:
        if c.name == "example-robot-data":
            from . import data as pdata

            out += [Path(d) for d in pdata.robot_path()]
        else:
            pkg = _package_dir(c.package)
            if pkg is not None:
                out.append(pkg.parent)
    return out


def _menagerie_roots(data: Path | None, installed: bool) -> list[Path]:
    roots = [data / n for n in ("mujoco_menagerie", "mujoco-menagerie")] if data is not None else []
    if installed:
        if os.environ.get("MENAGERIE_ROOT"):
            roots.append(Path(os.environ["MENAGERIE_ROOT"]))
        cache = os.environ.get("MENAGERIE_CACHE_DIR") or Path(
            os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "mujoco_menagerie"
        roots.append(Path(cache))
    return [r for r in roots if r.is_dir()]


def _menagerie_files(roots: list[Path]) -> list[Path]:
    """Every robot folder's scene.xml and the model files it includes (the robot alone)."""
    files: set[Path] = set()
    for root in roots:
        for scene in root.rglob("scene.xml"):
            files.add(scene)
            try:
                inc = [e.get("file", "") for e in ET.parse(scene).getroot().iter("include")]
            except ET.ParseError:
                continue
            files.update(scene.parent / f for f in inc if f and (scene.parent / f).is_file())
    return sorted(files)


def find(c: Collection, data: Path | None, installed: bool = True) -> tuple[Path | None, list[Path], str]:
    """(root, files, note): root None when the collection is not found (the note says how to get
    it)."""
    if c.name == "mujoco_menagerie":
        roots = _menagerie_roots(data, installed)
        files = _menagerie_files(roots)
        if files:
            return roots[0], files, ""
        registry = any((r / "mujoco_menagerie" / "registry.json").is_file() for r in roots + (
            [data / "mujoco-menagerie"] if data else [])) or (installed and _package_dir(c.package) is not None)
        why = "registry only, no model downloaded" if registry else "not installed"
        return None, [], f"{why}: {c.pip}"
    for base in _candidates(c, data, installed):
        folder = base / c.folder
        if folder.is_dir():
            pattern = c.pattern or ("**/*.urdf" if c.kind == "urdf" else "*.xml")
            files = sorted(f for f in folder.glob(pattern)
                           if not c.exclude or f.relative_to(folder).parts[0] != c.exclude)
            if files:
                return folder, files, ""
    return None, [], f"not installed: {c.pip}"


def sample(files: list[Path], n: int | None) -> list[Path]:
    """A deterministic sample of at most n files spread over the sorted list (None: all)."""
    if n is None or n >= len(files):
        return files
    idx = np.unique(np.linspace(0, len(files) - 1, max(n, 1)).round().astype(int))
    return [files[i] for i in idx]


# --- import --------------------------------------------------------------------------------------
def _scene_text(kind: str, path: Path, root_joint: str | None, ignore: list[str]) -> str:
    lines = ['name = "corpus"', "[model]", f'kind = "{kind}"', f"file = {json.dumps(str(path))}"]
    if root_joint is not None:
        lines.append(f'root_joint = "{root_joint}"')
    if ignore:
        lines.append("ignore = { " + ", ".join(f'{k} = "corpus: dynamics parity only"' for k in ignore) + " }")
    return "\n".join(lines + ["[initial]", "[time]", "t1 = 1.0", ""])


def error_record(e: BaseException) -> dict[str, Any]:
    """The error's kind, location (file:line), first line and a reason that groups alike errors."""
    msg = str(getattr(e, "message", None) or e).splitlines()
    first = msg[0] if msg else type(e).__name__
    f, line = getattr(e, "file", None), getattr(e, "line", None)
    # the generated scene (deleted after the run) stands for the model as a whole
    loc = "" if not f else "the model" if Path(f).name == "scene.toml" else f"{Path(f).name}:{line}"
    field = re.sub(r"\[[^\]]*\]", "[]", str(getattr(e, "field", None) or ""))
    gist = re.sub(r"`[^`]*`", "`…`", first)
    gist = re.sub(r"-?\d+(\.\d+)?(e-?\d+)?", "#", gist)
    reason = (f"{field}: " if field else "") + gist
    return {"kind": str(getattr(e, "kind", type(e).__name__)), "location": loc, "message": first,
            "reason": reason[:110]}


def load(kind: str, path: Path, root_joint: str | None, folder: Path) -> Any:
    """progmo's import of the file through a minimal scene in ``folder``: loaded once, then again
    with every unmodelled kind the file holds declared ignored (the simulators switch those off)."""
    from ._core import Scene

    scene_path = folder / "scene.toml"
    allow = os.environ.get("PROGMO_ALLOW_ROOTS")
    os.environ["PROGMO_ALLOW_ROOTS"] = os.pathsep.join([str(path.parent)] + ([allow] if allow else []))
    try:
        scene_path.write_text(_scene_text(kind, path, root_joint, []))
        scene = Scene(str(scene_path))
        kinds = sorted({str(u["kind"]) for u in scene.unmodelled})
        if kinds:
            scene_path.write_text(_scene_text(kind, path, root_joint, kinds))
            scene = Scene(str(scene_path))
        return scene
    finally:
        if allow is None:
            os.environ.pop("PROGMO_ALLOW_ROOTS", None)
        else:
            os.environ["PROGMO_ALLOW_ROOTS"] = allow


def _urdf_root_is_world(path: Path) -> bool:
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError:
        return False
    kids = [j.find("child") for j in root.iter("joint")]
    children = {k.get("link") for k in kids if k is not None}
    roots = [lk.get("name") for lk in root.findall("link") if lk.get("name") not in children]
    return roots == ["world"]


# --- parity --------------------------------------------------------------------------------------
def _backend(scene: Any, simulator: str, simulator_file: Path | None) -> Any:
    """The check's back-end of ``simulator`` on the file (``simulators.robot_file``)."""
    from .simulators.robot_file import robot_file

    rf = robot_file(scene)
    assert rf is not None
    if simulator_file is not None:  # negative control: the simulator reads another file
        rf.path = Path(simulator_file)
    if simulator == "mujoco":
        from .simulators.mujoco_sim import MujocoBackend as cls
        doc, report = scene.export("mjcf", supply_reactions=True)
    else:
        from .simulators.pinocchio_sim import PinocchioBackend as cls  # type: ignore[assignment]
        doc, report = scene.export("urdf", supply_reactions=True)
    be = cls(doc, report, scene, robot=rf)
    if simulator == "mujoco" and "fluid" in rf.ignored:  # passive fluid forces: off as declared
        be.m.opt.density = be.m.opt.viscosity = 0.0
        be.m.opt.wind[:] = 0.0
    return be


def states(scene: Any, n: int, seed: int, quats: list[list[int]]) -> list[tuple[np.ndarray, np.ndarray]]:
    """n random states: q0 +- 0.5 (quaternions normalised), v in [-1, 1]."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        q = np.array(scene.q0) + rng.uniform(-0.5, 0.5, len(scene.q0))
        for g in quats:
            q[g] /= np.linalg.norm(q[g])
        out.append((q, rng.uniform(-1.0, 1.0, len(scene.v_names))))
    return out


def parity(scene: Any, simulator: str, n: int, seed: int, simulator_file: Path | None = None) -> dict[str, Any]:
    """Relative max error of A and of G + Q against the simulator's reading of the file."""
    from .simulators import Unsupported

    try:
        be = _backend(scene, simulator, simulator_file)
    except Unsupported as e:
        return {"status": "not_compared", "reason": str(e).splitlines()[0]}
    except Exception as e:  # the simulator's reader refuses the file
        return {"status": "error", "reason": f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"}
    if not scene.v_names:
        return {"status": "not_compared", "reason": "no degree of freedom"}
    try:
        return _compare(scene, be, n, seed)
    except Exception as e:
        return {"status": "error", "reason": f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"}


def _compare(scene: Any, be: Any, n: int, seed: int) -> dict[str, Any]:
    dM = dF = sM = sF = 0.0
    for q, v in states(scene, n, seed, be.cm.quats):
        dyn = scene.dynamics(scene.t0, q, v)
        A = np.asarray(dyn["mass"])
        rhs = np.asarray(dyn["velocity_terms"]) + np.asarray(dyn["applied_forces"])
        Ms, rs = be.model_terms(scene.t0, q, v)
        dM, dF = max(dM, float(np.abs(Ms - A).max())), max(dF, float(np.abs(rs - rhs).max()))
        sM, sF = max(sM, float(np.abs(A).max())), max(sF, float(np.abs(rhs).max()))
    # G + Q relative to its own size or, where that is smaller, to the force of a unit acceleration
    # (max|A| x 1): a file whose gravity is along every joint axis (a wheeled base) has G + Q of
    # round-off size, and round-off relative to round-off is no measure of agreement
    mass, bias = dM / max(sM, 1e-300), dF / max(sF, sM, 1e-300)
    return {"status": "ok", "mass": mass, "bias": bias, "worst": max(mass, bias), "states": n}


def mujoco_refusal(kind: str, path: Path, root_joint: str | None = None) -> str | None:
    """MuJoCo's own compiler on the file (a URDF through the faithful copy the check reads:
    ``robot_file.urdf_for_mujoco``): None when it compiles, else its error's first line. Asked of
    every refused import, so the table tells a defect of the file that MuJoCo refuses too (an
    inertia with a negative eigenvalue, moments against the triangle inequality, a massless moving
    body) from a refusal of progmo's alone. ``root_joint = "free"``: with the free root the import
    adds (as the check adds it: ``robot_file.mujoco_model``)."""
    import mujoco

    from .simulators.robot_file import ROOT_JOINT, urdf_for_mujoco

    try:
        if kind == "urdf":
            spec = mujoco.MjSpec.from_string(urdf_for_mujoco(path))
            if root_joint == "free" and spec.worldbody.first_body() is not None:
                spec.worldbody.first_body().add_freejoint(name=ROOT_JOINT)
            spec.compile()
        else:
            mujoco.MjModel.from_xml_path(str(path))
    except Exception as e:
        text = str(e).strip().splitlines()
        return f"{type(e).__name__}: {text[0] if text else ''}"
    return None


def check_file(kind: str, path: Path, folder: Path, *, n_states: int = STATES,
               simulator_file: Path | None = None, simulators: tuple[str, ...] = SIMULATORS) -> list[dict[str, Any]]:
    """One record per import of the file (a URDF: fixed and free root; an MJCF: as written)."""
    variants: list[str | None] = [None]
    if kind == "urdf":
        variants = ["fixed", None if _urdf_root_is_world(path) else "free"]
        variants = [v for v in variants if v]
    out = []
    seed = zlib.crc32(path.name.encode())
    for rj in variants:
        rec: dict[str, Any] = {"file": str(path), "kind": kind, "root_joint": rj or "file",
                               "imported": False, "error": None, "parity": None}
        try:
            scene = load(kind, path, rj, folder)
        except Exception as e:  # SceneError (located), or anything else the import raises
            rec["error"] = error_record(e)
            rec["mujoco_refuses"] = mujoco_refusal(kind, path, rj)
            out.append(rec)
            continue
        rec.update(imported=True, nq=len(scene.q_names), nv=len(scene.v_names),
                   ignored=sorted({str(u["kind"]) for u in scene.unmodelled}))
        if rj == "free" or any(n.endswith(".vx") for n in scene.v_names):
            rec["note"] = FREE_BASE
        rec["parity"] = {s: parity(scene, s, n_states, seed, simulator_file) for s in simulators}
        out.append(rec)
    return out


# --- tables --------------------------------------------------------------------------------------
def summarize(name: str, files: int, records: list[dict[str, Any]], note: str = "") -> dict[str, Any]:
    """A collection's row: counts, rates, parity and the top refusal reasons."""
    if note:
        return {"collection": name, "status": note, "files": files}
    imported = [r for r in records if r["imported"]]
    checked = [r for r in imported if r["parity"]]
    # refusals MuJoCo's compiler shares (the file's defect); the rest are progmo's alone
    shared = [r for r in records if not r["imported"] and r.get("mujoco_refuses")]
    row: dict[str, Any] = {"collection": name, "status": "ok", "files": files, "imports": len(records),
                           "imported": len(imported),
                           "import_rate": len(imported) / len(records) if records else 0.0,
                           "refused_by_mujoco_too": len(shared),
                           "import_rate_mujoco_compiles": (len(imported) / (len(records) - len(shared))
                                                           if len(records) > len(shared) else 0.0),
                           "shared_refusals": Counter(r["mujoco_refuses"][:110] for r in shared).most_common(5),
                           "free_base": sum(1 for r in imported if r.get("note") == FREE_BASE),
                           "parity_checked": len(checked)}
    worst = 0.0
    for s in SIMULATORS:
        ok = [r["parity"][s] for r in checked if r["parity"].get(s, {}).get("status") == "ok"]
        row[f"{s}_compared"] = len(ok)
        row[f"{s}_within"] = sum(1 for p in ok if p["worst"] <= PARITY_TOL)
        worst = max([worst] + [p["worst"] for p in ok])
        row[f"{s}_not_compared"] = Counter(
            r["parity"][s]["reason"][:110] for r in checked if r["parity"].get(s, {}).get("status") != "ok"
        ).most_common(5)
    row["worst_parity"] = worst if any(row[f"{s}_compared"] for s in SIMULATORS) else None
    row["refusals"] = Counter(r["error"]["reason"] for r in records if r["error"]).most_common(5)
    return row


def table(rows: list[dict[str, Any]]) -> str:
    """The markdown table of the rows, then each collection's refusal reasons."""
    head = ("| collection | files | imports | imported | import rate | refused, MuJoCo too | import rate "
            "where MuJoCo compiles | parity checked | within 1e-12 (MuJoCo; Pinocchio) | worst parity |\n"
            "|---|---|---|---|---|---|---|---|---|---|")
    lines = [head]
    for r in rows:
        if r["status"] != "ok":
            lines.append(f"| {r['collection']} | {r['status']} | | | | | | | | |")
            continue
        worst = "—" if r["worst_parity"] is None else f"{r['worst_parity']:.1e}"
        lines.append(
            f"| {r['collection']} | {r['files']} | {r['imports']} | {r['imported']} | {100 * r['import_rate']:.0f}% "
            f"| {r['refused_by_mujoco_too']} | {100 * r['import_rate_mujoco_compiles']:.0f}% "
            f"| {r['parity_checked']} ({r['free_base']} free base) "
            f"| {r['mujoco_within']}/{r['mujoco_compared']}; {r['pinocchio_within']}/{r['pinocchio_compared']} "
            f"| {worst} |")
    for r in rows:
        if r["status"] == "ok" and r["refusals"]:
            lines.append(f"\n{r['collection']}: top refusal reasons")
            lines += [f"- {n} x {reason}" for reason, n in r["refusals"]]
        if r["status"] == "ok" and r["shared_refusals"]:
            lines.append(f"\n{r['collection']}: refused imports MuJoCo's compiler refuses too")
            lines += [f"- {n} x {reason}" for reason, n in r["shared_refusals"]]
        for s in SIMULATORS:
            if r["status"] == "ok" and r[f"{s}_not_compared"]:
                lines.append(f"\n{r['collection']}: not compared in {s}")
                lines += [f"- {n} x {reason}" for reason, n in r[f"{s}_not_compared"]]
    return "\n".join(lines) + "\n"


# --- command -------------------------------------------------------------------------------------
def parser() -> argparse.ArgumentParser:
    p = cliutil.parser(
        "progmo corpus",
        "Import every robot file of public collections (example-robot-data, pybullet_data, gymnasium, "
        "dm_control, robosuite, MuJoCo Menagerie) and compare each fixed-base import's A(q) and G + Q with MuJoCo's and "
        "Pinocchio's own reading of the file (also: python -m progmo.corpus).",
        "Outputs in --out: corpus.json (every file's result) and corpus.md (the table). A collection "
        "not found is listed as not installed with the command that provides it. Exit codes: 0 done, "
        "2 bad usage.")
    p.add_argument("--data", metavar="DIR", default=None,
                   help="folder of unzipped collections (DIR/<package>/...), searched before the installed packages")
    p.add_argument("--data-only", action="store_true", help="search --data only, not the installed packages")
    p.add_argument("-c", "--collection", action="append", choices=NAMES, metavar="NAME",
                   help=f"collection to run, repeatable: {', '.join(NAMES)} (default: all)")
    p.add_argument("--sample", type=int, default=None, metavar="N",
                   help="at most N files per collection, a deterministic sample spread over the sorted list")
    p.add_argument("--states", type=int, default=STATES, metavar="N",
                   help=f"random states of each parity comparison (default: {STATES})")
    p.add_argument("-o", "--out", default="out/corpus", metavar="DIR", help="output folder (default: out/corpus)")
    return p


def run(collections: list[Collection], data: Path | None, installed: bool, n_sample: int | None,
        n_states: int, progress: Callable[[str], None]) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(rows, records) of the collections."""
    rows, records = [], []
    with tempfile.TemporaryDirectory(prefix="progmo-corpus-") as tmp:
        for c in collections:
            root, files, note = find(c, data, installed)
            if root is None:
                progress(f"{c.name}: {note}")
                rows.append(summarize(c.name, 0, [], note))
                continue
            chosen = sample(files, n_sample)
            progress(f"{c.name}: {len(chosen)} of {len(files)} files in {root}")
            recs: list[dict[str, Any]] = []
            for i, f in enumerate(chosen, 1):
                t0 = time.perf_counter()
                try:
                    got = check_file(c.kind, f, Path(tmp), n_states=n_states)
                except Exception as e:  # a bug of the harness: recorded, the run goes on
                    got = [{"file": str(f), "kind": c.kind, "root_joint": "?", "imported": False,
                            "error": {**error_record(e), "kind": "internal"}, "parity": None}]
                for r in got:
                    r.update(collection=c.name, relpath=str(f.relative_to(root)))
                recs += got
                progress(f"[{c.name} {i}/{len(chosen)}] {f.relative_to(root)}: "
                         + "; ".join(_gist(r) for r in got) + f" ({time.perf_counter() - t0:.1f} s)")
            rows.append(summarize(c.name, len(chosen), recs))
            records += recs
    return rows, records


def _gist(r: dict[str, Any]) -> str:
    if not r["imported"]:
        return f"{r['root_joint']}: refused ({r['error']['location']}: {r['error']['message'][:100]})"
    if not r["parity"]:
        return f"{r['root_joint']}: imported (import only)"
    return f"{r['root_joint']}: imported, parity " + ", ".join(
        f"{s} {p['worst']:.1e}" if p["status"] == "ok" else f"{s} {p['status']}" for s, p in r["parity"].items())


def main(argv: list[str] | None = None) -> int:
    a = parser().parse_args(argv)
    if a.sample is not None and a.sample < 1 or a.states < 1:
        print("progmo corpus: error: --sample and --states must be at least 1", file=sys.stderr)
        return 2
    data = Path(a.data) if a.data else None
    if data is not None and not data.is_dir():
        print(f"progmo corpus: error: --data {data}: not a folder", file=sys.stderr)
        return 2
    chosen = [c for c in COLLECTIONS if not a.collection or c.name in a.collection]
    rows, records = run(chosen, data, not a.data_only, a.sample, a.states,
                        lambda s: print(s, file=sys.stderr, flush=True))
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    md = table(rows)
    (out / "corpus.json").write_text(json.dumps({"tolerance": PARITY_TOL, "states": a.states, "sample": a.sample,
                                                 "collections": rows, "files": records}, indent=1))
    (out / "corpus.md").write_text("# progmo corpus\n\n" + md)
    print(md, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
