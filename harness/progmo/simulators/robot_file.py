"""The user's robot file in the simulators (issue 27): a scene whose model is a robot description
file (``[model] kind = "urdf"`` or ``"mjcf"``) is checked against each simulator's **own reading of
that file**, not against progmo's export of its import. Only the scene's own additions are applied
on top: locked joints, gravity, a free root joint, the harness forces of the export report (point,
coordinate and attractor forces) and u.

* MuJoCo builds its model with ``MjSpec`` from the file: MJCF natively, URDF through MuJoCo's own
  URDF compiler. A URDF is read from a faithful copy: ``<visual>`` and ``<collision>`` removed (a
  URDF's geometry carries no inertia; its ``package://`` mesh paths are not readable by MuJoCo) and
  a ``<mujoco><compiler>`` that keeps every link a body and the stated inertials (no inertia from
  geometry, no balancing or bounds). The spec is then made ideal rigid-body dynamics where the scene
  says so: RK4, contact and autoreset off, limits / frictionloss / equalities off only where the
  scene declares them ignored, the file's actuators' gains and biases zeroed (u enters as
  ``qfrc_applied``). Passive forces of the file (damping, springs with springref, gravcomp) and
  armature stay: progmo's model must have them.
* Pinocchio reads the file with ``buildModelFromUrdf`` / ``buildModelFromMJCF`` (its own
  ``armature`` enters ``crba``, ``rnea`` and ``aba``; its ``damping`` does not: the harness applies
  ``-damping * v``). Its MJCF reader has no joint springs and no gravcomp: those the harness applies
  from MuJoCo's compilation of the same file (``jnt_stiffness``, ``qpos_spring``,
  ``body_gravcomp``), said in the notes. Locked joints: ``buildReducedModel`` at q = 0. A URDF
  ``continuous`` joint is an unbounded revolute joint there, q = (cos θ, sin θ) with one velocity:
  the check's ``CoordMap`` maps progmo's angle θ to that pair and back (atan2, kept within π of the
  step before so θ stays continuous over whole turns).

Coordinates are matched by joint name (:func:`name_report`): the export report's q/v entries keep
their names and conversions, their simulator addresses come from the simulator's model of the file.
"""

from __future__ import annotations

import copy
import os
import tomllib
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import Unsupported

#: MuJoCo's URDF compiler settings of the faithful copy (module doc)
URDF_COMPILER = dict(angle="radian", discardvisual="true", fusestatic="false", inertiafromgeom="false",
                     balanceinertia="false", boundmass="0", boundinertia="0")


@dataclass
class RobotFile:
    """The robot file of a scene and what the scene adds to it."""

    path: Path
    fmt: str  # "urdf" or "mjcf"
    locked: list[str] = field(default_factory=list)
    root_joint: str = "fixed"
    #: unmodelled elements the scene declares ignored: kinds ("frictionloss", "limit", ...)
    ignored: set[str] = field(default_factory=set)
    #: the URDF's <mimic> couplings progmo models as system rows (the core's ``mimics``: joint,
    #: leader, multiplier, offset); their reactions are supplied with u in the check
    mimics: list[dict] = field(default_factory=list)


def robot_file(scene: Any) -> RobotFile | None:
    """The scene's robot file (``Scene.robot_file`` when the core gives it, else the scene's
    ``[model]`` table with ``package://`` resolved as progmo.data does); None for other models."""
    with open(scene.path, "rb") as f:
        model = tomllib.load(f).get("model", {})
    kind = model.get("kind")
    if kind not in ("urdf", "mjcf"):
        return None
    given = getattr(scene, "robot_file", None)  # the core's {kind, path, locked_joints}
    path = given["path"] if isinstance(given, dict) else given
    if not path:
        rel = str(model["file"])
        if rel.startswith("package://"):
            from .. import data

            rest = rel.removeprefix("package://")
            dirs = [Path(d) for d in data.robot_path()]
            dirs += [Path(d) for d in os.environ.get("PROGMO_ROBOT_PATH", "").split(os.pathsep) if d]
            path = next((str(d / rest) for d in dirs if (d / rest).is_file()), None)
            if path is None:
                raise FileNotFoundError(f"robot file {rel} not found")
        else:
            path = str(Path(scene.path).parent / rel)
    ignored = {str(u["kind"]) for u in getattr(scene, "unmodelled", []) or [] if u.get("declared")}
    mimics = list(given.get("mimics", [])) if isinstance(given, dict) else []
    return RobotFile(Path(path), kind, list(model.get("locked_joints", [])),
                     str(model.get("root_joint", "fixed")), ignored, mimics)


