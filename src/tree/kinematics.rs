//! Workspace, forward kinematics (poses, velocities, accelerations), configuration-space helpers
//! and kinematics of body points.

use super::model::{JointKind, Model};
use super::spatial::{
    cross, lift3, lift33, mm, mv, quat_from_rot, rot_axis_angle, rot_quat, Force, Inertia, Motion,
    Xform,
};
use crate::scalar::{c, Scalar};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

/// Per-link workspace (all quantities in link coordinates unless stated otherwise).
#[derive(Clone, Debug)]
pub(crate) struct LinkData<S: Scalar> {
    /// `^i X_λ(i)` = joint transform composed with the fixed placement (`X_J X_T`, Featherstone Table 5.1).
    pub x: Xform<S>,
    /// Rotation link -> world.
    pub rot: Matrix3<S>,
    /// Link origin, world frame.
    pub pos: Vector3<S>,
    /// Motion subspace columns (nv of the joint).
    pub s: [Motion<S>; 6],
    /// The same in world coordinates (set by the CRBA).
    pub sw: [Motion<S>; 6],
    pub v: Motion<S>,
    pub a: Motion<S>,
    /// Joint velocity `S qdot` and velocity-product term `c_J` (Featherstone ch. 3, apparent derivative of S).
    pub vj: Motion<S>,
    pub cj: Motion<S>,
    pub f: Force<S>,
    /// Composite inertia (CRBA) or body inertia in S.
    pub ic: Inertia<S>,
}

impl<S: Scalar> LinkData<S> {
    fn new() -> Self {
        LinkData {
            x: Xform::identity(),
            rot: Matrix3::identity(),
            pos: Vector3::zeros(),
            s: [Motion::zero(); 6],
            sw: [Motion::zero(); 6],
            v: Motion::zero(),
            a: Motion::zero(),
            vj: Motion::zero(),
            cj: Motion::zero(),
            f: Force::zero(),
            ic: Inertia::zero(),
        }
    }
}

/// Preallocated workspace for one [`Model`] and one scalar type; the algorithms allocate nothing
/// per call (output vectors/matrices are resized only if their shape is wrong).
#[derive(Clone, Debug)]
pub struct TreeData<S: Scalar> {
    pub(crate) links: Vec<LinkData<S>>,
    /// Result of the last [`super::rnea`].
    pub(crate) tau: DVector<S>,
    pub(crate) zero_v: Vec<S>,
    /// q of the last [`forward_kinematics`] and v of the last [`forward_velocity`]: their results
    /// are reused while q (and v) are bit for bit unchanged, for every scalar type (all dual parts
    /// compared), so the CRBA, the RNEA and the signal jets of one evaluation share one sweep
    /// (the idea of Pinocchio's `computeAllTerms`). The velocity pass is valid only for the
    /// positions it ran on (`fv_valid` is cleared whenever the position pass runs).
    fk_q: Vec<S>,
    fk_valid: bool,
    fv_v: Vec<S>,
    fv_valid: bool,
    /// The links' accelerations `a` are those at dv/dt = 0 without gravity at the q and v of the
    /// passes above (left by [`forward_bias_acceleration`] or by the RNEA of [`super::bias`]).
    pub(crate) acc_bias: bool,
    passes: SweepPasses,
    /// World-frame motion subspace column of each dof (CRBA).
    pub(crate) sw_dof: Vec<Motion<S>>,
    /// The articulated-body factorization's per-link scratch ([`super::aba_factor`]).
    pub(crate) aba: Vec<super::aba::AbaLink<S>>,
    /// [`super::aba_solve_block`]'s per-link, per-column forces, u_j and accelerations.
    pub(crate) aba_block: Vec<[S; 6]>,
}

impl<S: Scalar> TreeData<S> {
    pub fn new(model: &Model) -> Self {
        TreeData {
            links: vec![LinkData::new(); model.links.len()],
            tau: DVector::zeros(model.nv()),
            zero_v: vec![c(0.0); model.nv()],
            fk_q: vec![c(0.0); model.nq()],
            fk_valid: false,
            fv_v: vec![c(0.0); model.nv()],
            fv_valid: false,
            acc_bias: false,
            passes: SweepPasses::default(),
            sw_dof: vec![Motion::zero(); model.nv()],
            aba: vec![super::aba::AbaLink::new(); model.links.len()],
            aba_block: Vec::new(),
        }
    }
}

