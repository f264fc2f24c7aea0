"""A check runner for the Ray fault test: the real ``run_check`` after a pause, so that a test can
kill the worker while a check is running (named by ``PROGMO_CHECK_RUNNER=slow_checks:run_check``;
the pause in seconds is ``$SLOW_CHECKS_PAUSE``, default 2)."""

from __future__ import annotations

import os
import time

from progmo.checks import run_check as _real


def run_check(path, simulator, options=None):
    time.sleep(float(os.environ.get("SLOW_CHECKS_PAUSE", "2")))
    return _real(path, simulator, options)
