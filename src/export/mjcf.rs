//! MJCF writer (MuJoCo 4.0).

use super::{
    attractor_forces, check_options, children, esc, floored, num, nums, ClosureExport, Conversion,
    CoordMap, ExportError, ExportOptions, ExportReport, Format, MUJOCO_SOLIMP, MUJOCO_SOLREF_STEPS,
};
use crate::tree::{JointType, Model};
use std::fmt::Write;

/// MJCF document reproducing `tree` as ideal rigid-body dynamics, and its [`ExportReport`].
///
/// Radians; RK4; contact, limit, equality, frictionloss and autoreset disabled; spring/damper
/// disabled unless a joint has a stiffness/damping (then `stiffness`/`springref`/`damping` are on the
/// joints; a body's gravcomp keeps the damper flag enabled: MuJoCo skips gravcomp with both off); actuation left enabled (`mjcb_control` needs it); `armature` as ours (written 0
/// otherwise), hinge/slide `ref` when nonzero (MuJoCo's meaning is ours: the joint moves by
/// qpos - ref), body `gravcomp` when nonzero (MuJoCo's passive force -gravcomp m g at the CoM, as
/// ours); explicit `<inertial>`
/// (mass floor: see the module doc); joints of a body in sequence in one `<body>` (MuJoCo composes
/// them like our model); hinge/ball `pos` = our anchor. MuJoCo's qpos/qvel use our conventions
/// (ball/free quaternion w, x, y, z; free linear velocity world-frame), so the maps are
/// permutations only (DFS body order).
pub fn mjcf(tree: &Model, options: &ExportOptions) -> Result<(String, ExportReport), ExportError> {
    mjcf_closed(tree, &[], options)
}

/// [`mjcf`] with loop closures (see [`ClosureExport`]): sites, `<equality>` elements, equality
/// enabled and the constraint solver at its tightest (Newton, 200 iterations, tolerance 1e-15).
/// A `distance` closure is [`ExportError::Unsupported`]: MuJoCo offers no exact one; nor does it
/// offer a point on a line or in a plane (`line`, `plane`) or rolling without slip (`rolling`).
pub fn mjcf_closed(
    tree: &Model,
    closures: &[ClosureExport],
    options: &ExportOptions,
) -> Result<(String, ExportReport), ExportError> {
    check_options(options)?;
    refuse_closures(closures, options)?;
    // sites per body index (tree.bodies().len(): the world)
    let sites = closure_sites(tree, closures)?;
    let g = tree.fields().gravity;
    let mut x = String::new();
    write_header(&mut x, tree, closures, options);
    let _ = writeln!(x, "  <worldbody>");
    for s in &sites[tree.bodies().len()] {
        let _ = writeln!(x, "    {s}");
    }

    let mut report = ExportReport {
        format: Format::Mjcf,
        mass_changes: vec![],
        harness_forces: attractor_forces(tree),
        q_map: Vec::new(),
        v_map: Vec::new(),
        gravity: g,
        root_joint: None,
        closures: vec![],
        armature: vec![],
        notes: vec![
            "qpos/qvel conventions equal ours (quaternions w, x, y, z; free joint linear velocity \
             world-frame, angular body-frame)"
                .into(),
            "no actuators: write generalized forces to d.qfrc_applied".into(),
        ],
    };
    let mut w = Bodies {
        tree,
        options,
        x,
        qmap: vec![None; tree.nq()],
        vmap: vec![None; tree.nv()],
        sq: 0,
        sv: 0,
    };
    let ch = children(tree);
    let n = tree.bodies().len();
    // Preorder DFS; MuJoCo numbers joints in the same order.
    let mut stack: Vec<(usize, usize, bool)> =
        ch[n].iter().rev().map(|&b| (b, 2usize, false)).collect();
    while let Some((b, depth, closing)) = stack.pop() {
        // indentation stops growing at MAX_INDENT levels: a deep chain's document stays linear
        let ind = "  ".repeat(depth.min(super::MAX_INDENT));
        if closing {
            let _ = writeln!(w.x, "{ind}</body>");
            continue;
        }
        w.write_body(b, &ind, &mut report);
        for s in &sites[b] {
            let _ = writeln!(w.x, "{ind}  {s}");
        }
        stack.push((b, depth, true));
        for &c in ch[b].iter().rev() {
            stack.push((c, depth + 1, false));
        }
    }
    let mut x = w.x;
    let _ = writeln!(x, "  </worldbody>");
    write_equalities(&mut x, closures, options);
    let _ = writeln!(x, "</mujoco>");
    report.q_map = coord_map(tree.q_names(), w.qmap);
    report.v_map = coord_map(tree.v_names(), w.vmap);
    if !closures.is_empty() {
        report.notes.push(format!(
            "closures: equality solref timeconst = {MUJOCO_SOLREF_STEPS} x timestep (keep the \
             ratio when replaying at another step), solimp {}",
            nums(&MUJOCO_SOLIMP)
        ));
    }
    report.closures = closures.to_vec();
    Ok((x, report))
}

