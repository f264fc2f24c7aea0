"""Type stubs of the private extension module `progmo._core` (Rust, pyo3).

Shapes: n = number of samples, nq / nv = sizes of q / v, s = number of constraint rows.
"""

import os
from typing import Sequence, Any, Literal, NotRequired, TypedDict, Unpack, final

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]

class SceneError(ValueError):
    """A scene file (or a file it names) is invalid; the message names file, line, column and
    field, and so do the attributes (line and column None without a position, field None when not
    applicable). Every error of the core carries these attributes (``progmo::Error``, converted in
    one place): ``kind`` names its variant (``scene``, ``input``, ``settings``, ...)."""

    kind: str
    field: str | None
    message: str
    file: str | None
    line: int | None
    column: int | None
    excerpt: str
    rows: list[int] | None

class SettingsError(ValueError):
    """A solver setting, override or time span is invalid; the message names it
    (``rtol: must be > 0``), ``field`` is its name at every door, ``message`` what is wrong."""

    kind: str
    field: str | None
    message: str
    file: str | None
    line: int | None
    column: int | None
    excerpt: str
    rows: list[int] | None

class SolveStopped(RuntimeError):
    """A solve stopped before t1 (raised by `Solution.raise_if_stopped`)."""

    code: str
    solution: "Solution"

class ExportUnsupported(ValueError):
    """The scene holds an element the simulator format cannot carry; the message names it."""

    kind: str
    field: str | None
    message: str
    file: str | None
    line: int | None
    column: int | None
    excerpt: str
    rows: list[int] | None

# generated: SolveSettings from progmo::solve::settings (PROGMO_BLESS=1 pytest tests/python/test_settings.py)
class SolveSettings(TypedDict, total=False):
    """The settings of ``Scene.solve`` (``progmo::solve::Overrides``); None keeps the scene's."""
    assemble: bool | None
    atol: float | None
    baumgarte_alpha: float | None
    baumgarte_beta: float | None
    drift: Literal["projection", "baumgarte", "none"] | None
    formulation: Literal["auto", "null_space", "null_space_stacked", "kkt", "range_space", "udwadia_kalaba", "articulated_body"] | None
    integrator: Literal["dop853", "dopri5", "radau5", "rk4"] | None
    max_drift: float | None
    max_samples: int | None
    max_step: float | None
    max_steps: int | None
    output_dt: float | None
    projection_tol: float | None
    richardson: bool | None
    rtol: float | None
    step: float | None
    strict: bool | None
    t1: float | None
# end generated

class SettingInfo(TypedDict):
    name: str
    table: Literal["solver", "time", "initial"]
    kind: Literal["number", "integer", "string", "boolean"]
    description: str
    above: float | None
    at_least: float | None
    choices: list[str]
    default: Any

class Warning(TypedDict):
    kind: Literal["row_gradient", "singular_value", "u_cancellation", "global_error"]
    t: float  # first crossing of the threshold
    rows: list[str]
    value: float
    worst: float
    t_worst: float
    threshold: float
    message: str  # one sentence: quantity, time, rows
    # row_gradient of a fixed-step solve: the Richardson companion's relative velocity error
    # before `t` and after `t_worst` (what the passage cost)
    error_before: NotRequired[float]
    error_after: NotRequired[float]

class ExpressionForces(TypedDict):
    generalized: F64  # (nv,) the scene's coordinate forces
    points: list[tuple[str, list[float], list[float]]]  # (body, world point, world force) per point force

class Row(TypedDict):
    name: str
    level: Literal["position", "velocity", "acceleration"]
    role: Literal["programme", "system"]

class Mimic(TypedDict):
    joint: str  # the follower: q_joint = multiplier * q_leader + offset (system row mimic_JOINT)
    leader: str
    multiplier: float
    offset: float

class RobotFile(TypedDict):
    kind: Literal["urdf", "mjcf"]
    path: str  # the resolved absolute path of the robot file
    locked_joints: list[tuple[str, float]]  # (joint, q value it is welded at)
    mimics: list[Mimic]  # the URDF <mimic>s modelled as system rows