/// How often the position and velocity passes ran on a [`TreeData`] and how often a call found
/// them already done for its (q, v) and reused them (what the shared-sweep tests count).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SweepPasses {
    pub positions: u64,
    pub positions_reused: u64,
    pub velocities: u64,
    pub velocities_reused: u64,
}

impl<S: Scalar> TreeData<S> {
    /// Pass counts since the workspace was made.
    pub fn passes(&self) -> SweepPasses {
        self.passes
    }
}

/// A tree and a workspace over it, lent by a model to constraints on the same tree (body-point
/// signals) so they read the model's forward passes instead of running their own.
pub struct TreeSweep<'a, S: Scalar> {
    pub model: &'a Model,
    pub data: &'a mut TreeData<S>,
}

/// Same bits in every part (dual parts included); `==` on dual numbers compares real parts only.
fn same_bits<S: Scalar>(a: &[S], b: &[S]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.bit_eq(y))
}

pub(crate) fn ensure_vec<S: Scalar>(x: &mut DVector<S>, n: usize) {
    if x.len() != n {
        *x = DVector::zeros(n);
    }
}

pub(crate) fn ensure_mat<S: Scalar>(x: &mut DMatrix<S>, r: usize, c: usize) {
    if x.shape() != (r, c) {
        *x = DMatrix::zeros(r, c);
    }
}

fn check_len(what: &str, got: usize, want: usize) {
    assert!(
        got == want,
        "tree: {what} has length {got}, expected {want}"
    );
}

/// Forward position kinematics: link transforms `^i X_λ`, world poses and motion subspaces.
/// Joint transforms (post-joint frame in pre-joint frame, `x_pre = R x_post + p`), with the
/// displacement `d = q - ref` of hinges and slides (MuJoCo `ref`, 0 by default):
/// hinge `R = Rot(u, d)`, `p = a - R a` (anchor a); slide `R = 1`, `p = u d`; ball
/// `R = R(quat)`, `p = a - R a`; free `R = R(quat)`, `p = position`. Motion subspaces in the
/// post-joint frame: hinge `(u, a x u)`, slide `(0, u)`, ball `(e_k, a x e_k)`, free
/// `[(0, R^T e_k) | (e_k, 0)]` (world linear velocity, body angular velocity).
///
/// Skipped when q has the same bits (every dual part) as the q of the previous call on `data`.
pub fn forward_kinematics<S: Scalar>(model: &Model, data: &mut TreeData<S>, q: &[S]) {
    check_len("q", q.len(), model.nq());
    if data.fk_valid && same_bits(&data.fk_q, q) {
        data.passes.positions_reused += 1;
        return;
    }
    data.passes.positions += 1;
    data.fk_valid = false;
    data.fv_valid = false;
    data.acc_bias = false;
    let zero = Vector3::<S>::zeros();
    for (i, link) in model.links.iter().enumerate() {
        let place = Xform::<S>::lift(&link.place);
        let mut s = [Motion::zero(); 6];
        let xj = match link.joint {
            None => Xform::identity(),
            Some(j) => {
                let jt = &model.joints[j];
                let a = lift3::<S>(&jt.anchor);
                let iq = jt.iq;
                // displacement q - ref (MuJoCo `ref`; hinge and slide only)
                let disp = || {
                    if jt.reference != 0.0 {
                        q[iq] - c::<S>(jt.reference)
                    } else {
                        q[iq]
                    }
                };
                match jt.kind {
                    JointKind::Hinge(u) => {
                        let r = rot_axis_angle(&u, disp());
                        let ul = lift3::<S>(&u);
                        s[0] = Motion::new(ul, cross(&a, &ul));
                        Xform::from_pose(r, a - r * a)
                    }
                    JointKind::Slide(u) => {
                        let ul = lift3::<S>(&u);
                        s[0] = Motion::new(zero, ul);
                        Xform::from_pose(Matrix3::identity(), ul * disp())
                    }
                    JointKind::Ball => {
                        let r = rot_quat(q[iq], q[iq + 1], q[iq + 2], q[iq + 3]);
                        for (k, sk) in s.iter_mut().take(3).enumerate() {
                            let e = Vector3::<S>::ith(k, c(1.0));
                            *sk = Motion::new(e, cross(&a, &e));
                        }
                        Xform::from_pose(r, a - r * a)
                    }
                    JointKind::Free => {
                        let r = rot_quat(q[iq + 3], q[iq + 4], q[iq + 5], q[iq + 6]);
                        let rt = r.transpose();
                        for k in 0..3 {
                            s[k] = Motion::new(zero, rt.column(k).into_owned());
                            s[k + 3] = Motion::new(Vector3::ith(k, c(1.0)), zero);
                        }
                        Xform::from_pose(r, Vector3::new(q[iq], q[iq + 1], q[iq + 2]))
                    }
                }
            }
        };
        let x = xj.compose(&place);
        let (rp, pp) = match link.parent {
            Some(p) => (data.links[p].rot, data.links[p].pos),
            None => (Matrix3::identity(), Vector3::zeros()),
        };
        let ld = &mut data.links[i];
        ld.rot = mm(&rp, &x.e.transpose());
        ld.pos = pp + mv(&rp, &x.r);
        ld.x = x;
        ld.s = s;
    }
    data.fk_q.copy_from_slice(q);
    data.fk_valid = true;
}