/// The closures MuJoCo cannot hold exactly: distance, line, plane and rolling.
fn refuse_closures(closures: &[ClosureExport], options: &ExportOptions) -> Result<(), ExportError> {
    if let Some(c) = closures.iter().find(|c| c.kind == "distance") {
        return Err(ExportError::Unsupported {
            format: Format::Mjcf,
            what: format!(
                "distance closure '{}' of scene '{}': MuJoCo has no exact distance constraint (its \
                 fixed-length tendon equality leaves out the tendon's curvature term dJ/dt v: on a \
                 1 m pendulum at 1 m/s the closure force was off by m v^2/r, 33 %, and the loop \
                 drifted 7.9e-5 m at h = 1e-3, where connect holds to 2e-8 m; \
                 src/export/MUJOCO_CLOSURES.md): the scene stays solver-only in MuJoCo",
                c.name, options.name
            ),
        });
    }
    if let Some(c) = closures
        .iter()
        .find(|c| c.kind == "line" || c.kind == "plane")
    {
        return Err(ExportError::Unsupported {
            format: Format::Mjcf,
            what: format!(
                "{} closure '{}' of scene '{}': MuJoCo has no equality constraint holding a point \
                 on a line or in a plane of another body (connect, weld, joint, tendon and flex \
                 only): the scene stays solver-only in MuJoCo",
                c.kind, c.name, options.name
            ),
        });
    }
    if let Some(c) = closures.iter().find(|c| c.kind == "rolling") {
        return Err(ExportError::Unsupported {
            format: Format::Mjcf,
            what: format!(
                "rolling closure '{}' of scene '{}': MuJoCo has no rolling constraint (its \
                 contacts are soft and frictional, never an exact no-slip row)",
                c.name, options.name
            ),
        });
    }
    Ok(())
}

/// The `<site>` elements of the closures per body index (`tree.bodies().len()`: the world).
fn closure_sites(
    tree: &Model,
    closures: &[ClosureExport],
) -> Result<Vec<Vec<String>>, ExportError> {
    let body_of = |name: &str| {
        tree.body_id(name).ok_or_else(|| ExportError::Unsupported {
            format: Format::Mjcf,
            what: format!("closure body '{name}' is not in the tree"),
        })
    };
    let mut sites: Vec<Vec<String>> = vec![vec![]; tree.bodies().len() + 1];
    for c in closures {
        let site = |name: &str, p: &[f64; 3], q: &[f64; 4]| {
            format!(
                "<site name=\"{}\" pos=\"{}\" quat=\"{}\"/>",
                esc(name),
                nums(p),
                nums(q)
            )
        };
        sites[body_of(&c.body_a)?].push(site(&c.site_a, &c.point_a, &c.quat_a));
        let b = match &c.body_b {
            Some(b) => body_of(b)?,
            None => tree.bodies().len(),
        };
        sites[b].push(site(&c.site_b, &c.point_b, &c.quat_b));
    }
    Ok(sites)
}

/// `<mujoco>`, `<compiler>` and `<option>` with its flags.
fn write_header(x: &mut String, tree: &Model, closures: &[ClosureExport], options: &ExportOptions) {
    let has_spring = tree.joints().iter().any(|j| j.stiffness != 0.0);
    // MuJoCo 4.0 computes gravcomp in its passive forces, skipped when both the spring and the
    // damper flags are disabled (measured: qfrc_gravcomp = 0 then); the damper flag stays enabled
    // for it (with no joint damping it adds nothing).
    let has_gravcomp = tree.bodies().iter().any(|b| b.gravcomp != 0.0);
    let has_damper = tree.joints().iter().any(|j| j.damping != 0.0) || has_gravcomp;
    let g = tree.fields().gravity;
    let _ = writeln!(x, "<mujoco model=\"{}\">", esc(&options.name));
    let _ = writeln!(
        x,
        "  <compiler angle=\"radian\" inertiafromgeom=\"false\" autolimits=\"false\"/>"
    );
    let solver = if closures.is_empty() {
        String::new()
    } else {
        // the closures' constraint solve to round-off (MUJOCO_CLOSURES.md)
        " solver=\"Newton\" iterations=\"200\" tolerance=\"1e-15\" ls_tolerance=\"1e-15\" \
         jacobian=\"dense\""
            .to_string()
    };
    let _ = writeln!(
        x,
        "  <option integrator=\"RK4\" timestep=\"{}\" gravity=\"{}\"{solver}>",
        num(options.timestep),
        nums(&g)
    );
    let onoff = |b: bool| if b { "enable" } else { "disable" };
    let _ = writeln!(
        x,
        "    <flag contact=\"disable\" limit=\"disable\" equality=\"{}\" \
         frictionloss=\"disable\" spring=\"{}\" damper=\"{}\" autoreset=\"disable\"/>",
        onoff(!closures.is_empty()),
        onoff(has_spring),
        onoff(has_damper)
    );
    let _ = writeln!(x, "  </option>");
}