#: harness forces of the export report that stand for elements of the robot file itself (the file's
#: passive forces): on the user's-file route the simulator's own reading supplies them
FILE_FORCES = ("spring", "damper", "gravcomp")


def name_report(report: dict, addr: dict[str, tuple[int, int]]) -> dict:
    """The export report with simulator addresses taken from the simulator's model of the file:
    ``addr[sim_joint] = (first qpos, first dof)``; each entry keeps its offset within its joint (the
    export's component order, e.g. Pinocchio's quaternion x, y, z, w)."""
    out = copy.deepcopy(report)
    out["harness_forces"] = [hf for hf in report.get("harness_forces", []) if hf["kind"] not in FILE_FORCES]
    for key, k in (("q_map", 0), ("v_map", 1)):
        first: dict[str, int] = {}
        for c in report[key]:
            first[c["sim_joint"]] = min(first.get(c["sim_joint"], c["sim_index"]), c["sim_index"])
        for c in out[key]:
            j = c["sim_joint"]
            if j not in addr:
                raise Unsupported(f"joint {j!r} of the scene is not in the simulator's reading of the file")
            c["sim_index"] = addr[j][k] + c["sim_index"] - first[j]
    return out


# --- MuJoCo --------------------------------------------------------------------------------------
def urdf_for_mujoco(path: Path) -> str:
    """The faithful copy of a URDF that MuJoCo's URDF compiler reads (module doc)."""
    root = ET.parse(path).getroot()
    for link in root.iter("link"):
        for tag in ("visual", "collision"):
            for e in link.findall(tag):
                link.remove(e)
    for e in root.findall("mujoco"):
        root.remove(e)
    ET.SubElement(ET.SubElement(root, "mujoco"), "compiler", URDF_COMPILER)
    return ET.tostring(root, encoding="unicode")


def mujoco_model(rf: RobotFile, gravity: list[float], closures: list[dict] | None = None) -> tuple[Any, list[str]]:
    """MuJoCo's model of the file with the scene's additions (a free root, the loop closures of
    the export report as sites and equalities, set as the export sets them: MUJOCO_CLOSURES.md);
    notes say what was prepared."""
    import mujoco

    closures = closures or []
    notes = []
    if rf.fmt == "urdf":
        spec = mujoco.MjSpec.from_string(urdf_for_mujoco(rf.path))
        notes.append(f"MuJoCo reads {rf.path.name} through its URDF compiler from a faithful copy: "
                     "visual and collision geometry removed (no inertia in a URDF's geometry; mesh "
                     "paths unreadable), every link kept a body, stated inertials only")
    else:
        spec = mujoco.MjSpec.from_file(str(rf.path))
        notes.append(f"MuJoCo reads {rf.path.name} as given")
    _remove_locked(spec, rf, notes)
    _remove_mimics(spec, rf, notes)
    if rf.root_joint == "free":
        root = spec.worldbody.first_body()
        root.add_freejoint(name=ROOT_JOINT)
        notes.append(f"free root joint 'root' added to body {root.name!r}")
    if closures:
        _add_closures(spec, closures, rf)
        notes.append("loop closures added as sites and equalities: " + ", ".join(
            f"{c['name']} ({'connect' if c['kind'] == 'point' else 'weld'})" for c in closures))
        if "equality" in rf.ignored:  # the file's own, declared ignored: removed, not switched off
            for e in list(spec.equalities):
                if e.name not in {c["name"] for c in closures}:
                    spec.delete(e)
    # ideal rigid-body dynamics (shared/notes/simulators.md) except what the file says
    spec.option.gravity = np.asarray(gravity, float)
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_RK4
    off = mujoco.mjtDisableBit.mjDSBL_CONTACT | mujoco.mjtDisableBit.mjDSBL_AUTORESET
    declared = {"joint_limit": mujoco.mjtDisableBit.mjDSBL_LIMIT,
                "frictionloss": mujoco.mjtDisableBit.mjDSBL_FRICTIONLOSS,
                "equality": mujoco.mjtDisableBit.mjDSBL_EQUALITY}
    switched = [k for k in declared if k in rf.ignored and not (k == "equality" and closures)]
    for k in switched:
        off |= declared[k]
    spec.option.disableflags = int(spec.option.disableflags) | int(off)
    spec.option.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_ACTUATION)
    m = spec.compile()
    if "tendon" in rf.ignored and m.ntendon:
        m.tendon_stiffness[:] = 0.0
        m.tendon_damping[:] = 0.0
        m.tendon_frictionloss[:] = 0.0
        m.tendon_limited[:] = 0
        switched.append("tendons (stiffness, damping, friction, limits zeroed)")
    if m.nu:
        m.actuator_gainprm[:] = 0.0
        m.actuator_biasprm[:] = 0.0
        notes.append(f"the file's {m.nu} actuator(s) made inert (gains and biases zeroed): u enters as qfrc_applied")
    notes.append("MuJoCo options: RK4, contact and autoreset off"
                 + (", " + ", ".join(switched) + " off (declared ignored by the scene)" if switched else "")
                 + "; the file's armature, damping, springs and gravcomp kept")
    return m, notes