/// Velocity pass (after [`forward_kinematics`]): `v_i = X_i v_λ + S_i qdot_i` (Featherstone
/// Table 5.1) and `c_J` = apparent derivative of S times qdot (nonzero only for the free
/// joint, whose S depends on q: `c_J = (0, -ω x (R^T v_world))`). Skipped when neither the
/// positions nor the bits of v changed since the previous call on `data`.
pub fn forward_velocity<S: Scalar>(model: &Model, data: &mut TreeData<S>, v: &[S]) {
    check_len("v", v.len(), model.nv());
    if data.fv_valid && same_bits(&data.fv_v, v) {
        data.passes.velocities_reused += 1;
        return;
    }
    data.passes.velocities += 1;
    data.acc_bias = false;
    for (i, link) in model.links.iter().enumerate() {
        let vp = match link.parent {
            Some(p) => data.links[p].v,
            None => Motion::zero(),
        };
        let ld = &mut data.links[i];
        let mut vj = Motion::zero();
        let mut cj = Motion::zero();
        if let Some(j) = link.joint {
            let jt = &model.joints[j];
            for k in 0..jt.nv {
                vj = vj.add(&ld.s[k].scale(v[jt.iv + k]));
            }
            if jt.kind == JointKind::Free {
                cj = Motion::new(Vector3::zeros(), -cross(&vj.ang, &vj.lin));
            }
        }
        ld.v = ld.x.apply_motion(&vp).add(&vj);
        ld.vj = vj;
        ld.cj = cj;
    }
    data.fv_v.copy_from_slice(v);
    data.fv_valid = data.fk_valid;
}

/// Acceleration pass (after [`forward_velocity`]): `a_i = X_i a_λ + S_i qddot_i + c_J + v_i x v_J`
/// (Featherstone Table 5.1), with base acceleration `a_0 = (0, -gravity)` (the gravity trick of Table 5.1).
pub fn forward_acceleration<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    a: &[S],
    gravity: &Vector3<S>,
) {
    check_len("a", a.len(), model.nv());
    data.acc_bias = false;
    let a0 = Motion::new(Vector3::zeros(), -gravity);
    for (i, link) in model.links.iter().enumerate() {
        let ap = match link.parent {
            Some(p) => data.links[p].a,
            None => a0,
        };
        let ld = &mut data.links[i];
        let mut acc =
            ld.x.apply_motion(&ap)
                .add(&ld.cj)
                .add(&ld.v.cross_motion(&ld.vj));
        if let Some(j) = link.joint {
            let jt = &model.joints[j];
            for k in 0..jt.nv {
                acc = acc.add(&ld.s[k].scale(a[jt.iv + k]));
            }
        }
        ld.a = acc;
    }
}

/// The links' accelerations at dv/dt = 0 without gravity (the velocity-product accelerations
/// behind J'v of every point), after [`forward_kinematics`] and [`forward_velocity`] at (q, v).
/// Reused when the RNEA of [`super::bias`] ran last at this (q, v): it keeps its accelerations
/// gravity-free (gravity enters its forces only), so they are this pass's bit for bit.
pub fn forward_bias_acceleration<S: Scalar>(model: &Model, data: &mut TreeData<S>) {
    if data.acc_bias {
        return;
    }
    let zero = std::mem::take(&mut data.zero_v);
    forward_acceleration(model, data, &zero, &Vector3::zeros());
    data.zero_v = zero;
    data.acc_bias = true;
}

