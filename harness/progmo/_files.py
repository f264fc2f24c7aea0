"""Result files of the Python commands (``check``, ``debug``, ``sweep``), under the rule of the Rust
writers (src/output/staged.rs): a file carries its real name only when whole. It is written as
``<name>.partial`` and renamed when complete; a write that fails (a full device, ``ulimit -f``)
leaves the ``.partial`` and raises :class:`WriteFailed`, which the command turns into one line
naming the file and exit 3 (:mod:`progmo._stdio`). A destination holding something other than a
regular file (a device, a FIFO, a directory) is refused, never replaced."""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

PARTIAL = ".partial"


class WriteFailed(BaseException):
    """A result file could not be written. A BaseException, so that no ``except Exception`` of a
    command's own swallows it: the command ends with exit 3. ``str()``: ``cannot write FILE:
    reason``."""

    def __init__(self, path: str | os.PathLike[str], error: OSError | str) -> None:
        self.path = str(path)
        self.reason = error if isinstance(error, str) else (error.strerror or str(error))
        super().__init__(f"cannot write {self.path}: {self.reason}")


def partial(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    return p.with_name(p.name + PARTIAL)


def kind(mode: int) -> str | None:
    """What a file of this mode is when it is not a regular file (None for a regular file)."""
    if stat.S_ISREG(mode):
        return None
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def check_destination(path: str | os.PathLike[str]) -> None:
    """WriteFailed unless ``path`` is free or a regular file (links followed)."""
    try:
        what = kind(os.stat(path).st_mode)
    except FileNotFoundError:
        what = "a dangling symbolic link" if os.path.islink(path) else None
    except OSError:
        what = None  # opening it will say what is wrong
    if what is not None:
        raise WriteFailed(path, f"it is {what}, not a regular file: refusing to replace it")


@contextmanager
def staged(path: str | os.PathLike[str], mode: str = "w", **kw: Any) -> Iterator[IO[Any]]:
    """``with staged(p) as f: ...`` writes ``p.partial`` and renames it to ``p`` when the block
    ends without error. An OSError while writing or closing: the ``.partial`` stays and
    :class:`WriteFailed` names it. Any other exception (Ctrl-C): the ``.partial`` stays as it is."""
    path = Path(path)
    part = partial(path)
    check_destination(path)
    check_destination(part)
    try:
        f = open(part, mode, **kw)
    except OSError as e:
        raise WriteFailed(part, e) from None
    try:
        yield f
        f.close()
    except OSError as e:
        _close_quietly(f)
        raise WriteFailed(part, e) from None
    except BaseException:
        _close_quietly(f)
        raise
    check_destination(path)
    try:
        os.replace(part, path)
    except OSError as e:
        raise WriteFailed(part, e) from None


@contextmanager
def deferred_interrupt() -> Iterator[None]:
    """Ctrl-C (SIGINT) during the block is held back to its end, then raised as KeyboardInterrupt:
    a record being written (one simulator's messages) is never cut in half. In the main thread
    only (elsewhere Python delivers no signals anyway)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGINT) in (
            signal.SIG_IGN, None):
        yield  # elsewhere no signal arrives; an ignored SIGINT stays ignored
        return
    caught: list[int] = []
    old = signal.signal(signal.SIGINT, lambda sig, frame: caught.append(sig))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)
    if caught:
        raise KeyboardInterrupt


def _close_quietly(f: IO[Any]) -> None:
    try:
        f.close()
    except OSError:
        pass


def write_text(path: str | os.PathLike[str], text: str, **kw: Any) -> None:
    """``path`` holds ``text`` whole, or ``path.partial`` the part written and WriteFailed."""
    kw.setdefault("encoding", "utf-8")
    with staged(path, "w", **kw) as f:
        f.write(text)


def remove(paths: "list[Path]") -> None:
    """Remove files of an earlier run (those that exist), so that none passes for this run's."""
    for p in paths:
        try:
            p.unlink()
        except FileNotFoundError:
            pass
        except OSError as e:
            raise WriteFailed(p, f"cannot remove the earlier run's file: {e.strerror or e}") from None