#: the name of the free root joint a scene's ``root_joint = "free"`` adds (progmo's, src/import/urdf.rs)
ROOT_JOINT = "root"

#: the export's equality settings (src/export/mjcf.rs, MUJOCO_CLOSURES.md): timeconst 4 steps
CLOSURE_TIMECONST_STEPS, CLOSURE_SOLIMP = 4.0, [0.9999, 0.9999, 0.001, 0.5, 2.0]


def _add_closures(spec: Any, closures: list[dict], rf: RobotFile) -> None:
    """Each closure's two sites on its bodies (the world: ``body`` None) and a ``connect`` (point)
    or ``weld`` equality between them; the solver set as the export sets it."""
    import mujoco

    for c in closures:
        if c["kind"] not in ("point", "weld"):
            raise Unsupported(f"the {c['kind']} closure {c['name']!r} over a robot file in MuJoCo "
                              "(connect and weld equalities only)")
        for site, body, point, quat in ((c["site_a"], c["body_a"], c["point_a"], c["quat_a"]),
                                        (c["site_b"], c["body_b"], c["point_b"], c["quat_b"])):
            b = spec.worldbody if body is None else spec.body(body)
            if b is None:
                raise Unsupported(f"closure {c['name']!r}: body {body!r} is not in MuJoCo's reading of {rf.path.name}")
            b.add_site(name=site, pos=list(map(float, point)), quat=list(map(float, quat)))
        kind = mujoco.mjtEq.mjEQ_CONNECT if c["kind"] == "point" else mujoco.mjtEq.mjEQ_WELD
        spec.add_equality(name=c["name"], type=kind, objtype=mujoco.mjtObj.mjOBJ_SITE,
                          name1=c["site_a"], name2=c["site_b"],
                          solref=[CLOSURE_TIMECONST_STEPS * spec.option.timestep, 1.0], solimp=CLOSURE_SOLIMP)
    spec.option.solver = mujoco.mjtSolver.mjSOL_NEWTON
    spec.option.iterations = 200
    spec.option.tolerance = 1e-15
    spec.option.ls_tolerance = 1e-15
    spec.option.jacobian = mujoco.mjtJacobian.mjJAC_DENSE


