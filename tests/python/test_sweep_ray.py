"""`progmo sweep --executor ray` on a real Ray cluster (issue 16): a head and a second worker node
started on 127.0.0.1, a sweep whose worker process is killed (SIGKILL) while it runs a check. The
sweep must complete with every (sample, simulator) exactly once and the same tolerance report as the
local executor. Skipped, with the reason, only where Ray cannot start."""

import json
import os
import pathlib
import re
import signal
import socket
import subprocess
import sys
import time

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
HERE = pathlib.Path(__file__).resolve().parent
SPEC = """scene = "double_pendulum"
samples = 4
seed = 11
simulators = ["mujoco", "pinocchio"]
horizon = 0.2
[vary]
"parameters.amp" = { uniform = [0.3, 0.7] }
"initial.q.q1" = { normal = [0.3, 0.1] }
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def cluster():
    ray = pathlib.Path(sys.executable).parent / "ray"
    if not ray.is_file():
        pytest.skip("SKIPPED: Ray is not installed (pip install 'progmo[ray]'); the Ray executor was NOT tested")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")]),
           "RAY_USAGE_STATS_ENABLED": "0", "SLOW_CHECKS_PAUSE": "1.5",
           # a private cluster on 127.0.0.1 for this test only: no token to distribute
           "RAY_AUTH_MODE": "disabled"}
    port = _free_port()
    common = ["--num-cpus=1", "--disable-usage-stats"]
    head = subprocess.run([str(ray), "start", "--head", "--node-ip-address=127.0.0.1", f"--port={port}",
                           "--include-dashboard=false", *common], capture_output=True, text=True, timeout=180, env=env)
    if head.returncode != 0:
        pytest.skip(f"SKIPPED: a Ray head cannot start here: {head.stderr.strip().splitlines()[-1:]}")
    try:
        worker = subprocess.run([str(ray), "start", f"--address=127.0.0.1:{port}", "--node-ip-address=127.0.0.1",
                                 *common], capture_output=True, text=True, timeout=180, env=env)
        assert worker.returncode == 0, worker.stderr
        yield f"127.0.0.1:{port}", env
    finally:
        subprocess.run([str(ray), "stop", "--force"], capture_output=True, timeout=120)


def _task_workers() -> list[int]:
    ps = subprocess.run(["ps", "-eo", "pid,args"], capture_output=True, text=True).stdout
    return [int(line.split()[0]) for line in ps.splitlines() if "ray::_check_remote" in line]


def test_a_killed_ray_worker_loses_and_duplicates_nothing(tmp_path, cluster):
    address, env = cluster
    spec = tmp_path / "s.toml"
    spec.write_text(SPEC)
    out = tmp_path / "ray"
    env = {**env, "PROGMO_CHECK_RUNNER": "slow_checks:run_check"}
    p = subprocess.Popen([sys.executable, "-m", "progmo.sweep", "--spec", str(spec), "-o", str(out),
                          "--executor", "ray", "--address", address], cwd=ROOT, env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    killed = None
    deadline = time.monotonic() + 240
    while killed is None and time.monotonic() < deadline and p.poll() is None:
        res = out / "results.jsonl"
        if res.is_file() and res.read_text().count("\n") >= 1:
            pids = _task_workers()
            if pids:
                os.kill(pids[0], signal.SIGKILL)
                killed = pids[0]
        time.sleep(0.1)
    stdout, stderr = p.communicate(timeout=600)
    assert killed is not None, "no running Ray task to kill was seen:\n" + stderr[-3000:]
    assert p.returncode == 0, stdout + stderr[-3000:]
    keys = [(json.loads(x)["sample"], json.loads(x)["simulator"]) for x in (out / "results.jsonl").read_text().splitlines()]
    assert sorted(keys) == sorted((i, m) for i in range(4) for m in ("mujoco", "pinocchio")), keys
    # the same report as the local executor, whatever the order results arrived in
    local = tmp_path / "local"
    r = subprocess.run([sys.executable, "-m", "progmo.sweep", "--spec", str(spec), "-o", str(local), "-j", "2"],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    a, b = (json.loads((d / "sweep.json").read_text()) for d in (out, local))
    assert a["metrics"] == b["metrics"] and a["counts"] == b["counts"]
    assert a["meta"]["executor"] == "ray" and b["meta"]["executor"] == "local"
    assert re.search(r"PASS: 8 of 8", stdout)
    # `progmo check` on the same cluster: the same verdicts as the local executor
    env = {k: v for k, v in env.items() if k != "PROGMO_CHECK_RUNNER"}
    outs = {}
    for ex in ("ray", "local"):
        c = subprocess.run([sys.executable, "-m", "progmo.cli", "check", "double_pendulum", "heavy_top",
                            "-s", "mujoco", "-s", "pinocchio", "--horizon", "0.2", "--no-plots", "--json", "-o", str(tmp_path / f"check-{ex}"),
                            "--executor", ex, "--address", address], cwd=ROOT, env=env, capture_output=True,
                           text=True, timeout=600)
        assert c.returncode == 0, c.stderr[-3000:]
        outs[ex] = sorted((r["scene"], r["simulator"], r["status"], r["metrics"]["replay_residual"])
                          for r in json.loads(c.stdout)["results"])
    assert outs["ray"] == outs["local"] and len(outs["ray"]) == 4