/// Time derivative of q: hinge/slide `dq/dt = v`; ball `d quat/dt = ½ quat ⊗ (0, ω_body)`; free
/// `dp/dt = v_world`, `d quat/dt = ½ quat ⊗ (0, ω_body)`. The quaternion is used as given (not
/// normalised).
pub fn qdot<S: Scalar>(model: &Model, q: &[S], v: &[S], out: &mut DVector<S>) {
    check_len("q", q.len(), model.nq());
    check_len("v", v.len(), model.nv());
    ensure_vec(out, model.nq());
    let half = c::<S>(0.5);
    let quat_rate = |qq: &[S], w: &[S], o: &mut [S]| {
        // ½ q ⊗ (0, w)
        o[0] = -(qq[1] * w[0] + qq[2] * w[1] + qq[3] * w[2]) * half;
        o[1] = (qq[0] * w[0] + qq[2] * w[2] - qq[3] * w[1]) * half;
        o[2] = (qq[0] * w[1] + qq[3] * w[0] - qq[1] * w[2]) * half;
        o[3] = (qq[0] * w[2] + qq[1] * w[1] - qq[2] * w[0]) * half;
    };
    let o = out.as_mut_slice();
    for jt in &model.joints {
        let (iq, iv) = (jt.iq, jt.iv);
        match jt.kind {
            JointKind::Hinge(_) | JointKind::Slide(_) => o[iq] = v[iv],
            JointKind::Ball => quat_rate(&q[iq..iq + 4], &v[iv..iv + 3], &mut o[iq..iq + 4]),
            JointKind::Free => {
                o[iq..iq + 3].copy_from_slice(&v[iv..iv + 3]);
                quat_rate(
                    &q[iq + 3..iq + 7],
                    &v[iv + 3..iv + 6],
                    &mut o[iq + 3..iq + 7],
                );
            }
        }
    }
}

/// Neutral configuration (MuJoCo's qpos0): hinge/slide their reference position `ref` (0 by
/// default: the pose the placements describe), ball identity (1, 0, 0, 0), free = the body's
/// placement (position, quaternion) as given in its [`super::BodySpec`].
pub fn neutral(model: &Model) -> DVector<f64> {
    let mut q = DVector::zeros(model.nq());
    for jt in &model.joints {
        let iq = jt.iq;
        match jt.kind {
            JointKind::Hinge(_) | JointKind::Slide(_) => q[iq] = jt.reference,
            JointKind::Ball => q[iq] = 1.0,
            JointKind::Free => {
                let b = &model.bodies[jt.body];
                for k in 0..3 {
                    q[iq + k] = b.pos[k];
                }
                for k in 0..4 {
                    q[iq + 3 + k] = b.quat[k];
                }
            }
        }
    }
    q
}

/// Normalise the quaternions of ball and free joints in place.
pub fn normalize_quaternions<S: Scalar>(model: &Model, q: &mut [S]) {
    for jt in &model.joints {
        let i = match jt.kind {
            JointKind::Ball => jt.iq,
            JointKind::Free => jt.iq + 3,
            _ => continue,
        };
        let n =
            (q[i] * q[i] + q[i + 1] * q[i + 1] + q[i + 2] * q[i + 2] + q[i + 3] * q[i + 3]).sqrt();
        for k in 0..4 {
            q[i + k] /= n;
        }
    }
}

/// World pose of a body frame: `(R, p)` with `x_world = R x_body + p`.
pub fn body_pose<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    q: &[S],
    body: usize,
) -> (Matrix3<S>, Vector3<S>) {
    forward_kinematics(model, data, q);
    body_frame(model, data, body)
}

/// Orientation of a body as a unit quaternion (w, x, y, z), w >= 0 (body -> world).
pub fn body_quaternion<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    q: &[S],
    body: usize,
) -> [S; 4] {
    let (r, _) = body_pose(model, data, q, body);
    quat_from_rot(&r)
}