def _remove_mimics(spec: Any, rf: RobotFile, notes: list[str]) -> None:
    """The joint equalities MuJoCo's URDF compiler makes of the <mimic>s progmo models as system
    rows, removed: the check supplies those rows' reactions with u (``supplied``), as for Pinocchio,
    which has no coupling constraint. Each is first compared with progmo's law (MuJoCo's
    polycoef: q_joint = c0 + c1 q_leader)."""
    import mujoco

    for mm in rf.mimics:
        eq = next((e for e in spec.equalities if e.type == mujoco.mjtEq.mjEQ_JOINT
                   and e.name1 == mm["joint"] and e.name2 == mm["leader"]), None)
        if eq is None:
            raise ValueError(f"MuJoCo's reading of {rf.path.name} has no joint equality for the <mimic> of "
                             f"{mm['joint']!r} on {mm['leader']!r}")
        c = np.asarray(eq.data[:5], float)
        want = np.array([mm["offset"], mm["multiplier"], 0.0, 0.0, 0.0])
        if np.abs(c - want).max() > 1e-12 * max(1.0, float(np.abs(want).max())):
            raise ValueError(f"MuJoCo reads the <mimic> of {mm['joint']!r} as polycoef {c.tolist()}, progmo as "
                             f"offset {mm['offset']!r}, multiplier {mm['multiplier']!r}")
        spec.delete(eq)
        notes.append(f"joint equality of the <mimic> {mm['joint']} = {mm['multiplier']!r} {mm['leader']} + "
                     f"{mm['offset']!r} (equal to progmo's row) removed: its reaction is supplied with u")


def _remove_locked(spec: Any, rf: RobotFile, notes: list[str]) -> None:
    """The locked joints removed from MuJoCo's spec (welded in the file's pose), with the joint
    equalities (a URDF <mimic>) over them."""
    import mujoco

    gone = []  # equalities over a locked joint (a URDF <mimic>) lock with it
    for e in list(spec.equalities):
        if e.type == mujoco.mjtEq.mjEQ_JOINT and (e.name1 in rf.locked or e.name2 in rf.locked):
            if not (e.name1 in rf.locked and (not e.name2 or e.name2 in rf.locked)):
                raise Unsupported(f"joint equality (mimic) between {e.name1} and {e.name2}: only one of them "
                                  "is locked")
            gone.append(f"{e.name1} = f({e.name2})" if e.name2 else e.name1)
            spec.delete(e)
    if gone:
        notes.append("joint equalities (URDF mimic) between locked joints removed with them: " + ", ".join(gone))
    for j in rf.locked:
        js = spec.joint(j)
        if js is None:
            raise Unsupported(f"locked joint {j!r} is not in MuJoCo's reading of {rf.path.name}")
        spec.delete(js)
    if rf.locked:
        notes.append("locked joints removed in MuJoCo's copy (welded in the file's pose: q = 0, MJCF q = ref): "
                     + ", ".join(rf.locked))


def mujoco_addresses(m: Any) -> dict[str, tuple[int, int]]:
    import mujoco

    out = {}
    for j in range(m.njnt):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
        if not name and int(m.jnt_type[j]) == mujoco.mjtJoint.mjJNT_FREE:
            # an unnamed free joint: progmo (and Pinocchio) name it BODY_free
            name = f"{mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, int(m.jnt_bodyid[j]))}_free"
        if name:
            out[name] = (int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j]))
    return out


# --- Pinocchio -----------------------------------------------------------------------------------
@dataclass
class PinFile:
    """Pinocchio's model of the file and the passive forces the harness applies for it."""

    model: Any
    addr: dict[str, tuple[int, int]]
    #: per dof: Pinocchio's own model.damping (applied by the harness: rnea/aba ignore it)
    damping: np.ndarray
    #: (qpos index, dof index, stiffness, springref) of springs Pinocchio's reader does not read
    springs: list[tuple[int, int, float, float]]
    #: (body frame id, CoM in that frame, mass x gravcomp) Pinocchio's reader does not read
    gravcomp: list[tuple[int, np.ndarray, float]]
    notes: list[str]
    #: elements of the file Pinocchio's reader skips that progmo does not model (tendons, equalities)
    skipped: list[dict] = field(default_factory=list)
    #: (qpos index, ref) of MJCF joints with a nonzero ``ref``: Pinocchio's reader puts the file's
    #: pose at q = 0, MuJoCo (and progmo) at q = ref, so q_pin = q - ref
    q_offset: list[tuple[int, float]] = field(default_factory=list)
    #: qpos index of each unbounded revolute joint (a URDF ``continuous`` joint: (cos θ, sin θ))
    unbounded: list[int] = field(default_factory=list)
    #: (first qpos, first dof) of each planar joint (x, y, cos θ, sin θ; velocity in the moving frame)
    planar: list[tuple[int, int]] = field(default_factory=list)