class Unmodelled(TypedDict):
    kind: str  # one of Scene.unmodelled_kinds()
    element: str  # e.g. "joint[elbow].frictionloss", "tendon.fixed[t1]", "link[hand].collision"
    location: str  # "file:line" of the element in the robot file
    declared: str | None  # the scene's reason ([model] ignore), None: undeclared

class Code(TypedDict, total=False):
    code: str  # the return code's name; other keys: its fields (t, rows, values)

@final
class Solution:
    """The outcome of `Scene.solve`: samples as read-only arrays, the return code, statistics,
    warnings, and the writers of `progmo solve` (same formats)."""

    @property
    def scene(self) -> str: ...
    @property
    def success(self) -> bool: ...
    @property
    def code(self) -> str:
        """success, step_too_small, singular_programme, ..."""
    @property
    def code_details(self) -> Code: ...
    @property
    def message(self) -> str:
        """The return code as one sentence (quantity, time, rows)."""
    @property
    def t_end(self) -> float: ...
    @property
    def warnings(self) -> list[Warning]: ...
    @property
    def stats(self) -> dict[str, Any]: ...
    @property
    def settings(self) -> dict[str, Any]: ...
    @property
    def wall_seconds(self) -> float: ...
    @property
    def q_names(self) -> list[str]: ...
    @property
    def v_names(self) -> list[str]: ...
    @property
    def row_names(self) -> list[str]: ...
    @property
    def t(self) -> F64:
        """(n,)"""
    @property
    def q(self) -> F64:
        """(n, nq)"""
    @property
    def v(self) -> F64:
        """(n, nv)"""
    @property
    def a(self) -> F64:
        """(n, nv) accelerations dv/dt"""
    @property
    def u(self) -> F64:
        """(n, nv) control forces of the programme rows (paper eq. 2.12)"""
    @property
    def reactions(self) -> F64:
        """(n, nv) reactions of the system's own constraints"""
    @property
    def lambda_(self) -> F64:
        """(n, s) multipliers"""
    @property
    def tau(self) -> F64 | None:
        """(n, m) actuator forces in the order of [[actuators]] (u = H(t, q) tau); None without actuators."""
    @property
    def residuals(self) -> F64:
        """(n, s)"""
    @property
    def residual_rates(self) -> F64:
        """(n, s) dg/dt of position rows"""
    @property
    def max_residuals(self) -> F64:
        """(s,) over every accepted step"""
    @property
    def max_residual_rates(self) -> F64:
        """(s,)"""
    def write_csv(self, path: str | os.PathLike[str]) -> None: ...
    def write_mcap(self, path: str | os.PathLike[str]) -> None: ...
    def write_summary(self, path: str | os.PathLike[str]) -> None: ...
    def raise_if_stopped(self) -> "Solution": ...
    def __len__(self) -> int: ...

class Dynamics(TypedDict):
    mass: F64  # (nv, nv) A(q)
    velocity_terms: F64  # (nv,) G(q, v)
    applied_forces: F64  # (nv,) Q(t, q, v); A dv/dt - G = Q
    B: F64  # (s, nv) constraint Jacobian
    gamma: F64  # (s,) B dv/dt = gamma

__all__ = ["Scene", "Solution", "SceneError", "SettingsError", "SolveStopped", "ExportUnsupported", "FORMULATIONS", "INTEGRATORS", "DRIFTS", "version",
           "chain_toml", "drift_cost", "cli", "REFERENCE_RTOL", "REFERENCE_ATOL", "SIMULATORS", "SOLVER_ONLY",
           "CHECK_OPTIONS", "SOLVER_NUMBERS", "SETTINGS", "check_metrics", "default_budgets", "tolerance_keys", "nearest", "resolve_file"]

#: The core's method vocabulary (progmo::solve::FORMULATION_NAMES, ...); the Literal types below
#: spell the same names (tests/python/test_bindings.py checks it).
FORMULATIONS: list[str]
INTEGRATORS: list[str]
DRIFTS: list[str]

