"""MuJoCo equality 'connect' softness on the slider crank tree (slider_crank_tree.toml): replay
the solver's u(t) open-loop (per-stage via mjcb_control, RK4) and report max closure error."""
import csv, sys, numpy as np, mujoco
rows = list(csv.DictReader(open(sys.argv[1])))
T = np.array([float(r["t"]) for r in rows]); U = np.array([float(r["u:phi1"]) for r in rows])
X3 = np.array([float(r["q:x3"]) for r in rows])
from scipy.interpolate import CubicSpline
u = CubicSpline(T, U)
def mjcf(solref, solimp, h):
    return f"""<mujoco><compiler angle="radian"/>
<option timestep="{h}" integrator="RK4" solver="Newton" iterations="200" tolerance="1e-15" ls_tolerance="1e-15">
<flag contact="disable" limit="disable" frictionloss="disable" spring="disable" damper="disable" autoreset="disable"/></option>
<worldbody>
<body name="crank"><joint name="phi1" type="hinge" axis="0 0 1"/><inertial pos="0 0 0" mass="0.1" diaginertia="0.0013635 0.0013635 0.002727"/>
 <body name="rod" pos="0.15 0 0"><joint name="th" type="hinge" axis="0 0 1"/><inertial pos="0.15 0 0" mass="0.151104" diaginertia="0.0011340859 0.0011340859 0.0011340859"/><site name="a" pos="0.3 0 0"/></body></body>
<body name="slider"><joint name="x3" type="slide" axis="1 0 0"/><inertial pos="0 0 0" mass="0.075552" diaginertia="1e-4 1e-4 1e-4"/><site name="b"/></body>
</worldbody>
<equality><connect site1="a" site2="b" solref="{solref}" solimp="{solimp}"/></equality>
</mujoco>"""
def run(solref, solimp, h):
    m = mujoco.MjModel.from_xml_string(mjcf(solref, solimp, h)); d = mujoco.MjData(m)
    d.qpos[:] = [0, 0, 0.45]; d.qvel[:] = [150, -225, 0]
    mujoco.set_mjcb_control(lambda m, d: d.qfrc_applied.__setitem__(0, u(d.time)))
    err = 0.0; n = int(round(0.1 / h)); dev = 0.0
    try:
        for k in range(n):
            d.time = k * h
            mujoco.mj_step(m, d)
            mujoco.mj_kinematics(m, d)
            # closure: rod end vs slider origin
            pa = d.xpos[2] + d.xmat[2].reshape(3, 3) @ np.array([0.3, 0, 0]); pb = d.xpos[3]
            err = max(err, np.linalg.norm(pa - pb))
            t = (k + 1) * h
            dev = max(dev, abs(d.qpos[2] - np.interp(t, T, X3)))
    finally:
        mujoco.set_mjcb_control(None)
    return err, dev
print("mujoco", mujoco.__version__)
for h in (1e-3, 2.5e-4):
    for solref in (f"{2*h} 1", f"{4*h} 1", "0.02 1", "-1e6 -2e3"):
        for solimp in ("0.9 0.95 0.001", "0.9999 0.9999 0.001"):
            e, dev = run(solref, solimp, h)
            print(f"h={h:g} solref='{solref}' solimp='{solimp}': max closure error {e:.2e} m, max |x3 - solver| {dev:.2e} m")