#: what an ``<include>``d file may hold for Pinocchio 4.1's MJCF reader to read the model right
PIN_INCLUDE_OK = {"asset", "visual", "statistic", "extension", "custom"}


def pinocchio_misreads_includes(path: Path) -> str | None:
    """Why Pinocchio 4.1 cannot read an MJCF file's ``<include>``s, or None. Measured: an include
    inside a body is dropped without a word (its bodies and joints are missing) and an include of
    ``<default>``s fails (``unordered_map::at``); a top-level include of assets or visual settings
    reads fine. Paths are relative to the main file's folder (MuJoCo's rule)."""
    def check(file: Path, top: bool) -> str | None:
        try:
            root = ET.parse(file).getroot()
        except (OSError, ET.ParseError):
            return None  # progmo's importer and MuJoCo report an unreadable file
        for parent in root.iter():
            for inc in (c for c in parent if c.tag == "include"):
                where = "the top level" if parent is root else f"<{parent.tag}>"
                if parent is not root or not top:
                    return (f"Pinocchio 4.1's MJCF reader drops what an <include> inside {where} brings "
                            f"({file.name}: {inc.get('file')}): not checked in Pinocchio")
                name = path.parent / (inc.get("file") or "")
                try:
                    tags = {c.tag for c in ET.parse(name).getroot()}
                except (OSError, ET.ParseError):
                    return None
                if not tags <= PIN_INCLUDE_OK:
                    return (f"Pinocchio 4.1's MJCF reader cannot read the <{'>, <'.join(sorted(tags - PIN_INCLUDE_OK))}> "
                            f"of the included {inc.get('file')} ({file.name}): not checked in Pinocchio")
                nested = check(name, top=False)
                if nested:
                    return nested
        return None

    return check(path, top=True)


def pinocchio_misreads_frames(path: Path) -> str | None:
    """Why Pinocchio 4.1 cannot read an MJCF file's ``<frame>``s, or None. Measured: a body inside a
    ``<frame>`` stops its reader (``RuntimeError: No such node (body)``)."""
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError):
        return None  # progmo's importer and MuJoCo report an unreadable file
    if next(root.iter("frame"), None) is not None:
        return (f"Pinocchio 4.1's MJCF reader cannot read the <frame> elements of {path.name} "
                "(RuntimeError: No such node (body)): not checked in Pinocchio")
    return None


def pinocchio_mass_differs(model: Any, mj: Any, name: str) -> str | None:
    """Why Pinocchio's reading of an MJCF file cannot judge progmo's, or None: its moving bodies'
    total mass differs from MuJoCo's compile of the same file. Pinocchio 4.1's MJCF reader derives
    geom masses its own way and ignores ``settotalmass`` (measured with ``progmo corpus``:
    gymnasium's swimmer has mass 0 there against 106.8, dm_control's acrobot 16.4 against 2 and
    cheetah 21.2 against its settotalmass 14); MuJoCo's compile is the file's meaning."""
    moving = [b for b in range(1, mj.nbody) if int(mj.body_weldid[b]) != 0]
    mj_total = float(sum(mj.body_mass[b] for b in moving))
    pin_total = float(sum(model.inertias[j].mass for j in range(1, model.njoints)))
    if abs(pin_total - mj_total) <= 1e-9 * max(1.0, mj_total):
        return None
    return (f"Pinocchio's reading of {name} has moving mass {pin_total:.6g}, MuJoCo's compile of it "
            f"{mj_total:.6g} (Pinocchio 4.1's MJCF reader derives geom masses its own way and "
            "ignores settotalmass): not checked in Pinocchio")


