//! Inverse dynamics (RNEA), joint-space inertia (CRBA) and the project-facing generalized forces
//! of `A(q) dv/dt - G(q, v) = Q(t, q, v)` (Do Sanh 1998, eq. 2.2).

use super::kinematics::{
    ensure_mat, ensure_vec, for_each_point_column, forward_acceleration, forward_kinematics,
    forward_velocity, point_in_link, TreeData,
};
use super::model::{JointKind, Model};
use super::spatial::{lift3, mv, Inertia, Motion, Xform};
use crate::scalar::{c, Scalar};
use nalgebra::{DMatrix, DVector, Vector3};

/// Recursive Newton-Euler inverse dynamics (Featherstone Table 5.1):
/// `tau = M(q) a + C(q, v) v + g(q)` for uniform gravity `gravity` (world frame, e.g. (0,0,-9.81)),
/// without joint springs/dampers, gravity compensation, attractions or external forces. `M`
/// includes the joints' armature: `tau_k += armature a_k` on each dof (MuJoCo's `mj_rne` plus
/// the armature term of `mj_inverse`). The result lives in `data`.
pub fn rnea<'d, S: Scalar>(
    model: &Model,
    data: &'d mut TreeData<S>,
    q: &[S],
    v: &[S],
    a: &[S],
    gravity: &Vector3<S>,
) -> &'d DVector<S> {
    forward_kinematics(model, data, q);
    forward_velocity(model, data, v);
    forward_acceleration(model, data, a, &Vector3::zeros());
    // body forces f_i = I_i (a_i - (0, R_i^T g)) + v_i x* I_i v_i: gravity as the base's upward
    // acceleration, which enters a_i as (0, -R_i^T g) (Featherstone 5.3; X_i (0, l) = (0, E_i l)),
    // added here so that a_i stay gravity-free for the point kinematics that read them
    for (i, link) in model.links.iter().enumerate() {
        let ld = &mut data.links[i];
        ld.f = match &link.inertia {
            Some(inr) => {
                let inr = Inertia::<S>::lift(inr);
                let ag = Motion::new(ld.a.ang, ld.a.lin - ld.rot.tr_mul(gravity));
                inr.mul_motion(&ag)
                    .add(&ld.v.cross_force(&inr.mul_motion(&ld.v)))
            }
            None => super::spatial::Force::zero(),
        };
    }
    // backward pass: tau_i = S_i^T f_i, f_λ += X_i^T f_i
    for i in (0..model.links.len()).rev() {
        let link = &model.links[i];
        let f = data.links[i].f;
        if let Some(j) = link.joint {
            let jt = &model.joints[j];
            for k in 0..jt.nv {
                data.tau[jt.iv + k] = data.links[i].s[k].dot(&f);
            }
            if jt.armature != 0.0 {
                for k in 0..jt.nv {
                    data.tau[jt.iv + k] += a[jt.iv + k] * c::<S>(jt.armature);
                }
            }
        }
        if let Some(p) = link.parent {
            let fp = data.links[i].x.transpose_force(&f);
            data.links[p].f = data.links[p].f.add(&fp);
        }
    }
    &data.tau
}

/// Composite-rigid-body algorithm (Featherstone Table 6.2): joint-space inertia matrix `M(q)`
/// (the paper's `A(q)`), symmetric `nv x nv`, plus each joint's armature on its dofs' diagonal. Written in world coordinates (as Pinocchio does):
/// composite inertias `Ic_i` and motion subspace columns `S_i` are expressed in the world frame,
/// so `M[j, i] = S_j . (Ic_i S_i)` for every ancestor joint j needs no transform along the way.
pub fn crba<S: Scalar>(model: &Model, data: &mut TreeData<S>, q: &[S], m: &mut DMatrix<S>) {
    forward_kinematics(model, data, q);
    let nv = model.nv();
    ensure_mat(m, nv, nv);
    m.fill(c(0.0));
    for (i, link) in model.links.iter().enumerate() {
        let ld = &mut data.links[i];
        let xw = Xform::from_pose(ld.rot, ld.pos);
        ld.ic = match &link.inertia {
            Some(inr) => Inertia::lift(inr).transform_to_parent(&xw),
            None => Inertia::zero(),
        };
        if let Some(j) = link.joint {
            for k in 0..model.joints[j].nv {
                ld.sw[k] = xw.inv_apply_motion(&ld.s[k]);
            }
        }
    }
    for i in (0..model.links.len()).rev() {
        if let Some(p) = model.links[i].parent {
            let ic = data.links[i].ic;
            data.links[p].ic = data.links[p].ic.add(&ic);
        }
    }
    for (i, link) in model.links.iter().enumerate() {
        if let Some(j) = link.joint {
            let jt = &model.joints[j];
            data.sw_dof[jt.iv..jt.iv + jt.nv].copy_from_slice(&data.links[i].sw[..jt.nv]);
        }
    }
    for col in 0..nv {
        let f = data.links[model.dof_link[col]]
            .ic
            .mul_motion(&data.sw_dof[col]);
        m[(col, col)] = data.sw_dof[col].dot(&f);
        let mut d = model.dof_parent[col];
        while let Some(r) = d {
            let val = data.sw_dof[r].dot(&f);
            m[(r, col)] = val;
            m[(col, r)] = val;
            d = model.dof_parent[r];
        }
    }
    for jt in model.joints.iter().filter(|j| j.armature != 0.0) {
        for k in jt.iv..jt.iv + jt.nv {
            m[(k, k)] += c::<S>(jt.armature);
        }
    }
}