/// The writer of the `<body>` elements: the document so far, and the simulator offsets of the
/// q and v entries written (qpos, qvel offsets `sq`, `sv` of the next joint).
struct Bodies<'t> {
    tree: &'t Model,
    options: &'t ExportOptions,
    x: String,
    qmap: Vec<Option<(usize, String)>>,
    vmap: Vec<Option<(usize, String)>>,
    sq: usize,
    sv: usize,
}

impl Bodies<'_> {
    /// The opening `<body>` of body `b`, its `<inertial>` (mass floor in the report) and joints.
    fn write_body(&mut self, b: usize, ind: &str, report: &mut ExportReport) {
        let x = &mut self.x;
        let body = &self.tree.bodies()[b];
        let gravcomp = if body.gravcomp != 0.0 {
            format!(" gravcomp=\"{}\"", num(body.gravcomp))
        } else {
            String::new()
        };
        let _ = writeln!(
            x,
            "{ind}<body name=\"{}\" pos=\"{}\" quat=\"{}\"{gravcomp}>",
            esc(&body.name),
            nums(body.pos.as_slice()),
            nums(&body.quat)
        );
        let (mass, inertia, change) = floored(body, self.options);
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
            self.write_joint(j, ind);
        }
    }

    /// The `<joint>` element of our joint `j` and its entries in the q and v maps.
    fn write_joint(&mut self, j: usize, ind: &str) {
        let jt = &self.tree.joints()[j];
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
        let mut dyn_ = format!(" armature=\"{}\"", armature(jt.armature));
        if jt.reference != 0.0 {
            let _ = write!(dyn_, " ref=\"{}\"", num(jt.reference));
        }
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
            self.x,
            "{ind}  <joint name=\"{}\" type=\"{ty}\"{geo}{dyn_}/>",
            esc(&jt.name)
        );
        for k in 0..jt.nq {
            self.qmap[jt.iq + k] = Some((self.sq + k, jt.name.clone()));
        }
        for k in 0..jt.nv {
            self.vmap[jt.iv + k] = Some((self.sv + k, jt.name.clone()));
        }
        self.sq += jt.nq;
        self.sv += jt.nv;
    }
}

/// The report's map of our entries (`names`) to the simulator's (`m`: offset and joint).
fn coord_map(names: &[String], m: Vec<Option<(usize, String)>>) -> Vec<CoordMap> {
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
}

/// The armature attribute: `0` as before armature was modelled (documents stay byte-identical),
/// otherwise the shortest round-trip decimal.
fn armature(a: f64) -> String {
    if a == 0.0 {
        "0".into()
    } else {
        num(a)
    }
}

/// `<equality>` elements of the closures (point: `connect`, weld: `weld`, both over sites).
fn write_equalities(x: &mut String, closures: &[ClosureExport], o: &ExportOptions) {
    if closures.is_empty() {
        return;
    }
    let soft = format!(
        "solref=\"{} 1\" solimp=\"{}\"",
        num(MUJOCO_SOLREF_STEPS * o.timestep),
        nums(&MUJOCO_SOLIMP)
    );
    let _ = writeln!(x, "  <equality>");
    for c in closures {
        let (a, b) = (esc(&c.site_a), esc(&c.site_b));
        let n = esc(&c.name);
        match c.kind.as_str() {
            "point" => {
                let _ = writeln!(
                    x,
                    "    <connect name=\"{n}\" site1=\"{a}\" site2=\"{b}\" {soft}/>"
                );
            }
            "weld" => {
                let _ = writeln!(
                    x,
                    "    <weld name=\"{n}\" site1=\"{a}\" site2=\"{b}\" torquescale=\"1\" {soft}/>"
                );
            }
            _ => unreachable!(
                "distance, line, plane and rolling closures are refused before writing"
            ),
        }
    }
    let _ = writeln!(x, "  </equality>");
}
