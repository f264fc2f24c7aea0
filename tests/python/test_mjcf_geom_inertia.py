"""Issue 30, item 1: MJCF mass properties from geoms (src/import/geom_inertia.rs) against MuJoCo's
own compile of the same file. Each file has a free root and ball joints below it, so every body's
mass, centre of mass and full inertia reach A (mj_fullM after mj_forward) and the gravity forces;
both agree with progmo's import at random states to 1e-12 relative (`worst` of
test_robot_files_mujoco.py). Covered: every primitive type, fromto for capsule, cylinder, box and
ellipsoid, each orientation form, several geoms in one body (mass or density, density 0, a
non-colliding geom, groups), shellinertia, geom defaults (classes, childclass, a partial size,
default orientation and fromto), inertiafromgeom true/false, inertiagrouprange, boundmass and
boundinertia, settotalmass. Negative controls: a 1 % denser geom, a 1 % higher boundmass or total
mass, on MuJoCo's side fails.
"""

import pytest

from test_robot_files_mujoco import mjcf_scene, worst

mujoco = pytest.importorskip("mujoco")

TOL = 1e-12

SHAPES = """<mujoco>
  <worldbody>
    <body name="root" pos="0 0 1" euler="5 10 15">
      <freejoint name="root"/>
      <geom type="sphere" size="0.07" pos="0.01 0.02 0.03"/>
      <body name="capsule" pos="0 0 -0.2">
        <joint name="b1" type="ball"/>
        <geom type="capsule" size="0.03 0.1" pos="0.02 0 -0.1" euler="20 -30 40"/>
        <body name="cylinder" pos="0 0.1 -0.2">
          <joint name="b2" type="ball"/>
          <geom type="cylinder" size="0.04 0.12" axisangle="1 2 3 50" pos="0 0.01 -0.05"/>
          <body name="box" pos="0.1 0 -0.2">
            <joint name="b3" type="ball"/>
            <geom type="box" size="0.05 0.02 0.08" quat="0.9 0.1 -0.3 0.2" pos="0.03 0 0" mass="0.7"/>
            <body name="ellipsoid" pos="0 0 -0.2">
              <joint name="b4" type="ball"/>
              <geom type="ellipsoid" size="0.03 0.05 0.09" xyaxes="0 1 0 -1 0.3 0.2" density="800"/>
              <body name="fromto" pos="0 0 -0.2">
                <joint name="b5" type="ball"/>
                <geom type="capsule" fromto="0 0 0 0.1 -0.05 -0.2" size="0.02"/>
                <geom type="cylinder" fromto="0.1 0.1 0 0 0 -0.1" size="0.015"/>
                <geom type="box" fromto="0 0 0 0 0 -0.15" size="0.02 0.07"/>
                <geom type="ellipsoid" fromto="-0.1 0 0 0 0.05 0.05" size="0.03 0.5"/>
                <body name="mixed" pos="0 0 -0.3">
                  <joint name="b6" type="ball"/>
                  <geom type="sphere" size="0.05" mass="0.4" pos="0.1 0 0"/>
                  <geom type="box" size="0.05 0.05 0.01" density="0" pos="-0.3 0 0"/>
                  <geom type="capsule" size="0.01 0.05" zaxis="1 1 0" contype="0" conaffinity="0"/>
                  <geom type="sphere" size="0.02" group="3" pos="0 0.1 0"/>
                  <geom type="cylinder" size="0.02 0.02" mass="0" pos="0 0 0.3"/>
                  <body name="shell" pos="0 0 -0.2">
                    <joint name="b7" type="ball"/>
                    <geom type="sphere" size="0.03" shellinertia="true" pos="0.05 0 0"/>
                    <geom type="capsule" size="0.02 0.04" shellinertia="true" euler="90 0 0"/>
                    <geom type="cylinder" size="0.02 0.05" shellinertia="true" pos="0 0 -0.05"/>
                    <geom type="box" size="0.02 0.03 0.04" shellinertia="true" pos="0 0.05 0"/>
                    <geom type="ellipsoid" size="0.02 0.03 0.04" shellinertia="true" pos="0 -0.05 0"/>
                  </body>
                </body>
              </body>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""

DEFAULTS = """<mujoco>
  <compiler angle="radian" eulerseq="zyx"/>
  <default>
    <geom type="capsule" size="0.02 0.1 0.3" density="500"/>
    <default class="limb">
      <geom size="0.03" euler="0.3 0.2 0.1"/>
      <default class="box"><geom type="box" size="0.04 0.05" mass="0.3"/></default>
    </default>
    <default class="rod"><geom type="cylinder" fromto="0 0 0 0.2 0 -0.1"/></default>
  </default>
  <worldbody>
    <body name="root" pos="0 0 1" childclass="limb">
      <freejoint name="root"/>
      <geom/>
      <body name="a" pos="0.1 0 -0.2">
        <joint name="a" type="ball"/>
        <geom class="box" pos="0 0.02 0"/>
        <geom class="main" pos="0.05 0 0" quat="0 0 0 1"/>
        <body name="b" pos="0 0 -0.2" childclass="rod">
          <joint name="b" type="ball"/>
          <geom size="0.01"/>
          <geom class="box" euler="0 0 0.5" pos="0 0 -0.1"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""