/// `A(q)` of the paper: the mass matrix, by [`crba`].
pub fn mass_matrix<S: Scalar>(model: &Model, data: &mut TreeData<S>, q: &[S], a: &mut DMatrix<S>) {
    crba(model, data, q, a);
}

/// Bias force `C(q, v) v + g(q) = rnea(q, v, 0)` with the given uniform gravity.
pub fn bias<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    q: &[S],
    v: &[S],
    gravity: &Vector3<S>,
    out: &mut DVector<S>,
) {
    let zero = std::mem::take(&mut data.zero_v);
    rnea(model, data, q, v, &zero, gravity);
    data.zero_v = zero;
    data.acc_bias = true;
    ensure_vec(out, model.nv());
    out.copy_from(&data.tau);
}

/// `G(q, v)` of the paper: `-C(q, v) v = -rnea(q, v, 0)` without gravity.
pub fn velocity_terms<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    q: &[S],
    v: &[S],
    g: &mut DVector<S>,
) {
    bias(model, data, q, v, &Vector3::zeros(), g);
    g.neg_mut();
}

/// Generalized force of uniform gravity: `-g(q) = -rnea(q, 0, 0)` (sum of CoM Jacobian^T m g).
pub fn gravity_forces<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    q: &[S],
    gravity: &Vector3<S>,
    out: &mut DVector<S>,
) {
    let zero = std::mem::take(&mut data.zero_v);
    rnea(model, data, q, &zero, &zero, gravity);
    data.zero_v = zero;
    ensure_vec(out, model.nv());
    out.copy_from(&data.tau);
    out.neg_mut();
}

/// Adds to `out` the generalized force of a world-frame force applied at a body point (body
/// coordinates): `out += J_p(q)^T force` (point Jacobian transpose). Needs the positions of the
/// last [`forward_kinematics`] call at the same q (every `q`-taking function here runs it);
/// use [`body_point_force`] for a self-contained call.
pub(crate) fn add_point_force<S: Scalar>(
    model: &Model,
    data: &TreeData<S>,
    body: usize,
    point: &Vector3<S>,
    force: &Vector3<S>,
    out: &mut DVector<S>,
) {
    let ld = &data.links[model.body_link[body]];
    let pw = ld.pos + mv(&ld.rot, &point_in_link(model, body, point));
    for_each_point_column(model, data, body, &pw, |k, _w, lin| {
        out[k] += lin.dot(force);
    });
}

/// External force hook: adds `J_p(q)^T force` to `out` for a world-frame `force` applied at
/// `point` (body coordinates) of `body`. `out` must have length nv (it is resized and zeroed if not).
pub fn body_point_force<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    q: &[S],
    body: usize,
    point: &Vector3<S>,
    force: &Vector3<S>,
    out: &mut DVector<S>,
) {
    forward_kinematics(model, data, q);
    ensure_vec(out, model.nv());
    add_point_force(model, data, body, point, force, out);
}

/// External couple hook: adds `J_ω(q)^T torque` to `out` for a world-frame `torque` on `body`.
pub fn body_torque<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    q: &[S],
    body: usize,
    torque: &Vector3<S>,
    out: &mut DVector<S>,
) {
    forward_kinematics(model, data, q);
    ensure_vec(out, model.nv());
    let pw = Vector3::zeros();
    for_each_point_column(model, data, body, &pw, |k, w, _lin| {
        out[k] += w.dot(torque);
    });
}

/// `Q(t, q, v)` of the paper from the model's fields and joints (time-independent; `t` is accepted
/// for the interface): uniform gravity, Newtonian attraction of each body's CoM to fixed points
/// (`-mu m r/|r|^3`, by the CoM Jacobian transpose), gravity compensation (`-gravcomp m g` at each
/// body's CoM, by the CoM Jacobian transpose: MuJoCo's passive `gravcomp` force), joint springs
/// `-k (q - q_ref)` and dampers `-d v`. User forces are added by the caller with [`body_point_force`].
pub fn applied_forces<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    _t: S,
    q: &[S],
    v: &[S],
    out: &mut DVector<S>,
) {
    let g = lift3::<S>(&Vector3::from(model.fields.gravity));
    gravity_forces(model, data, q, &g, out); // also runs forward_kinematics(q)
    add_field_forces(model, data, q, v, out);
}