def pinocchio_model(rf: RobotFile, gravity: list[float], root: dict | None) -> PinFile:
    import pinocchio as pin

    notes: list[str] = []
    if rf.fmt == "urdf":
        if root:
            model = pin.buildModelFromUrdf(str(rf.path), pin.JointModelFreeFlyer(), root["name"])
        elif rf.root_joint == "free":  # the scene's free root, named as progmo names it
            model = pin.buildModelFromUrdf(str(rf.path), pin.JointModelFreeFlyer(), ROOT_JOINT)
            notes.append(f"free root joint {ROOT_JOINT!r} added (JointModelFreeFlyer)")
        else:
            model = pin.buildModelFromUrdf(str(rf.path))
        notes.append(f"Pinocchio reads {rf.path.name} (buildModelFromUrdf)")
    else:
        why = pinocchio_misreads_includes(rf.path) or pinocchio_misreads_frames(rf.path)
        if why:
            raise Unsupported(why)
        model = pin.buildModelFromMJCF(str(rf.path))
        notes.append(f"Pinocchio reads {rf.path.name} (buildModelFromMJCF; its gravity option is not read)")
    mj = _mujoco_of_file(rf) if rf.fmt == "mjcf" else None
    if mj is not None:
        why = pinocchio_mass_differs(model, mj, rf.path.name)
        if why:
            raise Unsupported(why)
    if rf.locked:
        model = _pin_locked(model, rf, notes)
    addr = _pin_addresses(model, mj, rf)
    planar = _pin_planar(model, addr, rf.path) if rf.fmt == "urdf" else []
    unbounded = _pin_unbounded(model, rf.path.name)
    model.gravity.linear = np.asarray(gravity, float)
    damping = np.asarray(model.damping, float).copy()
    springs: list[tuple[int, int, float, float]] = []
    grav: list[tuple[int, np.ndarray, float]] = []
    q_offset: list[tuple[int, float]] = []
    if mj is not None:
        springs, q_offset = _mjcf_springs(mj, addr, notes)
        grav = _mjcf_gravcomp(mj, model)
        if springs or grav:
            notes.append("not read by Pinocchio's MJCF reader, applied by the harness from MuJoCo's "
                         "compilation of the same file: "
                         + ", ".join([f"spring on {n}" for n in _names(addr, springs)]
                                     + [f"gravcomp of {model.frames[f].name}" for f, _, _ in grav]))
    if damping.any():
        notes.append("joint damping as Pinocchio reads it (model.damping) applied by the harness: -damping * v")
    skipped = []
    if mj is not None:
        import mujoco

        skipped += [{"kind": "tendon", "element": f"tendon {mujoco.mj_id2name(mj, mujoco.mjtObj.mjOBJ_TENDON, i) or i}",
                     "location": rf.path.name} for i in range(mj.ntendon)]
        skipped += [{"kind": "equality", "element": f"equality {mujoco.mj_id2name(mj, mujoco.mjtObj.mjOBJ_EQUALITY, i) or i}",
                     "location": rf.path.name} for i in range(mj.neq)]
    if unbounded:
        notes.append(f"{len(unbounded)} continuous joint(s) read by Pinocchio as unbounded revolute "
                     "(q = (cos θ, sin θ)): mapped to and from progmo's angle")
    if planar:
        notes.append(f"{len(planar)} planar joint(s) read by Pinocchio as JointModelPlanar (q = (x, y, cos θ, "
                     "sin θ), velocity in the moving frame): mapped to progmo's NAME_TX, NAME_TY, NAME_RZ")
    return PinFile(model, addr, damping, springs, grav, notes, skipped, q_offset,
                   unbounded + [iq + 2 for iq, _ in planar], planar)



