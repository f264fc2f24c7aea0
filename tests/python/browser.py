"""Headless Chromium for the page tests (test_report.py, test_bench_page.py)."""

import pathlib
import shutil
import subprocess

ROOT = pathlib.Path(__file__).resolve().parents[2]
NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def find_browser() -> str | None:
    """A Chromium on PATH, else one installed by harness/install_chromium.sh, else None."""
    for name in NAMES:
        if shutil.which(name):
            return shutil.which(name)
    subprocess.run(["bash", str(ROOT / "harness" / "install_chromium.sh")], capture_output=True, timeout=600)
    for name in NAMES:
        if shutil.which(name):
            return shutil.which(name)
    return None