/// World position of a point given in body coordinates.
pub fn point_position<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    q: &[S],
    body: usize,
    point: &Vector3<S>,
) -> Vector3<S> {
    let (r, p) = body_pose(model, data, q, body);
    p + r * point
}

/// World-frame velocity of a body point (coordinates in the body frame): `R (v_O + ω x p)`.
pub fn point_velocity<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    q: &[S],
    v: &[S],
    body: usize,
    point: &Vector3<S>,
) -> Vector3<S> {
    forward_kinematics(model, data, q);
    forward_velocity(model, data, v);
    let ld = &data.links[model.body_link[body]];
    let p = point_in_link(model, body, point);
    mv(&ld.rot, &(ld.v.lin + cross(&ld.v.ang, &p)))
}

/// Angular velocity of a body, world frame (body frame: `R^T ω`).
pub fn body_angular_velocity<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    q: &[S],
    v: &[S],
    body: usize,
) -> Vector3<S> {
    forward_kinematics(model, data, q);
    forward_velocity(model, data, v);
    let ld = &data.links[model.body_link[body]];
    mv(&ld.rot, &ld.v.ang)
}

/// World-frame classical acceleration of a body point and angular acceleration of the body, given
/// `(q, v, dv/dt)`: `a_P = R (a_O + α x p + ω x (v_O + ω x p))` from the spatial acceleration
/// `(α, a_O)` (classical vs spatial acceleration, Featherstone ch. 2).
/// With `a = 0` this is the drift term `J̇(q, v) v` of the point (rows 3..6 of [`point_jacobian`])
/// and of the angular velocity (rows 0..3), as needed by task-space programmes.
pub fn point_acceleration<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    q: &[S],
    v: &[S],
    a: &[S],
    body: usize,
    point: &Vector3<S>,
) -> (Vector3<S>, Vector3<S>) {
    forward_kinematics(model, data, q);
    forward_velocity(model, data, v);
    forward_acceleration(model, data, a, &Vector3::zeros());
    let k = point_kinematics(model, data, body, point);
    (k.acc, k.alpha)
}

/// World rotation and origin of a body after [`forward_kinematics`].
pub fn body_frame<S: Scalar>(
    model: &Model,
    data: &TreeData<S>,
    body: usize,
) -> (Matrix3<S>, Vector3<S>) {
    let ld = &data.links[model.body_link[body]];
    match &model.body_offset[body] {
        None => (ld.rot, ld.pos),
        Some((r, p)) => (mm(&ld.rot, &lift33(r)), ld.pos + mv(&ld.rot, &lift3(p))),
    }
}

/// A body point in the coordinates of the link that carries the body (a welded body is folded
/// into its moving ancestor's link, model.rs `fold_welded`).
pub(crate) fn point_in_link<S: Scalar>(
    model: &Model,
    body: usize,
    point: &Vector3<S>,
) -> Vector3<S> {
    match &model.body_offset[body] {
        None => *point,
        Some((r, p)) => lift3(p) + lift33(r) * point,
    }
}

/// Everything about a body point the forward passes give, world frame.
#[derive(Clone, Copy, Debug)]
pub struct PointKinematics<S: Scalar> {
    /// Body rotation (body -> world).
    pub rot: Matrix3<S>,
    /// Point position.
    pub pos: Vector3<S>,
    /// Point velocity.
    pub vel: Vector3<S>,
    /// Classical point acceleration `R (a_O + α x p + ω x (v_O + ω x p))`.
    pub acc: Vector3<S>,
    /// Body angular velocity.
    pub omega: Vector3<S>,
    /// Body angular acceleration `R α` (= d/dt of the world angular velocity).
    pub alpha: Vector3<S>,
}

/// Read a body point's kinematics from `data` after [`forward_kinematics`], [`forward_velocity`]
/// and [`forward_acceleration`] (run once for all points; gravity must be zero in the last pass).
pub fn point_kinematics<S: Scalar>(
    model: &Model,
    data: &TreeData<S>,
    body: usize,
    point: &Vector3<S>,
) -> PointKinematics<S> {
    let ld = &data.links[model.body_link[body]];
    let point = &point_in_link(model, body, point);
    let w = ld.v.ang;
    let vp = ld.v.lin + cross(&w, point);
    let ap = ld.a.lin + cross(&ld.a.ang, point) + cross(&w, &vp);
    PointKinematics {
        rot: body_frame(model, data, body).0,
        pos: ld.pos + mv(&ld.rot, point),
        vel: mv(&ld.rot, &vp),
        acc: mv(&ld.rot, &ap),
        omega: mv(&ld.rot, &w),
        alpha: mv(&ld.rot, &ld.a.ang),
    }
}

