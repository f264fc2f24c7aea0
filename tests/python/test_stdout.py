"""Every command, Rust and Python, with standard output on a full device exits 3 with a one-line
message on stderr, with a closed pipe ends quietly (141), never with a traceback or a panic; an
output path that is not UTF-8 is a path like any other (issue 11)."""

from __future__ import annotations

import os
import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENE = str(ROOT / "references" / "scenes" / "double_pendulum.toml")
NON_UTF8 = os.fsdecode(b"out-\xff")  # a surrogate escape: the bytes reach the OS as they are


def _progmo_bin() -> str | None:
    """The Rust binary `cargo build --release` builds."""
    cands = [os.environ.get("PROGMO_BIN", "")]
    if os.environ.get("CARGO_TARGET_DIR"):
        cands.append(os.path.join(os.environ["CARGO_TARGET_DIR"], "release", "progmo"))
    cands.append(str(ROOT / "target" / "release" / "progmo"))
    return next((c for c in cands if c and os.access(c, os.X_OK)), None)


#: harness/test.sh builds the binary beside pytest and writes "ok" (or "failed") into this file
#: when the build has ended: the tests that run it wait for it there, never for a stale binary.
READY = os.environ.get("PROGMO_BIN_READY")
BIN = None if READY else _progmo_bin()
needs_bin = pytest.mark.skipif(BIN is None and not READY,
                               reason="no target/release/progmo: run `cargo build --release`")


def _built() -> str:
    global BIN
    if BIN is None and READY:
        import time
        deadline = time.monotonic() + 1700  # before pytest-timeout (1800 s)
        while not (os.path.exists(READY) and open(READY).read().strip()):
            assert time.monotonic() < deadline, f"the binary's build did not end in 28 min ({READY})"
            time.sleep(2)
        state = open(READY).read().strip()
        assert state == "ok", "the Rust binary did not build (cargo's output follows pytest's)"
        BIN = _progmo_bin()
        assert BIN is not None, "cargo's build ended without target/release/progmo"
    assert BIN is not None
    return BIN


def rust(*args: str) -> list[str]:
    return [_built(), *args]


def py(*args: str) -> list[str]:
    return [sys.executable, "-m", *args]


