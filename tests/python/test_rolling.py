"""Reactions supplied by progmo (issue 28 item 4): system rows no simulator holds (here the
``rolling`` closure of the catalog's ``rolling_disk``) are left out of the simulator's model and
their generalized reaction B_s^T lambda_s from the reference solve is applied with u, labelled in
the verdict. The rolling disk passes in both simulators that way; negative controls: a wrong mass
in the exported document fails (parity, and the replay leaves the rows), and so does the replay
without the supplied reactions."""

import re

import numpy as np
import pytest

import progmo
from progmo.checks import CheckOptions, _run, run_check
from progmo.data import scene_file

BOTH = ["mujoco", "pinocchio"]
ROWS = ["roll_n", "roll_u", "roll_v"]


def test_the_export_door_refuses_and_the_supplying_route_lists_the_rows():
    scene = progmo.load("rolling_disk")
    with pytest.raises(progmo.ExportUnsupported, match="rolling closure 'roll'"):
        scene.export("mjcf")
    for fmt in ("mjcf", "urdf"):
        _, report = scene.export(fmt, supply_reactions=True)
        sup = [hf for hf in report["harness_forces"] if hf["kind"] == "supplied_reaction"]
        assert [hf["rows"] for hf in sup] == [ROWS] and "rolling closure `roll`" in sup[0]["reason"]
        assert report["closures"] == []


@pytest.mark.parametrize("sim", BOTH)
def test_rolling_disk_passes_with_its_reactions_supplied(sim):
    r = run_check(str(scene_file("rolling_disk")), sim)
    assert r.status == "pass", (r.reason, r.metrics)
    assert r.supplied == ROWS
    assert any("reactions of rows roll_n, roll_u, roll_v supplied by progmo" in n for n in r.notes), r.notes
    # the rows hold on the replay though the simulator knows nothing of them
    assert r.info["replay_supplied_residual"] < 1e-9, r.info


def _wrong_mass(doc: str) -> str:
    """The disk 10 % heavier in the exported document (MJCF `mass="2.0"`, URDF `<mass value="2.0"/>`)."""
    out, n = re.subn(r'(mass(?: value)?=")2\.0(")', r"\g<1>2.2\g<2>", doc)
    assert n == 1, doc
    return out


@pytest.mark.parametrize("sim", BOTH)
def test_a_wrong_mass_in_the_simulator_fails(sim):
    r, _ = _run(str(scene_file("rolling_disk")), sim, corrupt_export=_wrong_mass)
    assert r.status == "fail", (r.reason, r.metrics)
    assert "parity_mass" in {b.metric for b in r.breaches}, r.reason


@pytest.mark.parametrize("sim", BOTH)
def test_a_wrong_mass_leaves_the_rows_on_the_replay(sim, monkeypatch):
    """Past the parity gate (switched off here), the replay itself sees the wrong mass: the supplied
    contact force no longer carries the disk, which leaves the plane."""
    from progmo import checks

    monkeypatch.setattr(checks, "_parity", lambda c: None)
    r, _ = _run(str(scene_file("rolling_disk")), sim, CheckOptions(horizon=1.0), corrupt_export=_wrong_mass)
    assert r.status == "fail", (r.reason, r.metrics)
    assert {"replay_residual", "replay_deviation"} <= {b.metric for b in r.breaches}, r.reason
    assert r.info["replay_supplied_residual"] > 1e-3


@pytest.mark.parametrize("sim", BOTH)
def test_without_the_supplied_reactions_the_replay_fails(sim):
    r, _ = _run(str(scene_file("rolling_disk")), sim, CheckOptions(horizon=1.0),
                withhold=("supplied_reaction",))
    assert r.status == "fail", (r.reason, r.metrics)
    assert any("NEGATIVE CONTROL" in n for n in r.notes)
    assert "replay_residual" in {b.metric for b in r.breaches}, r.reason


def test_the_supplied_reaction_is_the_closed_form_contact_force():
    """What the harness feeds the simulators, against Newton-Euler (tests/rolling.rs): the linear
    part of B_s^T lambda_s on the free joint is the contact force m g e_3 + m Omega^2 rho n_c."""
    from progmo.checks import supplied_reactions

    scene = progmo.load("rolling_disk")
    p = dict(scene.parameters)
    sol = scene.solve(rtol=1e-11, atol=1e-13)
    t, q, v = np.asarray(sol.t), np.asarray(sol.q), np.asarray(sol.v)
    r = supplied_reactions(scene, ROWS, t, q, v, np.asarray(sol.lambda_))
    m, g, W, rho = p["m"], p["g"], p["Omega"], p["rho"]
    force = np.stack([-m * W**2 * rho * np.cos(W * t), -m * W**2 * rho * np.sin(W * t), m * g + 0 * t], axis=1)
    assert np.abs(r[:, :3] - force).max() < 1e-8 * m * g
    assert np.abs(r - np.asarray(sol.reactions)).max() < 1e-12 * m * g  # every system row is supplied
