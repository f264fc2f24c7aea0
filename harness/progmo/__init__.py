"""progmo harness: solve programmed motions with the Rust core and prove their control forces by
replaying them open-loop in MuJoCo and Pinocchio."""

from ._core import ExportUnsupported, Scene, SceneError, version

__all__ = ["ExportUnsupported", "Scene", "SceneError", "version"]
