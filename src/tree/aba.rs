//! The articulated-body factorization of `A(q)`: `A^-1 x` and `A x` in O(n) (Featherstone, *Rigid
//! Body Dynamics Algorithms*, 2008, Table 7.1 and Table 5.1), for the articulated-body formulation
//! (`crate::formulation::Formulation::ArticulatedBody`).
//!
//! Written in world coordinates, as [`super::crba`] is: rigid inertias `I_i` and motion subspaces
//! `S_i` are expressed in the world frame, so the recursions add child terms to the parent without a
//! transform. The factorization depends on q only; `A^-1 x` is ABA with v = 0, no gravity and the
//! generalized force x (its bias terms c_i, p_i vanish), so forces and velocity terms stay with the
//! caller (F = G + Q from [`super::natural_forces`]).
//!
//! - factor (Table 7.1, third loop): `I^A_i = I_i + sum_children I^a_c`, `U_i = I^A_i S_i`,
//!   `D_i = S_i^T U_i + diag(armature_i)`, `I^a_i = I^A_i - U_i D_i^-1 U_i^T` (armature as in
//!   MuJoCo and Pinocchio: added to A's diagonal, hence to the joint's own pivot block).
//! - solve: backward `u_i = x_i - S_i^T p_i`, `p_λ += p_i + U_i D_i^-1 u_i`; forward
//!   `qdd_i = D_i^-1 (u_i - U_i^T a_λ)`, `a_i = a_λ + S_i qdd_i` (a_0 = 0).
//! - product (RNEA, Table 5.1, with v = 0 and no gravity): `a_i = a_λ + S_i x_i`, `f_i = I_i a_i`,
//!   `(A x)_i = S_i^T (f_i + sum of descendants' f) + armature_i x_i`.
//!
//! The pivots D_i are the Schur complements of a block elimination of A from the leaves to the root,
//! so they are positive definite exactly when A is; a pivot that is not is reported as [`Singular`].

use super::kinematics::{forward_kinematics, TreeData};
use super::model::Model;
use super::spatial::{skew, Inertia, Motion, Xform};
use crate::linalg::Singular;
use crate::scalar::{re, Scalar};

/// A spatial vector as (angular, linear) components.
type V6<S> = [S; 6];
/// A 6 x 6 (or k x k, k <= 6) matrix, column-major: `m[col][row]`.
type M6<S> = [[S; 6]; 6];

/// Per-link scratch of the factorization and its solves.
#[derive(Clone, Debug)]
pub(crate) struct AbaLink<S: Scalar> {
    /// Rigid inertia `I_i`, world coordinates.
    iw: Inertia<S>,
    /// Motion subspace columns `S_i`, world coordinates.
    s: [V6<S>; 6],
    /// Articulated inertia `I^A_i` (motion -> force), world coordinates.
    ia: M6<S>,
    /// `U_i = I^A_i S_i` (k columns).
    u: M6<S>,
    /// `D_i^-1` (k x k).
    dinv: M6<S>,
    /// Product: the force `f_i`.
    p: V6<S>,
    /// Product: the acceleration `a_i`.
    a: V6<S>,
}

impl<S: Scalar> AbaLink<S> {
    pub(crate) fn new() -> Self {
        let z = S::zero();
        AbaLink {
            iw: Inertia::zero(),
            s: [[z; 6]; 6],
            ia: [[z; 6]; 6],
            u: [[z; 6]; 6],
            dinv: [[z; 6]; 6],
            p: [z; 6],
            a: [z; 6],
        }
    }
}

fn v6<S: Scalar>(m: &Motion<S>) -> V6<S> {
    [m.ang[0], m.ang[1], m.ang[2], m.lin[0], m.lin[1], m.lin[2]]
}

fn dot6<S: Scalar>(a: &V6<S>, b: &V6<S>) -> S {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] + a[4] * b[4] + a[5] * b[5]
}

