"""The installable package, as a user gets it: build the wheel, install it into a fresh virtual
environment (dependencies at the locked versions), and from a temporary directory run
`progmo solve double_pendulum`, `progmo check double_pendulum` and the README's Python snippet.
Nothing of the checkout is visible to it. Takes a few minutes (the wheel's release build, the
install); the only test that does."""

import json
import os
import pathlib
import subprocess
import sys

from test_readme import readme_snippet

ROOT = pathlib.Path(__file__).resolve().parents[2]


def run(cmd, cwd, env=None, timeout=1800):
    r = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True,
                       timeout=timeout)
    assert r.returncode == 0, f"{cmd}: exit {r.returncode}\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    return r


def test_wheel_in_a_fresh_venv_runs_solve_check_and_the_readme(tmp_path):
    wheels = tmp_path / "wheels"
    # -i: the interpreter `maturin develop` built the extension for (harness/setup.sh, in .venv).
    # Without it maturin picks another python3, pyo3's build script sees PYO3_PYTHON change and
    # pyo3, numpy and the bindings compile again (about 130 s of CPU on a fresh clone's CI).
    run([sys.executable, "-m", "maturin", "build", "--release", "-q", "-i", sys.executable, "-o", wheels], cwd=ROOT)
    (wheel,) = wheels.glob("progmo-*.whl")
    venv = tmp_path / "venv"
    run([sys.executable, "-m", "venv", venv], cwd=tmp_path)
    py, exe = venv / "bin" / "python", venv / "bin" / "progmo"
    run([py, "-m", "pip", "install", "-q", "-c", ROOT / "harness" / "constraints.txt", wheel], cwd=tmp_path)

    work = tmp_path / "work"
    work.mkdir()
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PROGMO_REFERENCES", "PROGMO_PYTHON", "VIRTUAL_ENV")}
    env.update(MPLBACKEND="Agg", PATH=f"{venv / 'bin'}:{env.get('PATH', '')}")
    where = run([py, "-c", "import progmo; print(progmo.__file__)"], cwd=work, env=env).stdout.strip()
    assert where.startswith(str(venv)), where  # the installed package, not the checkout

    # the bench's C++ anchor source, its Eigen installer and the accepted figures ship in the package
    run([py, "-c", "from progmo.bench import anchor, targets; assert anchor.SOURCE.is_file(), anchor.SOURCE; "
         "assert anchor.INSTALL_EIGEN.is_file(); targets.load_accepted()"], cwd=work, env=env)

    # a bundled scene whose robot file (MJCF) ships beside it in the package
    r = run([exe, "validate", "mjcf_arm"], cwd=work, env=env)
    assert "mjcf_arm: ok: nq = 6" in r.stdout

    r = run([exe, "solve", "double_pendulum"], cwd=work, env=env)
    assert "double_pendulum: success" in r.stdout
    assert {p.name for p in (work / "out" / "double_pendulum").iterdir()} >= {
        "trajectory.csv", "summary.json", "recording.mcap"}

    r = run([exe, "check", "double_pendulum", "--no-plots"], cwd=work, env=env)
    assert "PASS: 2 of 2 (scene x simulator) passed" in r.stdout, r.stdout + r.stderr
    # compared with the baselines the package ships (not skipped for want of a checkout)
    meta = json.loads((work / "out" / "check" / "run.json").read_text())
    assert meta["provenance"]["baselines"].startswith(str(venv)), meta["provenance"]["baselines"]
    assert len(meta["comparisons"]) == 2
    assert all(m["state"] != "new" for c in meta["comparisons"] for m in c["metrics"]), meta["comparisons"]

    r = run([py, "-c", readme_snippet()], cwd=work, env=env)
    assert r.stdout.splitlines()[0] == "success 10.0 (1001, 2)"
    assert (work / "u.png").is_file()