@final
class Scene:
    """A loaded, validated scene file."""

    def __new__(cls, path: str) -> "Scene": ...
    @property
    def name(self) -> str: ...
    @property
    def description(self) -> str: ...
    @property
    def purpose(self) -> str: ...
    @property
    def path(self) -> str: ...
    @property
    def kind(self) -> Literal["tree", "lagrangian"]: ...
    @property
    def q_names(self) -> list[str]: ...
    @property
    def v_names(self) -> list[str]: ...
    @property
    def rows(self) -> list[Row]: ...
    @property
    def tolerances(self) -> dict[str, tuple[float, str]]: ...
    @property
    def replay_step(self) -> tuple[float, str] | None:
        """`[checks] replay_step` as (value, reason); None: a convergence check picks the step."""
    @property
    def parameters(self) -> list[tuple[str, float]]: ...
    @property
    def t0(self) -> float: ...
    @property
    def t1(self) -> float: ...
    @property
    def q0(self) -> F64: ...
    @property
    def v0(self) -> F64: ...
    @property
    def settings(self) -> dict[str, Any]: ...
    def check_replay_step(self, h: float, *, t1: float | None = None) -> None: ...
    def solve(self, **settings: Unpack[SolveSettings]) -> Solution:
        """Solve with settings overridden by name (``SolveSettings``; ``SETTINGS`` documents each):
        the names of the scene file's keys and ``progmo solve``'s flags. Unknown names, wrong types
        and values out of range raise SettingsError (``.field``, ``.message``)."""
    def check_initial(self) -> None:
        """Raises SceneError with the located message `progmo solve` gives when the solver refuses
        the initial state."""
    @property
    def actuators(self) -> list[tuple[str, int | None]]:
        """[[actuators]] of the scene: (name, index into v) each, None for an actuator along a
        `direction`; empty: the ideal realization."""
    @property
    def actuation_map(self) -> F64 | None:
        """The actuation map H (n x m, u = H tau) at the initial state (H itself when constant);
        None without actuators."""
    @property
    def actuation_varies(self) -> bool:
        """Does H depend on the state (a `direction` of expressions of t and the coordinates)?"""
    def actuation_map_at(self, t: float, q: F64) -> F64 | None:
        """H(t, q) (n x m); None without actuators."""
    def unactuated_part(self, t: F64, q: F64, u: F64) -> F64 | None:
        """u_k - P(t_k, q_k) u_k per sample (K x n): the part of u outside range(H); None without actuators."""
    @property
    def robot_file(self) -> RobotFile | None:
        """The robot file of a urdf/mjcf scene (kind, resolved absolute path, locked joints with
        the q value each is welded at, the <mimic>s modelled as system rows); None for other
        models."""
    @property
    def unmodelled(self) -> list[Unmodelled]:
        """Every element of the robot file read and not modelled, in file order; [] for other
        models."""
    @property
    def joint_ranges(self) -> dict[str, tuple[float, float]]:
        """Position limits the robot file states for the modelled hinge/slide joints: {joint:
        (lower, upper)} in q's units; {} for other models."""
    @staticmethod
    def unmodelled_kinds() -> list[tuple[str, str]]:
        """The closed vocabulary of unmodelled kinds: (kind, what it covers)."""
    @property
    def expected_not_checked(self) -> list[tuple[str, str]]:
        """[checks] not_checked of the scene: (simulator, reason)."""
    @property
    def references(self) -> list[dict[str, Any]]:
        """[[reference]] of the scene: one dict per value (t, quantity "q"/"v"/"u", name, index,
        value, source, field)."""
    def expression_forces(self, t: float, q: F64, v: F64) -> ExpressionForces: ...
    def residuals(self, t: F64, q: F64, v: F64, a: F64 | None = None) -> F64: ...
    def dynamics(self, t: float, q: F64, v: F64) -> Dynamics: ...
    def accelerations(
        self, t: float, q: F64, v: F64, formulation: Literal["auto", "null_space", "null_space_stacked", "kkt", "range_space", "udwadia_kalaba", "articulated_body"]
    ) -> dict[str, F64]:
        """One right-hand side (no drift control): {"a": dv/dt, "u", "reactions", "lambda"}."""
    def rhs_benchmark(
        self,
        iterations: int,
        formulation: Literal["auto", "null_space", "null_space_stacked", "kkt", "range_space", "udwadia_kalaba", "articulated_body"],
        t: float | None = None,
        q: F64 | None = None,
        v: F64 | None = None,
    ) -> float:
        """Wall-clock seconds per right-hand side (dv/dt and u), looped in Rust, at (t0, q0, v0) by default."""
    def export(self, format: Literal["mjcf", "urdf"], *, timestep: float = 1e-3,
               supply_reactions: bool = False) -> tuple[str, dict[str, Any]]: ...
    def body_poses(self, q: F64) -> list[tuple[str, list[float], list[float]]]:
        """World pose of every body at q: (name, position, quaternion w x y z); [] for a lagrangian scene."""
    def scene_update(self, q: F64, prefix: str, alpha: float = 1.0, targets: bool = True) -> dict[str, Any] | None:
        """The foxglove.SceneUpdate drawing the mechanism on frames <prefix>/<body> (and the declared view
        targets in the world frame); None for a lagrangian scene."""
    def scene_trace(self, q: F64, prefix: str) -> dict[str, Any] | None:
        """The foxglove.SceneUpdate of the programme's sites' traces through the rows of q (entities
        <prefix>/trace/<site>); None for a lagrangian scene or no traced site."""
    def recording_schemas(self) -> dict[str, dict[str, Any]]:
        """JSON schemas of recordings by schema name (progmo.State, ..., foxglove.SceneUpdate)."""