/// The rigid inertia as a matrix: `[[ibar, [h]x], [[h]x^T, m 1]]` (the map of [`Inertia::mul_motion`]).
fn inertia_matrix<S: Scalar>(i: &Inertia<S>) -> M6<S> {
    let z = S::zero();
    let hx = skew(&i.h);
    let mut m = [[z; 6]; 6];
    for c in 0..3 {
        for r in 0..3 {
            m[c][r] = i.ibar[(r, c)];
            m[c + 3][r] = hx[(r, c)];
            m[c][r + 3] = hx[(c, r)];
        }
        m[c + 3][c + 3] = i.m;
    }
    m
}

fn mul6<S: Scalar>(m: &M6<S>, x: &V6<S>) -> V6<S> {
    let mut y = [S::zero(); 6];
    for (col, &xc) in m.iter().zip(x.iter()) {
        for r in 0..6 {
            y[r] += col[r] * xc;
        }
    }
    y
}

/// `D^-1` of the k x k symmetric positive definite `d` (Cholesky `D = L L^T`, then the columns of
/// `L^-T L^-1`); the pivots `l_jj^2` go to `pivot` (min, max). Not positive definite: the column.
fn spd_inverse<S: Scalar>(d: &M6<S>, k: usize, pivot: &mut (f64, f64)) -> Result<M6<S>, usize> {
    let z = S::zero();
    let mut l = [[z; 6]; 6];
    for j in 0..k {
        let mut djj = d[j][j];
        for p in 0..j {
            djj -= l[p][j] * l[p][j];
        }
        let r = re(djj);
        if r <= 0.0 || !r.is_finite() {
            return Err(j);
        }
        pivot.0 = pivot.0.min(r);
        pivot.1 = pivot.1.max(r);
        let ljj = djj.sqrt();
        l[j][j] = ljj;
        for i in j + 1..k {
            let mut x = d[j][i];
            for p in 0..j {
                x -= l[p][i] * l[p][j];
            }
            l[j][i] = x / ljj;
        }
    }
    let mut inv = [[z; 6]; 6];
    for c in 0..k {
        // L y = e_c, then L^T x = y
        let mut y = [z; 6];
        for i in 0..k {
            let mut x = if i == c { S::one() } else { z };
            for p in 0..i {
                x -= l[p][i] * y[p];
            }
            y[i] = x / l[i][i];
        }
        for i in (0..k).rev() {
            let mut x = y[i];
            for p in i + 1..k {
                x -= l[i][p] * inv[c][p];
            }
            inv[c][i] = x / l[i][i];
        }
    }
    Ok(inv)
}