COMPILER = """<mujoco>
  <compiler inertiafromgeom="true" inertiagrouprange="0 2" boundmass="0.05" boundinertia="2e-4"/>
  <worldbody>
    <body name="root" pos="0 0 1">
      <freejoint name="root"/>
      <inertial pos="1 1 1" mass="9" diaginertia="1 1 1"/>
      <geom type="box" size="0.1 0.05 0.02"/>
      <geom type="sphere" size="0.1" group="3" pos="0.2 0 0"/>
      <body name="tiny" pos="0 0 -0.2">
        <joint name="tj" type="ball"/>
        <geom type="sphere" size="0.005" pos="0 0.01 0"/>
        <body name="empty" pos="0.1 -0.05 0.2" euler="10 20 30">
          <joint name="e" type="ball"/>
          <body name="kept" pos="0 0 -0.2">
            <joint name="k" type="ball"/>
            <inertial pos="0 0 -0.1" mass="0.5" diaginertia="1e-5 0.01 0.01"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


# settotalmass after the bounds (MuJoCo scales the bounded masses: the order is tested here)
TOTALMASS = COMPILER.replace('boundinertia="2e-4"/>', 'boundinertia="2e-4" settotalmass="3.7"/>')


@pytest.mark.parametrize("name,text", [("shapes", SHAPES), ("defaults", DEFAULTS), ("compiler", COMPILER),
                                       ("totalmass", TOTALMASS)])
def test_inertia_from_geoms_matches_mujoco(name, text, tmp_path):
    xml = tmp_path / f"{name}.xml"
    xml.write_text(text)
    g = [0.0, 0.0, -9.81]
    scene = mjcf_scene(tmp_path, xml, dict(gravity=g))
    model = mujoco.MjModel.from_xml_path(str(xml))
    model.opt.gravity[:] = g
    wa, wf = worst(scene, model, 30)
    print(f"{name}: inertia from geoms vs MuJoCo: |dA| {wa:.2e}, |d(G + Q)| {wf:.2e}")
    assert wa <= TOL and wf <= TOL, f"{name}: |dA| = {wa:.2e}, |d(G + Q)| = {wf:.2e}"


@pytest.mark.parametrize(
    "text,old,new",
    [(SHAPES, 'density="800"', 'density="808"'), (COMPILER, 'boundmass="0.05"', 'boundmass="0.0505"'),
     (TOTALMASS, 'settotalmass="3.7"', 'settotalmass="3.737"')],
    ids=["denser_geom", "higher_boundmass", "higher_totalmass"],
)
def test_negative_control_changed_file_in_mujoco_fails(text, old, new, tmp_path):
    xml = tmp_path / "file.xml"
    xml.write_text(text)
    g = [0.0, 0.0, -9.81]
    scene = mjcf_scene(tmp_path, xml, dict(gravity=g))
    model = mujoco.MjModel.from_xml_string(text.replace(old, new))
    model.opt.gravity[:] = g
    wa, wf = worst(scene, model, 30)
    assert wa > 1e3 * TOL and wf > 1e3 * TOL


@pytest.mark.parametrize("name,text", [("compiler", COMPILER), ("totalmass", TOTALMASS)])
def test_pinocchio_reading_with_another_mass_is_not_checked(name, text, tmp_path):
    # Pinocchio 4.1's MJCF reader derives geom masses its own way and ignores settotalmass: its
    # reading of such a file is declared not checked, with both totals, rather than failing the check
    from progmo.simulators import Unsupported
    from progmo.simulators.robot_file import RobotFile, pinocchio_model

    xml = tmp_path / f"{name}.xml"
    xml.write_text(text)
    with pytest.raises(Unsupported, match="moving mass .* MuJoCo's compile of it"):
        pinocchio_model(RobotFile(xml, "mjcf"), [0.0, 0.0, -9.81], None)
    # control: the same kind of file with explicit inertials only is read by Pinocchio
    explicit = tmp_path / "explicit.xml"
    explicit.write_text(EXPLICIT)
    assert pinocchio_model(RobotFile(explicit, "mjcf"), [0.0, 0.0, -9.81], None).model.nv == 7


EXPLICIT = """<mujoco>
  <worldbody>
    <body name="root" pos="0 0 1">
      <freejoint name="root"/>
      <inertial pos="0.1 0 0" mass="2" diaginertia="0.1 0.2 0.25"/>
      <geom type="sphere" size="0.1" mass="5"/>
      <body name="arm" pos="0 0 -0.2">
        <joint name="a" type="hinge" axis="0 1 0"/>
        <inertial pos="0 0 -0.1" mass="0.5" diaginertia="0.01 0.01 0.002"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""
