"""Body of the sweep-file fuzz target (``sweep_target.py``, atheris) and of its bounded
deterministic pass in pytest (``tests/python/test_fuzz_sweep.py``): one function, so both exercise
the same code. Not part of the package (fuzz/ is not in the wheel).

``one_input(data, folder)`` writes ``data`` as a sweep file and goes through what ``progmo sweep``
does with it before any check runs: ``load_spec``, ``spec_scene`` (when it names a scene),
``check_names`` against the bundled double_pendulum (the bundled sweep's scene), the sample count,
and the first and last samples' values and scene text (``sample_text``, read back as TOML). The
property: only :class:`progmo.sweep.SweepError` (and the :class:`progmo.SceneError` of a scene
name that names no scene, which ``progmo sweep`` reports like it), never another exception; each
step bounded in time (the caller's timeout: atheris ``-timeout``, the pytest pass's clock); an
error of a file that is not text quotes none of its bytes.
"""

from __future__ import annotations

import functools
import tempfile
import tomllib
from pathlib import Path

from progmo import Scene, SceneError, data
from progmo import sweep as sw

#: samples generated per input: the first and the last (the sweep's size is checked, not walked)
INDICES = 2


@functools.cache
def base() -> tuple[Scene, str, str]:
    """The scene the fuzzed sweeps vary (loaded once): double_pendulum, its path and text."""
    path = data.scene_file("double_pendulum")
    return Scene(str(path)), str(path), path.read_text()


def folder() -> Path:
    """A fresh folder for the fuzzed file, memory-backed where there is one (/dev/shm: rewriting a
    file on disk costs milliseconds, which the fuzzer would spend instead of executions)."""
    shm = Path("/dev/shm")
    return Path(tempfile.mkdtemp(prefix="progmo-fuzz-sweep-", dir=shm if shm.is_dir() else None))


def _text(data_: bytes) -> bool:
    try:
        data_.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return True


def one_input(data_: bytes, folder: Path) -> None:
    p = folder / "sweep.toml"
    p.write_bytes(data_)
    try:
        spec = sw.load_spec(p)
    except sw.SweepError as e:
        msg = str(e)
        assert msg.startswith(str(p)), msg
        if not _text(data_):
            # located without quoting: the message is the same whatever the bytes after the error
            assert "\\x" not in msg and "b'" not in msg, msg
        return
    if spec.scene is not None:
        try:
            sw.spec_scene(spec)
        except (sw.SweepError, SceneError):
            pass
    scene, path, text = base()
    try:
        sw.check_names(spec, scene)
    except sw.SweepError as e:
        assert str(e).startswith(str(p)), str(e)
        return
    n = spec.total()
    assert n >= 1, n
    for i in sorted({0, n - 1})[:INDICES]:
        values = spec.values(i)
        assert set(values) == {v.key for v in spec.variables}, values
        try:
            st = sw.sample_text(text, path, spec, i, values)
        except sw.SweepError:
            continue
        tomllib.loads(st)  # a sample is a TOML scene file
