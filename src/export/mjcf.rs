//! MJCF writer (MuJoCo 4.0).

use super::{
    attractor_forces, check_options, children, esc, floored, num, nums, Conversion, CoordMap,
    ExportError, ExportOptions, ExportReport, Format,
};
use crate::tree::{JointType, Model};
use std::fmt::Write;

/// MJCF document reproducing `tree` as ideal rigid-body dynamics, and its [`ExportReport`].
///
/// Radians; RK4; contact, limit, equality, frictionloss and autoreset disabled; spring/damper
/// disabled unless a joint has a stiffness/damping (then `stiffness`/`springref`/`damping` are on the
/// joints); actuation left enabled (`mjcb_control` needs it); armature 0; explicit `<inertial>`
/// (mass floor: see the module doc); joints of a body in sequence in one `<body>` (MuJoCo composes
/// them like our model); hinge/ball `pos` = our anchor. MuJoCo's qpos/qvel use our conventions
/// (ball/free quaternion w, x, y, z; free linear velocity world-frame), so the maps are
/// permutations only (DFS body order).
pub fn mjcf(tree: &Model, options: &ExportOptions) -> Result<(String, ExportReport), ExportError> {
    check_options(options)?;
    let has_spring = tree.joints().iter().any(|j| j.stiffness != 0.0);
    let has_damper = tree.joints().iter().any(|j| j.damping != 0.0);
    let g = tree.fields().gravity;
    let mut x = String::new();
    let _ = writeln!(x, "<mujoco model=\"{}\">", esc(&options.name));
    let _ = writeln!(
        x,
        "  <compiler angle=\"radian\" inertiafromgeom=\"false\" autolimits=\"false\"/>"
    );
    let _ = writeln!(
        x,
        "  <option integrator=\"RK4\" timestep=\"{}\" gravity=\"{}\">",
        num(options.timestep),
        nums(&g)
    );
    let onoff = |b: bool| if b { "enable" } else { "disable" };
    let _ = writeln!(
        x,
        "    <flag contact=\"disable\" limit=\"disable\" equality=\"disable\" \
         frictionloss=\"disable\" spring=\"{}\" damper=\"{}\" autoreset=\"disable\"/>",
        onoff(has_spring),
        onoff(has_damper)
    );
    let _ = writeln!(x, "  </option>");
    let _ = writeln!(x, "  <worldbody>");

    let mut report = ExportReport {
        format: Format::Mjcf,
        mass_changes: vec![],
        harness_forces: attractor_forces(tree),
        q_map: Vec::new(),
        v_map: Vec::new(),
        gravity: g,
        root_joint: None,
        notes: vec![
            "qpos/qvel conventions equal ours (quaternions w, x, y, z; free joint linear velocity \
             world-frame, angular body-frame)"
                .into(),
            "no actuators: write generalized forces to d.qfrc_applied".into(),
        ],
    };
    let mut qmap = vec![None; tree.nq()];
    let mut vmap = vec![None; tree.nv()];
    let (mut sq, mut sv) = (0usize, 0usize);
    let ch = children(tree);
    let n = tree.bodies().len();
    // Preorder DFS; MuJoCo numbers joints in the same order.
    let mut stack: Vec<(usize, usize, bool)> =
        ch[n].iter().rev().map(|&b| (b, 2usize, false)).collect();
    while let Some((b, depth, closing)) = stack.pop() {
        let ind = "  ".repeat(depth);
        if closing {
            let _ = writeln!(x, "{ind}</body>");
            continue;
        }
        let body = &tree.bodies()[b];
        let _ = writeln!(
            x,
            "{ind}<body name=\"{}\" pos=\"{}\" quat=\"{}\">",
            esc(&body.name),
            nums(body.pos.as_slice()),
            nums(&body.quat)
        );
        let (mass, inertia, change) = floored(body, options);
        report.mass_changes.extend(change);
        let diag = inertia[(0, 1)] == 0.0 && inertia[(0, 2)] == 0.0 && inertia[(1, 2)] == 0.0;
        // fullinertia order: ixx iyy izz ixy ixz iyz (about the CoM, body frame).
        let inert = if diag {
            format!(
                "diaginertia=\"{}\"",
                nums(&[inertia[(0, 0)], inertia[(1, 1)], inertia[(2, 2)]])
            )
        } else {
            format!(
                "fullinertia=\"{}\"",
                nums(&[
                    inertia[(0, 0)],
                    inertia[(1, 1)],
                    inertia[(2, 2)],
                    inertia[(0, 1)],
                    inertia[(0, 2)],
                    inertia[(1, 2)]
                ])
            )
        };
        let _ = writeln!(
            x,
            "{ind}  <inertial pos=\"{}\" mass=\"{}\" {inert}/>",
            nums(body.com.as_slice()),
            num(mass)
        );
        for j in body.joints.clone() {
            let jt = &tree.joints()[j];
            let (ty, geo) = match jt.joint_type() {
                JointType::Hinge { axis } => (
                    "hinge",
                    format!(
                        " axis=\"{}\" pos=\"{}\"",
                        nums(&axis),
                        nums(jt.anchor.as_slice())
                    ),
                ),
                JointType::Slide { axis } => ("slide", format!(" axis=\"{}\"", nums(&axis))),
                JointType::Ball => ("ball", format!(" pos=\"{}\"", nums(jt.anchor.as_slice()))),
                JointType::Free => ("free", String::new()),
            };
            let mut dyn_ = String::from(" armature=\"0\"");
            if jt.damping != 0.0 {
                let _ = write!(dyn_, " damping=\"{}\"", num(jt.damping));
            }
            if jt.stiffness != 0.0 {
                let _ = write!(
                    dyn_,
                    " stiffness=\"{}\" springref=\"{}\"",
                    num(jt.stiffness),
                    num(jt.spring_ref)
                );
            }
            let _ = writeln!(
                x,
                "{ind}  <joint name=\"{}\" type=\"{ty}\"{geo}{dyn_}/>",
                esc(&jt.name)
            );
            for k in 0..jt.nq {
                qmap[jt.iq + k] = Some((sq + k, jt.name.clone()));
            }
            for k in 0..jt.nv {
                vmap[jt.iv + k] = Some((sv + k, jt.name.clone()));
            }
            sq += jt.nq;
            sv += jt.nv;
        }
        stack.push((b, depth, true));
        for &c in ch[b].iter().rev() {
            stack.push((c, depth + 1, false));
        }
    }
    let _ = writeln!(x, "  </worldbody>");
    let _ = writeln!(x, "</mujoco>");
    let mk = |names: &[String], m: Vec<Option<(usize, String)>>| {
        m.into_iter()
            .enumerate()
            .map(|(i, e)| {
                let (sim_index, sim_joint) = e.expect("every joint is written");
                CoordMap {
                    index: i,
                    name: names[i].clone(),
                    sim_index,
                    sim_joint,
                    conversion: Conversion::Same,
                }
            })
            .collect::<Vec<_>>()
    };
    report.q_map = mk(tree.q_names(), qmap);
    report.v_map = mk(tree.v_names(), vmap);
    Ok((x, report))
}
