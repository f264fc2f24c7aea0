"""`progmo corpus` (issue 30 item 3): a bounded sample of example-robot-data, the table's structure,
a negative control (the simulators read a URDF with perturbed masses: parity must fail), --data
discovery, and a missing collection listed as not installed."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from progmo import corpus, data

UR5 = "example-robot-data/robots/ur_description/urdf/ur5_robot.urdf"

PENDULUM = """<mujoco model="pendulum">
  <worldbody>
    <body name="link1" pos="0 0 1">
      <joint name="j1" type="hinge" axis="0 1 0" damping="0.3"/>
      <inertial pos="0 0 -0.4" mass="1.2" diaginertia="0.02 0.03 0.01"/>
      <body name="link2" pos="0 0 -0.8">
        <joint name="j2" type="hinge" axis="1 0 0" armature="0.01"/>
        <inertial pos="0.01 0 -0.25" mass="0.7" diaginertia="0.015 0.014 0.002"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.05" contype="0" conaffinity="0"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


FREE_BODY = """<mujoco model="free_body">
  <worldbody>
    <body name="trunk" pos="0 0 1">
      <freejoint name="root"/>
      <inertial pos="0.05 0 0" mass="2" diaginertia="0.02 0.03 0.04"/>
      <body name="leg" pos="0.2 0 0">
        <joint name="hip" axis="0 1 0"/>
        <inertial pos="0 0 -0.1" mass="0.5" diaginertia="0.002 0.002 0.001"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def _ur5() -> Path:
    return next(d / UR5 for d in data.robot_path() if (d / UR5).is_file())


def test_sample_of_example_robot_data(tmp_path, capsys):
    assert corpus.main(["-c", "example-robot-data", "--sample", "3", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr()
    assert "| collection | files | imports | imported | import rate |" in out.out
    assert re.search(r"\[example-robot-data 3/3\]", out.err)  # progress on stderr
    doc = json.loads((tmp_path / "corpus.json").read_text())
    assert (tmp_path / "corpus.md").read_text().startswith("# progmo corpus")
    (row,) = doc["collections"]
    assert row["collection"] == "example-robot-data" and row["status"] == "ok" and row["files"] == 3
    for key in ("imports", "imported", "import_rate", "parity_checked", "mujoco_within", "pinocchio_within",
                "worst_parity", "refusals", "free_base"):
        assert key in row
    assert row["imported"] >= 2 and row["parity_checked"] >= 1
    judged = [r["parity"][s] for r in doc["files"] if r["parity"] for s in corpus.SIMULATORS
              if r["parity"][s]["status"] == "ok"]
    assert judged and all(p["worst"] <= corpus.PARITY_TOL for p in judged)
    assert all(r["error"] is None or {"kind", "location", "message", "reason"} <= set(r["error"]) for r in doc["files"])
    free = [r for r in doc["files"] if r.get("note") == corpus.FREE_BASE]
    assert free and all(r["parity"] for r in free)  # free roots: compared too


def test_negative_control_perturbed_mass_is_outside_tolerance(tmp_path):
    urdf = _ur5()
    bad = tmp_path / "ur5_heavier.urdf"
    bad.write_text(re.sub(r'(<mass value=")([0-9.eE+-]+)"',
                          lambda m: f'{m[1]}{float(m[2]) * 1.01!r}"', urdf.read_text()))
    free = tmp_path / "free.xml"
    free.write_text(FREE_BODY)
    heavier = tmp_path / "free_heavier.xml"
    heavier.write_text(FREE_BODY.replace('mass="2"', 'mass="2.02"'))
    goods = corpus.check_file("urdf", urdf, tmp_path) + corpus.check_file("mjcf", free, tmp_path)
    worses = (corpus.check_file("urdf", urdf, tmp_path, simulator_file=bad)
              + corpus.check_file("mjcf", free, tmp_path, simulator_file=heavier))
    assert [r.get("note") for r in goods] == [None, corpus.FREE_BASE]
    for good, worse in zip(goods, worses):  # a free base is judged as a fixed one is
        for s in corpus.SIMULATORS:
            assert good["parity"][s]["worst"] <= corpus.PARITY_TOL, (good["file"], s)
            assert worse["parity"][s]["status"] == "ok" and worse["parity"][s]["worst"] > 1e-4
    row = corpus.summarize("negative", 2, worses)
    assert row["mujoco_within"] == row["pinocchio_within"] == 0 and row["worst_parity"] > 1e-4


def test_data_folder_is_searched(tmp_path):
    assets = tmp_path / "data" / "gymnasium" / "gymnasium" / "envs" / "mujoco" / "assets"
    assets.mkdir(parents=True)
    (assets / "pendulum.xml").write_text(PENDULUM)
    rows, records = corpus.run([c for c in corpus.COLLECTIONS if c.name == "gymnasium"], tmp_path / "data",
                               False, None, 2, lambda s: None)
    assert rows[0]["imported"] == 1 and rows[0]["parity_checked"] == 1
    assert rows[0]["mujoco_within"] == rows[0]["pinocchio_within"] == 1
    assert records[0]["relpath"] == "pendulum.xml"


def test_missing_collection_is_listed_not_installed(tmp_path, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    assert corpus.main(["--data", str(empty), "--data-only", "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    doc = json.loads((tmp_path / "out" / "corpus.json").read_text())
    assert [r["collection"] for r in doc["collections"]] == corpus.NAMES  # none dropped
    for r in doc["collections"]:
        assert r["status"].startswith("not installed") and "pip install" in r["status"]
        assert r["collection"] in out
    assert "pip install example-robot-data" in out


def test_bad_usage(tmp_path, capsys):
    assert corpus.main(["--data", str(tmp_path / "nowhere"), "--out", str(tmp_path)]) == 2
    assert "not a folder" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        corpus.main(["-c", "nosuch"])


def test_sample_is_deterministic_and_spread():
    files = [Path(f"f{i:02}") for i in range(10)]
    assert corpus.sample(files, 3) == [files[0], files[4], files[9]]  # linspace 0, 4.5, 9 rounded to even
    assert corpus.sample(files, 3) == corpus.sample(list(files), 3)
    assert corpus.sample(files, None) == files and corpus.sample(files, 50) == files


def test_refusals_mujoco_shares_are_told_apart(tmp_path):
    """A refused import is asked of MuJoCo's compiler too: an inertia with a negative eigenvalue is
    the file's defect (MuJoCo refuses it as well) and leaves the second rate; a refusal of progmo's
    alone (here: a joint named `t`, which rows cannot write; MuJoCo compiles the file) stays in it."""
    link = ('<link name="{n}"><inertial><mass value="1"/><inertia ixx="{i}" ixy="0" ixz="0" iyy="0.1" '
            'iyz="0" izz="0.1"/></inertial></link>')
    def robot(name: str, inertia: str, joint: str) -> Path:
        f = tmp_path / f"{name}.urdf"
        f.write_text(f'<robot name="{name}">' + link.format(n="a", i="0.1") + link.format(n="b", i=inertia)
                     + f'<joint name="{joint}" type="revolute"><parent link="a"/><child link="b"/>'
                     '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>')
        return f
    defect = corpus.check_file("urdf", robot("defect", "-0.05", "j"), tmp_path)
    alone = corpus.check_file("urdf", robot("alone", "0.1", "t"), tmp_path)
    fine = corpus.check_file("urdf", robot("fine", "0.1", "j"), tmp_path)
    assert not any(r["imported"] for r in defect + alone) and all(r["imported"] for r in fine)
    assert all("eigenvalue" in r["mujoco_refuses"] for r in defect), defect
    assert all(r["mujoco_refuses"] is None for r in alone), alone
    row = corpus.summarize("mixed", 3, defect + alone + fine)
    assert row["imports"] == 6 and row["imported"] == 2 and row["refused_by_mujoco_too"] == 2
    assert row["import_rate"] == pytest.approx(2 / 6) and row["import_rate_mujoco_compiles"] == pytest.approx(2 / 4)
    md = corpus.table([row])
    assert "| mixed | 3 | 6 | 2 | 33% | 2 | 50% |" in md and "refuses too" in md


def test_bench_targets_judge_the_rates_and_parity():
    """The bench page's corpus targets: 95 % per collection and every comparison within 1e-12; a
    sampled run is not measured; a collection below the rate is named in the verdict."""
    from progmo.bench import targets as tg

    ok = {"status": "ok", "worst": 1e-15}
    def rec(imported: bool, worst: float = 1e-15) -> dict:
        p = {"mujoco": {**ok, "worst": worst}, "pinocchio": {**ok, "worst": worst}} if imported else None
        return {"imported": imported, "parity": p, "error": None if imported else {"reason": "r"},
                "mujoco_refuses": None}
    full = corpus.summarize("full", 20, [rec(True)] * 20)
    low = corpus.summarize("low", 20, [rec(True)] * 18 + [rec(False)] * 2)
    off = corpus.summarize("off", 2, [rec(True), rec(True, worst=1e-9)])
    rate, parity = tg.corpus_targets([full])
    assert rate.met and parity.met and "full 20/20 (100%" in rate.measured
    rate, parity = tg.corpus_targets([full, low])
    assert not rate.met and rate.verdict == "MISSED: low 90%" and parity.met
    rate, parity = tg.corpus_targets([off])
    assert rate.met and parity.verdict == "MISSED: 2 outside"
    assert all(t.status == "not measured" for t in tg.corpus_targets([full], "a sample of 2 files"))
    assert all(t.status == "not measured" for t in tg.corpus_targets([]))


def test_pybullet_and_robosuite_layouts_are_found(tmp_path):
    """pybullet_data's generated objects (random_urdfs) are their own collection, not hidden in the
    robots' rate; robosuite's robots are each folder's robot.xml."""
    pb = tmp_path / "pybullet_data"
    (pb / "random_urdfs" / "000").mkdir(parents=True)
    (pb / "kuka").mkdir()
    urdf = _ur5().read_text()
    (pb / "kuka" / "arm.urdf").write_text(urdf)
    (pb / "random_urdfs" / "000" / "000.urdf").write_text(urdf)
    rs = tmp_path / "robosuite" / "models" / "assets" / "robots" / "arm"
    rs.mkdir(parents=True)
    (rs / "robot.xml").write_text(PENDULUM)
    (rs / "other.xml").write_text(PENDULUM)
    by = {c.name: c for c in corpus.COLLECTIONS}
    _, robots, _ = corpus.find(by["pybullet_data"], tmp_path, installed=False)
    _, objects, _ = corpus.find(by["pybullet_data/random_urdfs"], tmp_path, installed=False)
    _, suite, _ = corpus.find(by["robosuite"], tmp_path, installed=False)
    assert [f.relative_to(pb).as_posix() for f in robots] == ["kuka/arm.urdf"]
    assert [f.relative_to(pb).as_posix() for f in objects] == ["random_urdfs/000/000.urdf"]
    assert [f.name for f in suite] == ["robot.xml"]


class _Flat:
    """A scene and back-end stub whose G + Q is of round-off size (a wheel turning about its axis)."""
    t0 = 0.0
    q0 = [0.0]
    v_names = ["wheel"]

    def __init__(self, sim_rhs: float):
        self.sim_rhs = sim_rhs
        self.cm = type("cm", (), {"quats": []})()

    def dynamics(self, t, q, v):
        return {"mass": [[2.0]], "velocity_terms": [1e-20], "applied_forces": [0.0]}

    def model_terms(self, t, q, v):
        return np.array([[2.0]]), np.array([self.sim_rhs])


def test_bias_of_round_off_size_is_judged_against_a_unit_acceleration():
    """Round-off against round-off (1e-20 vs -1e-18) is agreement: the bias is relative to max|A| x
    1 m/s^2 where G + Q is smaller; a real disagreement of that force's size still fails."""
    agree = corpus._compare(_Flat(1e-20), _Flat(-1e-18), 2, 0)
    assert agree["bias"] <= 1e-18
    differ = corpus._compare(_Flat(1e-20), _Flat(0.02), 2, 0)
    assert differ["bias"] == pytest.approx(0.01)