/// Factor `A(q)` (Table 7.1, articulated inertias and pivots): after it, [`aba_solve`] gives
/// `A^-1 x` and [`mass_mul`] gives `A x` at this q. Returns the pivot ratio min/max over the
/// dofs' pivots (a reciprocal condition estimate), or [`Singular`] with the dof whose pivot is not
/// positive (A is then not positive definite).
pub fn aba_factor<S: Scalar>(
    model: &Model,
    data: &mut TreeData<S>,
    q: &[S],
) -> Result<f64, Singular> {
    forward_kinematics(model, data, q);
    for (i, link) in model.links.iter().enumerate() {
        let ld = &data.links[i];
        let xw = Xform::from_pose(ld.rot, ld.pos);
        let iw = match &link.inertia {
            Some(inr) => Inertia::lift(inr).transform_to_parent(&xw),
            None => Inertia::zero(),
        };
        let nv = link.joint.map_or(0, |j| model.joints[j].nv);
        // written in place: the columns past nv stay zero from `AbaLink::new`
        let ab = &mut data.aba[i];
        for (k, sk) in ab.s.iter_mut().take(nv).enumerate() {
            *sk = v6(&xw.inv_apply_motion(&ld.s[k]));
        }
        ab.ia = inertia_matrix(&iw);
        ab.iw = iw;
    }
    let mut pivot = (f64::INFINITY, 0.0f64);
    for i in (0..model.links.len()).rev() {
        let link = &model.links[i];
        let ab = &mut data.aba[i];
        if let Some(j) = link.joint {
            let jt = &model.joints[j];
            let k = jt.nv;
            for c in 0..k {
                ab.u[c] = mul6(&ab.ia, &ab.s[c]);
            }
            if k == 1 {
                // hinge and slide: D = s^T U scalar, no k x k work (the same operations as the
                // general branch below: D^-1 = (1 / sqrt(D)) / sqrt(D), results to the bit)
                let mut d = dot6(&ab.s[0], &ab.u[0]);
                if jt.armature != 0.0 {
                    d += S::from(jt.armature);
                }
                let r = re(d);
                if r <= 0.0 || !r.is_finite() {
                    return Err(Singular {
                        column: jt.iv,
                        rcond: 0.0,
                    });
                }
                pivot = (pivot.0.min(r), pivot.1.max(r));
                let l = d.sqrt();
                let dinv = (S::one() / l) / l;
                ab.dinv[0][0] = dinv;
                let w = ab.u[0].map(|x| x * dinv);
                for (col, &uc) in ab.ia.iter_mut().zip(ab.u[0].iter()) {
                    for r in 0..6 {
                        col[r] -= w[r] * uc;
                    }
                }
            } else {
                let mut d = [[S::zero(); 6]; 6];
                for c in 0..k {
                    for r in 0..k {
                        d[c][r] = dot6(&ab.s[r], &ab.u[c]);
                    }
                }
                // armature: A gains it on the joint's diagonal, so does the pivot D_i (A's block
                // elimination from the leaves sees the joint's own diagonal block last)
                if jt.armature != 0.0 {
                    for (c, dc) in d.iter_mut().enumerate().take(k) {
                        dc[c] += S::from(jt.armature);
                    }
                }
                ab.dinv = spd_inverse(&d, k, &mut pivot).map_err(|c| Singular {
                    column: jt.iv + c,
                    rcond: 0.0,
                })?;
                // I^a = I^A - U D^-1 U^T
                for c in 0..k {
                    let w = mul_k(&ab.dinv, &ab.u, c, k); // (D^-1 U^T)^T column: U D^-1 e_c
                    for (col, &uc) in ab.ia.iter_mut().zip(ab.u[c].iter()) {
                        for r in 0..6 {
                            col[r] -= w[r] * uc;
                        }
                    }
                }
            }
        }
        if let Some(p) = link.parent {
            // parents come before their children (p < i): both borrowed, nothing copied
            let (head, tail) = data.aba.split_at_mut(i);
            for (cp, ci) in head[p].ia.iter_mut().zip(tail[0].ia.iter()) {
                for r in 0..6 {
                    cp[r] += ci[r];
                }
            }
        }
    }
    Ok(if pivot.1 > 0.0 {
        pivot.0 / pivot.1
    } else {
        1.0
    })
}

/// `U D^-1 e_c` (a 6-vector) for the k x k `dinv` and the k columns of `u`.
fn mul_k<S: Scalar>(dinv: &M6<S>, u: &M6<S>, c: usize, k: usize) -> V6<S> {
    let mut w = [S::zero(); 6];
    for (p, up) in u.iter().take(k).enumerate() {
        let x = dinv[c][p];
        for r in 0..6 {
            w[r] += up[r] * x;
        }
    }
    w
}

/// `x <- A(q)^-1 x` by the articulated-body factorization of the last [`aba_factor`] (O(n)):
/// [`aba_solve_block`] with one column.
pub fn aba_solve<S: Scalar>(model: &Model, data: &mut TreeData<S>, x: &mut [S]) {
    aba_solve_block(model, data, x, 1);
}

