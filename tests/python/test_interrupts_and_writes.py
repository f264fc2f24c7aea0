"""Hostile conditions for the outputs (issue 29, round two): Ctrl-C in the first solve of a Python
process, a full device (``ulimit -f``: Python ignores SIGXFSZ, so a write past the limit fails with
EFBIG as on a full disk), a destination that is not a regular file, standard output closed, and
files of an earlier run. Every result file carries its real name only when whole (``.partial``
otherwise), every failure is one line naming the file, exit codes as README documents."""

from __future__ import annotations

import json
import os
import pathlib
import resource
import signal
import stat
import subprocess
import sys
import time

import pytest

import progmo

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
DP = str(ROOT / "references" / "scenes" / "double_pendulum.toml")


def command(*args: str) -> list[str]:
    return [sys.executable, "-m", "progmo.command", *args]


def fake_env(plan: dict[str, str]) -> dict[str, str]:
    env = dict(os.environ, PROGMO_CHECK_RUNNER="fake_checks:run_check", FAKE_CHECKS_PLAN=json.dumps(plan))
    env["PYTHONPATH"] = os.pathsep.join([str(HERE), env.get("PYTHONPATH", "")])
    return env


def limited(nbytes: int):
    """preexec_fn: files may grow to nbytes only (writes beyond fail with EFBIG)."""
    return lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, nbytes))


def interrupt_when(p: subprocess.Popen, ready, deadline: float = 120.0) -> None:
    """Send SIGINT once ready() says the child has got that far."""
    end = time.monotonic() + deadline
    while not ready():
        assert p.poll() is None, "the child ended before it could be interrupted"
        assert time.monotonic() < end, "the child never got there"
        time.sleep(0.05)
    p.send_signal(signal.SIGINT)


def no_traceback(err: str) -> None:
    assert "Traceback" not in err and "PanicException" not in err, err


# --- Ctrl-C ----------------------------------------------------------------------------------------
SOLVE_SCRIPT = """
import progmo
scene = progmo.load("double_pendulum")
print("solving", flush=True)
try:
    scene.solve(t1=1e6, output_dt=1.0)
    print("returned")
except KeyboardInterrupt as e:
    s = e.solution
    print("KeyboardInterrupt", s.code, len(s), s.t_end == s.t[-1], flush=True)
"""


def test_ctrl_c_in_the_first_solve_is_a_keyboard_interrupt_with_the_samples_so_far():
    p = subprocess.Popen([sys.executable, "-c", SOLVE_SCRIPT], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    assert p.stdout is not None
    assert p.stdout.readline().strip() == "solving"
    time.sleep(0.5)  # inside the solve (a million seconds of motion: minutes uninterrupted)
    start = time.monotonic()
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=60)
    assert time.monotonic() - start < 10, "the solve did not stop at the next step"
    no_traceback(err)
    word, code, n, last = out.split()
    assert (word, code, last) == ("KeyboardInterrupt", "interrupted", "True") and int(n) > 1, out


