"""Where the bundled references live: scenes, accepted baselines, the IVP Test Set problems and
their published reference solutions. They ship inside the package (``progmo/references``; in a
checkout the top-level ``references`` is a link to the same folder), so every door finds them from
any directory and nothing is read from outside the installation at run time.

``$PROGMO_REFERENCES`` points at another folder of the same layout (a project's own catalog).
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

from ._core import SceneError


def references() -> Path:
    """The references folder: ``$PROGMO_REFERENCES``, else the one inside the package."""
    env = os.environ.get("PROGMO_REFERENCES")
    return Path(env).resolve() if env else Path(__file__).resolve().parent / "references"


def scenes_dir() -> Path:
    """The bundled scene catalog (``references/scenes``)."""
    return references() / "scenes"


def baselines_dir() -> Path:
    """The accepted baselines (``references/baselines``); ``--baselines DIR`` chooses another."""
    return references() / "baselines"


def testset_dir() -> Path:
    """IVP Test Set problems as scenes and their published references (``published/``)."""
    return references() / "testset"


def bundled_scenes() -> list[str]:
    """Names of the bundled scenes."""
    return sorted(p.stem for p in scenes_dir().glob("*.toml"))


def scene_file(name_or_path: str | os.PathLike[str]) -> Path:
    """A scene file named by a path, or by the name of a bundled scene (``double_pendulum``, with
    or without ``.toml``). The same rule as the Rust CLI's. Raises SceneError naming what was
    looked for."""
    p = Path(name_or_path)
    bare = p.parent == Path(".") and p.suffix in ("", ".toml")
    if p.exists() and not (bare and p.is_dir()):
        return p  # a FIFO, device or folder too: the core refuses it by what it is (src/input.rs)
    if bare:
        bundled = scenes_dir() / f"{p.stem}.toml"
        if bundled.is_file():
            return bundled
        raise SceneError(f"{name_or_path}: no such scene file or bundled scene "
                         f"(bundled in {scenes_dir()}: {', '.join(bundled_scenes())})")
    raise SceneError(f"{name_or_path}: no such scene file")


def checkout() -> Path | None:
    """The source checkout this package runs from (editable install), if any: provenance only."""
    root = Path(__file__).resolve().parents[2]
    return root if (root / "Cargo.toml").is_file() and (root / "harness").is_dir() else None


def git_revision() -> str:
    """Short commit of the checkout (+dirty), or "" outside one."""
    root = checkout()
    if root is None:
        return ""
    try:
        r = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
                           capture_output=True, text=True, timeout=10)
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "-uno"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return r.stdout.strip() + ("+dirty" if dirty else "") if r.returncode == 0 else ""
    except (OSError, subprocess.SubprocessError):
        return ""


ROBOT_PATH_VAR = "PROGMO_ROBOT_PATH"


def robot_path() -> list[Path]:
    """Directories where ``package://PKG/...`` robot files are found: those of
    ``$PROGMO_ROBOT_PATH``, then the ``share`` folder of an installed ``example-robot-data``
    (a cmeel package: ``<site-packages>/cmeel.prefix/share/example-robot-data``)."""
    import sys

    dirs = [Path(p) for p in os.environ.get(ROBOT_PATH_VAR, "").split(os.pathsep) if p]
    for entry in sys.path:
        share = Path(entry or ".") / "cmeel.prefix" / "share"
        if (share / "example-robot-data").is_dir() and share not in dirs:
            dirs.append(share)
    return dirs


def export_robot_path() -> None:
    """Set ``$PROGMO_ROBOT_PATH`` for the Rust core (same process) to :func:`robot_path`; the
    one rule by which every door (``progmo.load``, the ``progmo`` command) finds robot files."""
    dirs = robot_path()
    if dirs:
        os.environ[ROBOT_PATH_VAR] = os.pathsep.join(str(d) for d in dirs)