def _pin_planar(model: Any, addr: dict[str, tuple[int, int]], path: Path) -> list[tuple[int, int]]:
    """Pinocchio's planar joints (URDF ``planar``): their addresses under progmo's three names
    (``NAME_TX``, ``NAME_TY``, ``NAME_RZ``, MuJoCo's) in ``addr``; (first qpos, first dof) each.
    Pinocchio 4.1 moves a planar joint in the x-y plane of its frame whatever the file's axis:
    another axis is a misreading, not checked; it does not read the joint's damping: the file's
    is set on its three dofs (applied by the harness as every damping is)."""
    out = []
    joints = {j.get("name"): j for j in ET.parse(path).getroot().iter("joint")}
    axes = {n: j.find("axis") for n, j in joints.items()}
    for jid in range(1, model.njoints):
        if model.joints[jid].shortname() != "JointModelPlanar":
            continue
        name = model.names[jid]
        ax = axes.get(name)
        a = np.array([float(x) for x in ax.get("xyz", "1 0 0").split()]) if ax is not None else np.array([1.0, 0, 0])
        if np.linalg.norm(a / np.linalg.norm(a) - [0.0, 0.0, 1.0]) > 1e-12:
            raise Unsupported(f"Pinocchio 4.1 moves planar joint {name!r} of {path.name} in its frame's x-y "
                              f"plane, not normal to the file's axis {a.tolist()}: not checked in Pinocchio")
        iq, iv = addr.pop(name)
        dyn = joints[name].find("dynamics")
        damping = float(dyn.get("damping", "0")) if dyn is not None else 0.0
        if damping and not np.asarray(model.damping[iv:iv + 3]).any():
            # Pinocchio 4.1 does not read a planar joint's damping: the file's, on its three dofs
            # (the same on x and y: it does not depend on the frame the velocity is written in)
            model.damping[iv:iv + 3] = damping
        for k, part in enumerate(("_TX", "_TY", "_RZ")):
            addr[name + part] = (iq + k, iv + k)
        out.append((int(iq), int(iv)))
    return out


def _pin_unbounded(model: Any, name: str) -> list[int]:
    """The qpos index of each unbounded revolute joint of Pinocchio's model (a URDF continuous
    joint: q = (cos θ, sin θ), mapped by the check's CoordMap); any other joint whose nq differs
    from its nv, except free and ball joints, has no map to progmo's q."""
    unbounded = []
    for jid in range(1, model.njoints):
        kind = model.joints[jid].shortname()
        if kind.startswith("JointModelRUB") or kind == "JointModelRevoluteUnboundedUnaligned":
            unbounded.append(int(model.idx_qs[jid]))
        elif model.joints[jid].nq != model.joints[jid].nv and kind not in (
                "JointModelFreeFlyer", "JointModelSpherical", "JointModelPlanar"):
            raise Unsupported(f"Pinocchio reads joint {model.names[jid]!r} of {name} as "
                              f"{kind} (nq {model.joints[jid].nq}, nv "
                              f"{model.joints[jid].nv}): no coordinate map to progmo's q")
    return unbounded


def _pin_locked(model: Any, rf: RobotFile, notes: list[str]) -> Any:
    """Pinocchio's reading of the file with its locked joints removed (buildReducedModel)."""
    import pinocchio as pin

    ids = []
    for lj in rf.locked:
        if not model.existJointName(lj):
            raise Unsupported(f"locked joint {lj!r} is not a one-joint body of Pinocchio's reading of "
                              f"{rf.path.name} (buildReducedModel locks whole joints)")
        ids.append(model.getJointId(lj))
    # q = 0 is the file's pose in Pinocchio's reading (URDF q = 0, MJCF q = ref: see q_offset)
    model = pin.buildReducedModel(model, ids, pin.neutral(model))
    notes.append("locked joints removed by buildReducedModel in the file's pose: " + ", ".join(rf.locked))
    return model