/// Calls `f(dof, ω_col, v_col)` for every dof `k` that moves `body`, with the world-frame angular
/// velocity column and the world-frame velocity column of the (world) point `pw`.
pub fn for_each_point_column<S: Scalar>(
    model: &Model,
    data: &TreeData<S>,
    body: usize,
    pw: &Vector3<S>,
    mut f: impl FnMut(usize, Vector3<S>, Vector3<S>),
) {
    let mut li = Some(model.body_link[body]);
    while let Some(i) = li {
        let link = &model.links[i];
        if let Some(j) = link.joint {
            let jt = &model.joints[j];
            let ld = &data.links[i];
            let d = pw - ld.pos;
            for k in 0..jt.nv {
                let w = mv(&ld.rot, &ld.s[k].ang);
                let lin = mv(&ld.rot, &ld.s[k].lin) + cross(&w, &d);
                f(jt.iv + k, w, lin);
            }
        }
        li = link.parent;
    }
}

/// The linear Jacobian (`3 x nv`, world frame) of a weighted sum of body points c = sum_i w_i p_i
/// (`points`: body, the point in the body frame, weight w_i), after [`forward_kinematics`].
/// Column k, for dof k of link l, is sum over the points of l's subtree of
/// w_i (R s_lin + R s_ang x (p_i - o_l)) =
/// W_l R s_lin + R s_ang x (P_l - W_l o_l) with W_l = sum w_i and P_l = sum w_i p_i over the
/// subtree: one pass from the leaves, O(links + points), instead of a walk to the root per point
/// ([`for_each_point_column`], which sums the same terms in another order). `sub` is scratch.
pub fn weighted_points_jacobian<S: Scalar>(
    model: &Model,
    data: &TreeData<S>,
    points: impl Iterator<Item = (usize, Vector3<S>, S)>,
    sub: &mut Vec<(S, Vector3<S>)>,
    jac: &mut DMatrix<S>,
) {
    let z = c(0.0);
    sub.clear();
    sub.resize(model.links.len(), (z, Vector3::zeros()));
    for (body, point, w) in points {
        let l = model.body_link[body];
        let ld = &data.links[l];
        // p_i as point_kinematics computes it
        let p = ld.pos + mv(&ld.rot, &point_in_link(model, body, &point));
        sub[l].0 += w;
        sub[l].1 += p * w;
    }
    // children after their parents in `links`: one reverse sweep sums each subtree
    for l in (0..model.links.len()).rev() {
        if let Some(parent) = model.links[l].parent {
            debug_assert!(parent < l, "links are ordered parents first");
            let (w, p) = sub[l];
            sub[parent].0 += w;
            sub[parent].1 += p;
        }
    }
    jac.fill(z);
    for (l, link) in model.links.iter().enumerate() {
        let Some(j) = link.joint else { continue };
        let (jt, ld, (w, p)) = (&model.joints[j], &data.links[l], sub[l]);
        let d = p - ld.pos * w;
        for k in 0..jt.nv {
            let col = mv(&ld.rot, &ld.s[k].lin) * w + cross(&mv(&ld.rot, &ld.s[k].ang), &d);
            for r in 0..3 {
                jac[(r, jt.iv + k)] = col[r];
            }
        }
    }
}

/// Jacobian of a body point, world frame, `6 x nv`: rows 0..3 map v to the body's angular velocity,
/// rows 3..6 to the point's linear velocity.
pub fn point_jacobian<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    q: &[S],
    body: usize,
    point: &Vector3<S>,
    jac: &mut DMatrix<S>,
) {
    forward_kinematics(model, data, q);
    ensure_mat(jac, 6, model.nv());
    jac.fill(c(0.0));
    let ld = &data.links[model.body_link[body]];
    let pw = ld.pos + mv(&ld.rot, &point_in_link(model, body, point));
    for_each_point_column(model, data, body, &pw, |k, w, lin| {
        for r in 0..3 {
            jac[(r, k)] = w[r];
            jac[(r + 3, k)] = lin[r];
        }
    });
}