def test_check_interrupted_in_its_first_solve_exits_130_with_marked_outputs(tmp_path):
    out = tmp_path / "out"
    p = subprocess.Popen(command("check", "double_pendulum", "-s", "mujoco", "-j", "1", "--no-plots",
                                 "-o", str(out)),
                         env=fake_env({"double_pendulum/mujoco": "solve"}), cwd=tmp_path,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert p.stderr is not None
    while "solving" not in p.stderr.readline():
        assert p.poll() is None
    time.sleep(0.5)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    no_traceback(err)
    assert p.returncode == 130, err
    assert json.loads((out / "results.json").read_text()) == []
    run = json.loads((out / "run.json").read_text())
    assert any(n.startswith("INTERRUPTED after 0 of 1") for n in run["notes"]), run["notes"]
    assert "INTERRUPTED" in (out / "report.html").read_text()


def test_debug_interrupted_keeps_the_recording_so_far_as_partial(tmp_path):
    from mcap.reader import make_reader

    out = tmp_path / "dbg"
    part = out / "double_pendulum.mcap.partial"
    p = subprocess.Popen(command("debug", DP, "--out", str(out)), cwd=tmp_path,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # the first simulator's replay is being recorded: the recording has grown
    interrupt_when(p, lambda: part.is_file() and part.stat().st_size > 100_000)
    _, err = p.communicate(timeout=120)
    no_traceback(err)
    assert p.returncode == 130, err
    assert not (out / "double_pendulum.mcap").exists()
    assert f"the recording up to there is {part}" in err
    with open(part, "rb") as f:
        topics = {ch.topic for _, ch, _ in make_reader(f).iter_messages()}
    assert "/progmo/state" in topics, topics


# --- a full device ---------------------------------------------------------------------------------
def test_check_on_a_full_device_is_one_line_and_exit_3(tmp_path):
    out = tmp_path / "out"
    r = subprocess.run(command("check", "double_pendulum", "-s", "mujoco", "-j", "1", "--no-plots",
                               "-o", str(out)),
                       env=fake_env({}), cwd=tmp_path, capture_output=True, text=True, timeout=300,
                       preexec_fn=limited(4096))
    no_traceback(r.stderr)
    assert r.returncode == 3, r.stderr
    assert r.stderr.splitlines()[-1] == (
        f"progmo check: error: cannot write {out / 'results.json.partial'}: File too large")
    assert not (out / "results.json").exists()


def test_debug_on_a_full_device_leaves_no_truncated_file_under_a_real_name(tmp_path):
    out = tmp_path / "dbg"
    r = subprocess.run(command("debug", DP, "--simulator", "mujoco", "--out", str(out)), cwd=tmp_path,
                       capture_output=True, text=True, timeout=300, preexec_fn=limited(64 * 1024))
    no_traceback(r.stderr)
    assert r.returncode == 3, r.stderr
    last = r.stderr.splitlines()[-1]
    assert last.startswith(f"progmo debug: error: cannot write {out}/double_pendulum") and last.endswith(
        ".partial: File too large"), last
    assert sorted(p.name for p in out.iterdir() if not p.name.endswith(".partial")) == []


def test_solve_on_a_full_device_names_its_summary_partial_too(tmp_path):
    out = tmp_path / "run"
    r = subprocess.run(command("solve", DP, "--out", str(out)), capture_output=True, text=True,
                       timeout=120, preexec_fn=limited(40 * 1024))
    assert r.returncode == 3, r.stderr
    names = sorted(p.name for p in out.iterdir())
    assert names == ["recording.mcap.partial", "summary.json.partial", "trajectory.csv.partial"], names
    assert json.loads((out / "summary.json.partial").read_text())["success"] is True


WRITE_MCAP = """
import sys, progmo
sol = progmo.load("double_pendulum").solve()
try:
    sol.write_mcap(sys.argv[1])
except OSError as e:
    print(e)
"""


def test_write_mcap_on_a_full_device_leaves_a_partial_named_by_the_error(tmp_path):
    path = tmp_path / "rec.mcap"
    r = subprocess.run([sys.executable, "-c", WRITE_MCAP, str(path)], capture_output=True, text=True,
                       timeout=120, preexec_fn=limited(16 * 1024))
    assert r.stdout.startswith(f"{path}.partial: "), r.stdout + r.stderr
    assert not path.exists() and (tmp_path / "rec.mcap.partial").is_file()


def test_a_result_never_replaces_what_is_not_a_regular_file(tmp_path):
    sol = progmo.load("double_pendulum").solve(output_dt=1.0)
    fifo = tmp_path / "summary.json"
    os.mkfifo(fifo)
    with pytest.raises(OSError, match="it is a FIFO \\(named pipe\\), not a regular file"):
        sol.write_summary(fifo)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert not (tmp_path / "summary.json.tmp").exists()
    (tmp_path / "folder.csv").mkdir()
    with pytest.raises(OSError, match="it is a directory"):
        sol.write_csv(tmp_path / "folder.csv")
    assert not (tmp_path / "folder.csv.partial").exists()


# --- files of an earlier run -----------------------------------------------------------------------
def test_a_refused_solve_leaves_no_summary_of_the_earlier_run(tmp_path):
    out = tmp_path / "run"
    assert subprocess.run(command("solve", DP, "--out", str(out)), capture_output=True).returncode == 0
    assert (out / "summary.json").is_file()
    r = subprocess.run(command("solve", DP, "--out", str(out), "--output-dt", "1e-12"),
                       capture_output=True, text=True)
    assert r.returncode == 2 and "--output-dt" in r.stderr, r.stderr
    assert list(out.iterdir()) == []


def test_debug_removes_the_other_simulators_csv_of_an_earlier_run(tmp_path):
    out = tmp_path / "dbg"
    out.mkdir()
    old = out / "double_pendulum_pinocchio.csv"
    old.write_text("t\n0\n")
    r = subprocess.run(command("debug", DP, "--simulator", "mujoco", "--out", str(out)),
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["double_pendulum.mcap", "double_pendulum_mujoco.csv"]


# --- standard output closed ------------------------------------------------------------------------
@pytest.mark.parametrize("args", [["check", "double_pendulum", "-s", "mujoco", "-j", "1", "--no-plots",
                                   "--baselines", "none-here"], ["solve", DP]])
def test_a_closed_standard_output_is_no_traceback(tmp_path, args):
    r = subprocess.run(command(*args, "-o" if args[0] == "check" else "--out", str(tmp_path / "o")),
                       env=fake_env({}), cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                       text=True, timeout=300, preexec_fn=lambda: os.close(1))
    no_traceback(r.stderr)
    assert r.returncode == 0, r.stderr
    for f in (tmp_path / "o").iterdir():  # no result file took descriptor 1
        text = f.read_bytes()
        assert b"report: " not in text and b"success, t = " not in text, f


SWEEP_SPEC = """scene = "double_pendulum"
samples = 6
seed = 3
simulators = ["mujoco"]
horizon = 0.5
[vary]
"parameters.amp" = { uniform = [0.3, 0.7] }
"""


def test_sweep_interrupted_keeps_finished_checks_and_resumes(tmp_path):
    """Ctrl-C in a sweep: exit 130, every finished check kept as a whole line of results.jsonl, the
    report of what was done written; the same command then runs only what is missing."""
    spec, out = tmp_path / "s.toml", tmp_path / "o"
    spec.write_text(SWEEP_SPEC)
    results = out / "results.jsonl"
    cmd = command("sweep", "--spec", str(spec), "-o", str(out), "-j", "1", "--no-plots")
    p = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    interrupt_when(p, lambda: results.is_file() and results.read_text().count("\n") >= 1, deadline=300)
    _, err = p.communicate(timeout=300)
    no_traceback(err)
    assert p.returncode == 130, err
    kept = results.read_text().splitlines()
    assert 1 <= len(kept) < 6, kept
    assert all(json.loads(line)["simulator"] == "mujoco" for line in kept)
    agg = json.loads((out / "sweep.json").read_text())
    assert agg["counts"], agg
    r = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert f"{len(kept)} already done, {6 - len(kept)} to run" in r.stderr, r.stderr
    samples = sorted(json.loads(line)["sample"] for line in results.read_text().splitlines())
    assert samples == list(range(6)), samples
