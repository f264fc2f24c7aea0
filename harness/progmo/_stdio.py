"""Standard output of the harness's commands, treated as the Rust ``progmo`` treats it: a closed
pipe (``| head -1``) ends the command quietly with status 141, a write that fails otherwise (a full
device) is one line on stderr and exit 3, Ctrl-C is exit 130; never a traceback. Paths that are not
UTF-8 are printed as the bytes they are (``surrogateescape``). A standard stream closed at start
(``progmo check >&-``) is opened on /dev/null, as the Rust runtime does: its output is dropped and
no file the command opens can take its descriptor. A result file that cannot be written
(:class:`progmo._files.WriteFailed`: a full device) is one line naming the file and exit 3."""

from __future__ import annotations

import io
import os
import sys
from typing import Callable

EXIT_CANNOT_WRITE, EXIT_INTERRUPTED, EXIT_CLOSED_PIPE = 3, 130, 141


class StdoutFailed(BaseException):
    """Writing standard output failed. A BaseException, so that no ``except Exception`` of a
    command's own swallows it: the command ends."""

    def __init__(self, error: OSError) -> None:
        super().__init__(error)
        self.error = error


class _Raw(io.RawIOBase):
    """File descriptor 1 whose write errors become :class:`StdoutFailed`; after the first one every
    write is dropped (so the flush at interpreter exit cannot fail again)."""

    def __init__(self, fd: int) -> None:
        super().__init__()
        self._fd = fd
        self.failed = False

    def writable(self) -> bool:
        return True

    def fileno(self) -> int:
        return self._fd

    def isatty(self) -> bool:
        return os.isatty(self._fd)

    def write(self, b) -> int:  # type: ignore[override]
        if self.failed:
            return len(b)
        try:
            return os.write(self._fd, b)
        except OSError as e:
            self.failed = True
            raise StdoutFailed(e) from None


def sanitize_std_fds() -> None:
    """Open /dev/null on descriptors 0, 1 and 2 where they are closed (as the Rust runtime does at
    start), and give Python stream objects for them."""
    for fd, name, mode in ((0, "stdin", "r"), (1, "stdout", "w"), (2, "stderr", "w")):
        try:
            os.fstat(fd)
            continue
        except OSError:
            pass
        null = os.open(os.devnull, os.O_RDWR)
        if null != fd:
            os.dup2(null, fd)
            os.close(null)
        if getattr(sys, name) is None:
            setattr(sys, name, open(fd, mode, closefd=False, encoding="utf-8", errors="surrogateescape"))


def _wrap_stdout() -> _Raw | None:
    out = sys.stdout
    try:
        fd = out.fileno()
    except (AttributeError, OSError, ValueError):
        return None  # not a real file (a test's capture): leave it
    out.flush()
    raw = _Raw(fd)
    line_buffering = bool(getattr(out, "line_buffering", False))
    sys.stdout = io.TextIOWrapper(io.BufferedWriter(raw), encoding=out.encoding or "utf-8",
                                  errors="surrogateescape", line_buffering=line_buffering)
    return raw


def _stderr(msg: str) -> None:
    try:
        print(msg, file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass  # nowhere left to say it


def run(main: Callable[[], int | None], prog: str) -> int:
    """Run a command's ``main`` and return its exit status, with standard output as above."""
    from ._files import WriteFailed

    sanitize_std_fds()
    raw = _wrap_stdout()
    try:
        try:
            rc = main()
            code = int(rc or 0)
        except SystemExit as e:  # argparse: --help (0) or bad usage (2)
            if e.code is None or isinstance(e.code, int):
                code = int(e.code or 0)
            else:
                _stderr(str(e.code))
                code = 1
        sys.stdout.flush()
        return code
    except StdoutFailed as e:
        if raw is not None:
            raw.failed = True
        if isinstance(e.error, BrokenPipeError):
            return EXIT_CLOSED_PIPE
        _stderr(f"{prog}: error: cannot write to standard output: {e.error.strerror or e.error}")
        return EXIT_CANNOT_WRITE
    except WriteFailed as e:
        _stderr(f"{prog}: error: {e}")
        return EXIT_CANNOT_WRITE
    except KeyboardInterrupt:
        _stderr(f"{prog}: interrupted")
        return EXIT_INTERRUPTED
