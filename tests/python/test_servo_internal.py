"""passive_arm (issue 17): a programme with a non-trivial, stable internal dynamics (the passive damped
third link) replays open-loop over its whole span in both simulators; a torque on the passive joint
must fail the check (negative control)."""

from __future__ import annotations

import numpy as np
import pytest

from progmo import Scene
from progmo.checks import CheckOptions, _run, run_check
from progmo.data import scene_file

BOTH = ("mujoco", "pinocchio")


@pytest.mark.parametrize("sim", BOTH)
def test_passive_arm_replays_over_its_whole_span(sim):
    r = run_check(str(scene_file("passive_arm")), sim)
    assert r.status == "pass", (r.reason, r.metrics)
    assert r.metrics["replay_unactuated"] == 0.0
    assert list(r.span) == [4.0, 4.0], "checked over the whole span (no replay_horizon)"


@pytest.mark.parametrize("sim", BOTH)
def test_a_torque_on_the_passive_joint_fails_the_check(sim):
    s = Scene(str(scene_file("passive_arm")))
    push = np.zeros(len(s.v_names))
    push[s.v_names.index("q3")] = 1e-6
    r, _ = _run(str(scene_file("passive_arm")), sim, CheckOptions(horizon=1.0, step=1.25e-3),
                corrupt_u=lambda t, u: u + push)
    assert r.status == "fail", (r.reason, r.metrics)
    assert "replay_unactuated" in r.reason