def _mjcf_springs(mj: Any, addr: dict[str, tuple[int, int]], notes: list[str]
                  ) -> tuple[list[tuple[int, int, float, float]], list[tuple[int, float]]]:
    """From MuJoCo's compilation of an MJCF file: the joint springs (in Pinocchio's q) and the
    joints' ref, which Pinocchio's MJCF reader ignores (q_pin = q - ref): (springs, q_offset)."""
    import mujoco

    springs: list[tuple[int, int, float, float]] = []
    offset: dict[int, float] = {}
    for j in range(mj.njnt):
        name = mujoco.mj_id2name(mj, mujoco.mjtObj.mjOBJ_JOINT, j)
        ref = float(mj.qpos0[mj.jnt_qposadr[j]]) if int(mj.jnt_type[j]) in (2, 3) else 0.0
        if ref != 0.0 and name in addr:
            offset[addr[name][0]] = ref
        k = float(mj.jnt_stiffness[j])
        if k != 0.0 and name in addr:
            if int(mj.jnt_type[j]) not in (2, 3):
                raise Unsupported(f"a spring on the ball/free joint {name!r}: not applied for Pinocchio")
            iq, iv = addr[name]
            # in Pinocchio's q (q - ref): -k (q_pin + ref - springref)
            springs.append((iq, iv, k, float(mj.qpos_spring[mj.jnt_qposadr[j]]) - ref))
    q_offset = sorted(offset.items())
    if q_offset:
        notes.append("Pinocchio's MJCF reader ignores joint ref (the file's pose at q = 0): q_pin = q - ref on "
                     + ", ".join(f"{n}" for n, (iq, _) in addr.items() if iq in offset))
    return springs, q_offset


def _mjcf_gravcomp(mj: Any, model: Any) -> list[tuple[int, np.ndarray, float]]:
    """From MuJoCo's compilation of an MJCF file: each body's gravity compensation as (Pinocchio's
    body frame, CoM in the body frame, gravcomp x mass)."""
    import mujoco
    import pinocchio as pin

    grav: list[tuple[int, np.ndarray, float]] = []
    for b in range(1, mj.nbody):
        gc = float(mj.body_gravcomp[b])
        if gc != 0.0:
            name = mujoco.mj_id2name(mj, mujoco.mjtObj.mjOBJ_BODY, b)
            if not model.existFrame(name, pin.FrameType.BODY):
                raise Unsupported(f"gravcomp on body {name!r}: not a body frame of Pinocchio's reading")
            fid = model.getFrameId(name, pin.FrameType.BODY)
            grav.append((fid, np.array(mj.body_ipos[b], float), gc * float(mj.body_mass[b])))
    return grav


def _pin_addresses(model: Any, mj: Any, rf: RobotFile) -> dict[str, tuple[int, int]]:
    """Joint name -> (first q, first v) in Pinocchio's model; an MJCF body with several joints is
    one composite joint (named after the body's first joint) whose components follow the file's
    order (MuJoCo's compilation gives the joints of each body)."""
    addr = {model.names[jid]: (model.idx_qs[jid], model.idx_vs[jid]) for jid in range(1, model.njoints)}
    if mj is None:
        return addr
    import mujoco

    for b in range(1, mj.nbody):
        js = [j for j in range(mj.njnt) if mj.jnt_bodyid[j] == b]
        comp = f"Composite_{mujoco.mj_id2name(mj, mujoco.mjtObj.mjOBJ_JOINT, js[0])}" if len(js) > 1 else None
        if comp is None or comp not in addr:
            continue
        iq, iv = addr.pop(comp)
        for j in js:
            addr[mujoco.mj_id2name(mj, mujoco.mjtObj.mjOBJ_JOINT, j)] = (iq, iv)
            nq, nv = {0: (7, 6), 1: (4, 3)}.get(int(mj.jnt_type[j]), (1, 1))
            iq, iv = iq + nq, iv + nv
    return addr


def _names(addr: dict[str, tuple[int, int]], springs: list) -> list[str]:
    by = {v[1]: k for k, v in addr.items()}
    return [by.get(iv, str(iv)) for _, iv, _, _ in springs]


def _mujoco_of_file(rf: RobotFile) -> Any:
    """MuJoCo's plain compilation of an MJCF file (names, springs, gravcomp; no options changed)."""
    import mujoco

    return mujoco.MjModel.from_xml_path(str(rf.path))
