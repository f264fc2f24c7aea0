"""The README's Python section runs as written (from a temporary directory)."""

import os
import pathlib
import re
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]


def readme_snippet() -> str:
    text = (ROOT / "README.md").read_text()
    section = text.split("\n## Python\n", 1)[1]
    m = re.search(r"```python\n(.*?)```", section, re.S)
    assert m, "README: no python block under ## Python"
    return m.group(1)


def test_readme_python_snippet_runs(tmp_path):
    env = dict(os.environ, MPLBACKEND="Agg")
    r = subprocess.run([sys.executable, "-c", readme_snippet()], cwd=tmp_path, env=env,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[0] == "success 10.0 (1001, 2)"
    assert r.stdout.splitlines()[1].startswith("pass ")
    assert (tmp_path / "u.png").stat().st_size > 1000 and (tmp_path / "trajectory.csv").is_file()