/// `x <- A(q)^-1 x` for `cols` right-hand sides at once (x column-major, `nv x cols`; Table 7.1's
/// backward pass for the forces p, forward pass for the accelerations), in one pair of sweeps, so
/// each link's factor is read once for all of them (the formulation's 1 + s solves). Scratch grows
/// on the first call with more columns than before, never afterwards.
pub fn aba_solve_block<S: Scalar>(model: &Model, data: &mut TreeData<S>, x: &mut [S], cols: usize) {
    let z = S::zero();
    let nv = model.nv();
    let nl = model.links.len();
    if data.aba_block.len() < 3 * nl * cols {
        data.aba_block.resize(3 * nl * cols, [z; 6]);
    }
    // per (link, column): p at [i * cols + c], u_j at [(nl + i) * cols + c], a at [(2 nl + i) * cols + c]
    let (p_all, rest) = data.aba_block.split_at_mut(nl * cols);
    let (uj_all, a_all) = rest.split_at_mut(nl * cols);
    for p in p_all.iter_mut() {
        *p = [z; 6];
    }
    for i in (0..nl).rev() {
        let link = &model.links[i];
        let ab = &data.aba[i];
        if let Some(j) = link.joint {
            let jt = &model.joints[j];
            let k = jt.nv;
            for c in 0..cols {
                let (p, uj) = (&mut p_all[i * cols + c], &mut uj_all[i * cols + c]);
                for m in 0..k {
                    uj[m] = x[c * nv + jt.iv + m] - dot6(&ab.s[m], p);
                }
                // p^a = p^A + U D^-1 u
                for m in 0..k {
                    let mut w = z;
                    for l in 0..k {
                        w += ab.dinv[l][m] * uj[l];
                    }
                    for r in 0..6 {
                        p[r] += ab.u[m][r] * w;
                    }
                }
            }
        }
        if let Some(par) = link.parent {
            for c in 0..cols {
                let pa = p_all[i * cols + c];
                for (t, &f) in p_all[par * cols + c].iter_mut().zip(pa.iter()) {
                    *t += f;
                }
            }
        }
    }
    for (i, link) in model.links.iter().enumerate() {
        let ab = &data.aba[i];
        for c in 0..cols {
            let a = match link.parent {
                Some(par) => a_all[par * cols + c],
                None => [z; 6],
            };
            let mut ai = a;
            if let Some(j) = link.joint {
                let jt = &model.joints[j];
                let k = jt.nv;
                let uj = &uj_all[i * cols + c];
                let mut r = [z; 6];
                for m in 0..k {
                    r[m] = uj[m] - dot6(&ab.u[m], &a);
                }
                for m in 0..k {
                    let mut qdd = z;
                    for l in 0..k {
                        qdd += ab.dinv[l][m] * r[l];
                    }
                    x[c * nv + jt.iv + m] = qdd;
                    for t in 0..6 {
                        ai[t] += ab.s[m][t] * qdd;
                    }
                }
            }
            a_all[i * cols + c] = ai;
        }
    }
}

/// `out = A(q) x` in O(n): inverse dynamics with v = 0 and no gravity (Table 5.1) on the inertias and
/// motion subspaces of the last [`aba_factor`].
pub fn mass_mul<S: Scalar>(model: &Model, data: &mut TreeData<S>, x: &[S], out: &mut [S]) {
    let z = S::zero();
    for (i, link) in model.links.iter().enumerate() {
        let a = match link.parent {
            Some(p) => data.aba[p].a,
            None => [z; 6],
        };
        let ab = &mut data.aba[i];
        ab.a = a;
        if let Some(j) = link.joint {
            let jt = &model.joints[j];
            for c in 0..jt.nv {
                for t in 0..6 {
                    ab.a[t] += ab.s[c][t] * x[jt.iv + c];
                }
            }
        }
        let f = ab.iw.mul_motion(&Motion::new(
            [ab.a[0], ab.a[1], ab.a[2]].into(),
            [ab.a[3], ab.a[4], ab.a[5]].into(),
        ));
        ab.p = [f.ang[0], f.ang[1], f.ang[2], f.lin[0], f.lin[1], f.lin[2]];
    }
    for i in (0..model.links.len()).rev() {
        let link = &model.links[i];
        let f = data.aba[i].p;
        if let Some(j) = link.joint {
            let jt = &model.joints[j];
            for c in 0..jt.nv {
                out[jt.iv + c] = dot6(&data.aba[i].s[c], &f);
            }
            if jt.armature != 0.0 {
                for c in 0..jt.nv {
                    out[jt.iv + c] += x[jt.iv + c] * S::from(jt.armature);
                }
            }
        }
        if let Some(p) = link.parent {
            for (t, &fi) in data.aba[p].p.iter_mut().zip(f.iter()) {
                *t += fi;
            }
        }
    }
}