def version() -> str: ...
def cli(argv: Sequence[str | os.PathLike[str]]) -> int:
    """The `progmo` command line in this process (argv[0] is the program name); the exit code."""
def chain_toml(
    n: int,
    *,
    masses: Sequence[float] | None = None,
    length: float = 0.25,
    q0: float | None = None,
    name: str | None = None,
    t1: float = 2.0,
) -> str:
    """Scene text of a generated n-link planar chain (progmo::problems::chain); 2 <= n <= 10000,
    ValueError otherwise. The name is quoted and escaped."""
def drift_cost(rounds: int = 5) -> dict[str, float]:
    """Projection on/off over 10^4 periods: minimum wall times and residuals (progmo::problems::hard)."""

# The check's vocabulary (progmo::check): one definition for the loader, the schema, FORMAT.md and
# progmo.checks.
#: Tolerances of the check's reference solve.
REFERENCE_RTOL: float
REFERENCE_ATOL: float
#: Simulators of the cross-simulator check (keys of `[checks] not_checked`).
SIMULATORS: list[str]
#: The checker of scenes no simulator document describes.
SOLVER_ONLY: str
#: Options of the check that are not budgets, in a scene's `[checks]` table (replay_step).
CHECK_OPTIONS: list[str]
#: The numeric keys of `[solver]` (what a sweep may vary there).
SOLVER_NUMBERS: list[str]
SETTINGS: list[SettingInfo]

def check_metrics() -> list[dict[str, str]]:
    """Every metric the check judges, in the order budgets are listed: name, table (its budget's
    name in [tolerances]), simulators and solver_only (when those checks judge it: "always",
    "closures", "actuators", "references", "robot_file" or "never"), class (the tolerance class) and reason."""
def default_budgets(drift: dict[str, Any]) -> dict[str, tuple[float, str]]:
    """Default budget and reason of every metric under a drift control as `Scene.settings["drift"]`
    gives it; ValueError for an unknown kind."""
def tolerance_keys() -> list[str]:
    """Every name a scene's `[tolerances]` may hold."""
def nearest(name: str, candidates: list[str]) -> str | None:
    """The nearest candidate to a misspelt name (the rule of every "did you mean"), or None."""

def resolve_file(name: str, folder: str | os.PathLike[str]) -> str:
    """The canonical path `name` names from `folder` under the path rule of scene files
    (src/input.rs: inside the folder, the robot path or $PROGMO_ALLOW_ROOTS); SceneError otherwise."""