/// `G + Q` of the paper in one inverse-dynamics sweep: `-rnea(q, v, 0)` with the model's gravity
/// (Coriolis, centrifugal and gravity together) plus attractors, gravity compensation, springs and
/// dampers.
pub fn natural_forces<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    q: &[S],
    v: &[S],
    out: &mut DVector<S>,
) {
    let g = lift3::<S>(&Vector3::from(model.fields.gravity));
    bias(model, data, q, v, &g, out);
    out.neg_mut();
    add_field_forces(model, data, q, v, out);
}

/// Adds attraction, gravity compensation, spring and damper forces (the part of
/// [`applied_forces`] beyond gravity); needs `forward_kinematics(q)` done on `data`.
fn add_field_forces<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    q: &[S],
    v: &[S],
    out: &mut DVector<S>,
) {
    if !model.fields.attractors.is_empty() {
        for (b, body) in model.bodies.iter().enumerate() {
            if body.massless {
                continue;
            }
            let com = lift3::<S>(&body.com);
            let ld = &data.links[model.body_link[b]];
            let cw = ld.pos + mv(&ld.rot, &point_in_link(model, b, &com));
            for at in &model.fields.attractors {
                let r = cw - lift3::<S>(&Vector3::from(at.point));
                let r2 = r.dot(&r);
                let r3 = r2 * r2.sqrt();
                let f = r * (c::<S>(-at.mu * body.mass) / r3);
                add_point_force(model, data, b, &com, &f, out);
            }
        }
    }
    for (b, body) in model.bodies.iter().enumerate() {
        if body.gravcomp != 0.0 && !body.massless {
            // -gravcomp m g at the CoM (world frame)
            let f =
                lift3::<S>(&(Vector3::from(model.fields.gravity) * (-body.gravcomp * body.mass)));
            add_point_force(model, data, b, &lift3::<S>(&body.com), &f, out);
        }
    }
    for jt in &model.joints {
        if jt.stiffness != 0.0 {
            if let JointKind::Hinge(_) | JointKind::Slide(_) = jt.kind {
                out[jt.iv] -= (q[jt.iq] - c::<S>(jt.spring_ref)) * c::<S>(jt.stiffness);
            }
        }
        if jt.damping != 0.0 {
            for k in 0..jt.nv {
                out[jt.iv + k] -= v[jt.iv + k] * c::<S>(jt.damping);
            }
        }
    }
}

/// Kinetic energy `T = Σ ½ v_i · I_i v_i + Σ ½ armature v_k²` from the body velocities and the
/// joints' armature (equals `½ vᵀ A(q) v`).
pub fn kinetic_energy<S: Scalar>(model: &Model, data: &mut TreeData<S>, q: &[S], v: &[S]) -> S {
    forward_kinematics(model, data, q);
    forward_velocity(model, data, v);
    let mut t = c::<S>(0.0);
    for (i, link) in model.links.iter().enumerate() {
        if let Some(inr) = &link.inertia {
            let vi = data.links[i].v;
            t += vi.dot(&Inertia::<S>::lift(inr).mul_motion(&vi)) * c::<S>(0.5);
        }
    }
    for jt in model.joints.iter().filter(|j| j.armature != 0.0) {
        for k in jt.iv..jt.iv + jt.nv {
            t += v[k] * v[k] * c::<S>(0.5 * jt.armature);
        }
    }
    t
}

/// Potential energy of the conservative parts of `Q`: gravity and its compensation
/// `-Σ (1 - gravcomp) m g·c`, attraction `-Σ mu m/|r|`, springs `Σ ½ k (q - q_ref)²`, so that
/// `Q_conservative = -∂V/∂q` on hinge/slide coordinates.
pub fn potential_energy<S: Scalar>(model: &Model, data: &mut TreeData<S>, q: &[S]) -> S {
    forward_kinematics(model, data, q);
    let g = lift3::<S>(&Vector3::from(model.fields.gravity));
    let mut e = c::<S>(0.0);
    for (b, body) in model.bodies.iter().enumerate() {
        if body.massless {
            continue;
        }
        let ld = &data.links[model.body_link[b]];
        let cw = ld.pos + mv(&ld.rot, &point_in_link(model, b, &lift3::<S>(&body.com)));
        e -= g.dot(&cw) * c::<S>(body.mass);
        if body.gravcomp != 0.0 {
            e += g.dot(&cw) * c::<S>(body.gravcomp * body.mass);
        }
        for at in &model.fields.attractors {
            let r = cw - lift3::<S>(&Vector3::from(at.point));
            e -= c::<S>(at.mu * body.mass) / r.dot(&r).sqrt();
        }
    }
    for jt in &model.joints {
        if jt.stiffness != 0.0 {
            let d = q[jt.iq] - c::<S>(jt.spring_ref);
            e += d * d * c::<S>(0.5 * jt.stiffness);
        }
    }
    e
}