@pytest.fixture(scope="module")
def check_dir(tmp_path_factory) -> pathlib.Path:
    """The output folder of one small check (MuJoCo only), for `report`."""
    out = tmp_path_factory.mktemp("check") / "run"
    p = subprocess.run(py("progmo.cli", "check", SCENE, "-s", "mujoco", "--no-plots", "-j", "1", "--out", str(out)),
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    return out


# (name, needs the Rust binary, command line given a scratch folder and the check folder)
COMMANDS = [
    ("solve", True, lambda d, c: rust("solve", SCENE, "--no-mcap", "--quiet", "--out", str(d / "solve"))),
    ("validate", True, lambda d, c: rust("validate", SCENE)),
    ("export", True, lambda d, c: rust("export", SCENE, "--format", "mjcf")),
    ("progmo --help", True, lambda d, c: rust("--help")),
    ("progmo check --help", True, lambda d, c: rust("check", "--help")),
    ("progmo debug --help", True, lambda d, c: rust("debug", "--help")),
    ("progmo bench --help", True, lambda d, c: rust("bench", "--help")),
    ("check", False, lambda d, c: py("progmo.cli", "check", SCENE, "-s", "mujoco", "--no-plots", "-j", "1",
                                     "--out", str(d / "check"))),
    ("report", False, lambda d, c: py("progmo.cli", "report", str(c))),
    ("debug", False, lambda d, c: py("progmo.cli", "debug", SCENE, "--simulator", "mujoco", "--out", str(d / "dbg"))),
    ("progmo.debug", False, lambda d, c: py("progmo.debug", "--help")),
    ("progmo.cli --help", False, lambda d, c: py("progmo.cli", "--help")),
    ("bench --help", False, lambda d, c: py("progmo.bench.main", "--help")),
]


def _env() -> dict[str, str]:
    return {**os.environ, "PROGMO_PYTHON": sys.executable}  # the Rust CLI forwards to this Python


def _params():
    return [pytest.param(make, id=name, marks=[needs_bin] if needs_rust else [])
            for name, needs_rust, make in COMMANDS]


@pytest.mark.parametrize("make", _params())
def test_a_full_device_is_exit_3_with_one_line(make, tmp_path, check_dir):
    with open("/dev/full", "w") as full:
        p = subprocess.run(make(tmp_path, check_dir), stdout=full, stderr=subprocess.PIPE, text=True,
                           timeout=300, env=_env())
    assert p.returncode == 3, p.stderr
    last = p.stderr.strip().splitlines()[-1]
    assert "error: cannot write to standard output: No space left on device" in last, p.stderr
    assert "Traceback" not in p.stderr and "panicked" not in p.stderr, p.stderr


@pytest.mark.parametrize("make", _params())
def test_a_closed_pipe_ends_quietly_with_141(make, tmp_path, check_dir):
    r, w = os.pipe()
    os.close(r)  # every write to w fails with EPIPE
    try:
        p = subprocess.run(make(tmp_path, check_dir), stdout=w, stderr=subprocess.PIPE, text=True,
                           timeout=300, env=_env())
    finally:
        os.close(w)
    assert p.returncode == 141, p.stderr
    assert "Traceback" not in p.stderr and "panicked" not in p.stderr, p.stderr
    assert "standard output" not in p.stderr, p.stderr


# Commands with an output path; each writes its files there and exits 0.
OUT_COMMANDS = [
    ("solve", True, lambda d: rust("solve", SCENE, "--quiet", "--out", str(d)), ["summary.json", "trajectory.csv"]),
    ("export", True, lambda d: rust("export", SCENE, "--format", "urdf", "--out", str(d / "m.urdf")),
     ["m.urdf", "m.urdf.report.json"]),
    ("check", False, lambda d: py("progmo.cli", "check", SCENE, "-s", "mujoco", "--no-plots", "-j", "1", "--out", str(d)),
     ["results.json", "report.html", "summary.md"]),
    ("debug", False, lambda d: py("progmo.debug", SCENE, "--simulator", "mujoco", "--out", str(d)),
     ["double_pendulum.mcap", "double_pendulum_mujoco.csv"]),
    ("bench", False, lambda d: py("progmo.bench.main", "--smoke", "--only", "scaling", "--out", str(d)),
     ["index.html", "scaling.csv"]),
]


@pytest.mark.parametrize("make,files", [pytest.param(m, f, id=n, marks=[needs_bin] if r else [])
                                         for n, r, m, f in OUT_COMMANDS])
def test_a_non_utf8_output_path_is_a_path(make, files, tmp_path):
    d = tmp_path / NON_UTF8
    if files[0].startswith("m."):  # export writes a file: its folder must exist
        d.mkdir()
    p = subprocess.run(make(d), capture_output=True, timeout=300, env=_env())
    err = p.stderr.decode(errors="replace")
    assert p.returncode == 0, err
    assert "Traceback" not in err and "panicked" not in err, err
    for f in files:
        assert (d / f).is_file(), (f, sorted(os.listdir(os.fsencode(d))))
    if (d / "report.html").is_file():  # the report quotes the path and stays valid UTF-8
        assert "out-\\udcff" in (d / "report.html").read_text(encoding="utf-8")


def test_report_of_a_non_utf8_folder(tmp_path):
    d = tmp_path / NON_UTF8
    p = subprocess.run(py("progmo.cli", "check", SCENE, "-s", "mujoco", "--no-plots", "-j", "1", "--out", str(d)),
                       capture_output=True, timeout=300)
    assert p.returncode == 0, p.stderr.decode(errors="replace")
    (d / "report.html").unlink()
    p = subprocess.run(py("progmo.cli", "report", str(d)), capture_output=True, timeout=300)
    assert p.returncode == 0, p.stderr.decode(errors="replace")
    assert (d / "report.html").is_file()
    assert os.fsencode(d) + b"/report.html" in p.stdout  # printed as the bytes it is
