//! Tree scenes: the `crate::tree` dynamics (CRBA, RNEA, fields) behind the [`Model`] trait, plus
//! forces given as expressions (on body points, in world frame, or on joint coordinates).

use super::layout::Layout;
use crate::expr::Expr;
use crate::model::{Model, Segment};
use crate::scalar::Scalar;
use crate::tree::{self, JointType, TreeData};
use nalgebra::{DMatrix, DVector, Vector3};
use std::sync::Arc;

/// A force given by expressions, applied at a point of a body (world-frame components).
#[derive(Clone, Debug)]
pub struct PointForce {
    pub body: usize,
    pub point: [f64; 3],
    pub force: [Expr; 3],
}

/// A kinematic tree with expression forces.
#[derive(Clone, Debug)]
pub struct TreeSceneModel {
    tree: Arc<tree::Model>,
    segments: Vec<Segment>,
    layout: Layout,
    point_forces: Vec<PointForce>,
    coordinate_forces: Vec<(usize, Expr)>,
    max_stack: usize,
}

/// Scratch of a [`TreeSceneModel`] evaluation.
pub struct TreeWork<S: Scalar> {
    data: TreeData<S>,
    buf: DVector<S>,
    slots: Vec<S>,
    stack: Vec<S>,
}

/// The configuration-space blocks of a tree's joints.
pub fn segments_of(tree: &tree::Model) -> Vec<Segment> {
    let mut segs = vec![];
    for (j, joint) in tree.joints().iter().enumerate() {
        let (qr, vr) = (tree.joint_q_range(j), tree.joint_v_range(j));
        match joint.joint_type() {
            JointType::Hinge { .. } | JointType::Slide { .. } => segs.push(Segment::Euclidean {
                q: qr.start,
                v: vr.start,
                len: 1,
            }),
            JointType::Ball => segs.push(Segment::Quaternion {
                q: qr.start,
                v: vr.start,
            }),
            JointType::Free => {
                segs.push(Segment::Euclidean {
                    q: qr.start,
                    v: vr.start,
                    len: 3,
                });
                segs.push(Segment::Quaternion {
                    q: qr.start + 3,
                    v: vr.start + 3,
                });
            }
        }
    }
    segs
}

impl TreeSceneModel {
    /// Wrap a tree with its expression forces.
    pub fn new(
        tree: Arc<tree::Model>,
        layout: Layout,
        point_forces: Vec<PointForce>,
        coordinate_forces: Vec<(usize, Expr)>,
    ) -> Self {
        let max_stack = point_forces
            .iter()
            .flat_map(|p| p.force.iter().map(|e| e.max_stack()))
            .chain(coordinate_forces.iter().map(|c| c.1.max_stack()))
            .max()
            .unwrap_or(1);
        TreeSceneModel {
            segments: segments_of(&tree),
            tree,
            layout,
            point_forces,
            coordinate_forces,
            max_stack,
        }
    }

    /// The underlying tree (for export and kinematics).
    pub fn tree(&self) -> &Arc<tree::Model> {
        &self.tree
    }

    /// The point forces (body, body-frame point, world-frame force expressions).
    pub fn point_forces(&self) -> &[PointForce] {
        &self.point_forces
    }

    /// The coordinate forces (velocity index, expression).
    pub fn coordinate_forces(&self) -> &[(usize, Expr)] {
        &self.coordinate_forces
    }

    /// The expression forces at (t, q, v) as a simulator must apply them: the coordinate forces
    /// as a generalized force (nv) and each point force as (body, world point, world force).
    /// Their sum J_p^T f + coordinate forces is the part of Q that `add_user_forces` adds.
    #[allow(clippy::type_complexity)]
    pub fn expression_forces(
        &self,
        t: f64,
        q: &[f64],
        v: &[f64],
    ) -> (Vec<f64>, Vec<(usize, [f64; 3], [f64; 3])>) {
        let mut ws = self.workspace::<f64>();
        let l = &self.layout;
        ws.slots[l.t] = t;
        ws.slots[l.q..l.q + q.len()].copy_from_slice(q);
        ws.slots[l.v..l.v + v.len()].copy_from_slice(v);
        let mut gen = vec![0.0; self.tree.nv()];
        for (i, e) in &self.coordinate_forces {
            gen[*i] += e.eval(&ws.slots, &mut ws.stack);
        }
        let mut points = vec![];
        for pf in &self.point_forces {
            let f = [0, 1, 2].map(|k| pf.force[k].eval(&ws.slots, &mut ws.stack));
            let p = tree::point_position(
                &self.tree,
                &mut ws.data,
                q,
                pf.body,
                &Vector3::from(pf.point),
            );
            points.push((pf.body, [p[0], p[1], p[2]], f));
        }
        (gen, points)
    }
}

impl Model for TreeSceneModel {
    type Workspace<S: Scalar> = TreeWork<S>;

    fn workspace<S: Scalar>(&self) -> TreeWork<S> {
        TreeWork {
            data: self.tree.data(),
            buf: DVector::from_element(self.tree.nv(), S::zero()),
            slots: vec![S::zero(); self.layout.slots],
            stack: Vec::with_capacity(self.max_stack),
        }
    }
    fn nq(&self) -> usize {
        self.tree.nq()
    }
    fn nv(&self) -> usize {
        self.tree.nv()
    }
    fn segments(&self) -> &[Segment] {
        &self.segments
    }
    fn q_names(&self) -> Vec<String> {
        self.tree.q_names().to_vec()
    }
    fn v_names(&self) -> Vec<String> {
        self.tree.v_names().to_vec()
    }
    fn mass_matrix<S: Scalar>(&self, ws: &mut TreeWork<S>, q: &[S], a: &mut DMatrix<S>) {
        tree::mass_matrix(&self.tree, &mut ws.data, q, a);
    }
    fn velocity_terms<S: Scalar>(&self, ws: &mut TreeWork<S>, q: &[S], v: &[S], g: &mut [S]) {
        tree::velocity_terms(&self.tree, &mut ws.data, q, v, &mut ws.buf);
        g.copy_from_slice(ws.buf.as_slice());
    }
    fn applied_forces<S: Scalar>(&self, ws: &mut TreeWork<S>, t: S, q: &[S], v: &[S], f: &mut [S]) {
        tree::applied_forces(&self.tree, &mut ws.data, t, q, v, &mut ws.buf);
        self.add_user_forces(ws, t, q, v);
        f.copy_from_slice(ws.buf.as_slice());
    }
    fn natural_forces<S: Scalar>(
        &self,
        ws: &mut TreeWork<S>,
        t: S,
        q: &[S],
        v: &[S],
        f: &mut [S],
        _scratch: &mut [S],
    ) {
        tree::natural_forces(&self.tree, &mut ws.data, q, v, &mut ws.buf);
        self.add_user_forces(ws, t, q, v);
        f.copy_from_slice(ws.buf.as_slice());
    }
    fn tree_sweep<'w, S: Scalar>(
        &'w self,
        ws: &'w mut TreeWork<S>,
    ) -> Option<tree::TreeSweep<'w, S>> {
        Some(tree::TreeSweep {
            model: &self.tree,
            data: &mut ws.data,
        })
    }
    fn has_mass_factor(&self) -> bool {
        true
    }
    fn mass_factor<S: Scalar>(
        &self,
        ws: &mut TreeWork<S>,
        q: &[S],
    ) -> Result<f64, crate::linalg::Singular> {
        tree::aba_factor(&self.tree, &mut ws.data, q)
    }
    fn mass_solve<S: Scalar>(&self, ws: &mut TreeWork<S>, x: &mut [S]) {
        tree::aba_solve(&self.tree, &mut ws.data, x)
    }
    fn mass_solve_block<S: Scalar>(&self, ws: &mut TreeWork<S>, x: &mut [S], cols: usize) {
        tree::aba_solve_block(&self.tree, &mut ws.data, x, cols)
    }
    fn mass_mul<S: Scalar>(&self, ws: &mut TreeWork<S>, x: &[S], out: &mut [S]) {
        tree::mass_mul(&self.tree, &mut ws.data, x, out)
    }
}

impl TreeSceneModel {
    /// Adds the scene's coordinate and point forces (expressions) to `ws.buf`.
    fn add_user_forces<S: Scalar>(&self, ws: &mut TreeWork<S>, t: S, q: &[S], v: &[S]) {
        if !self.point_forces.is_empty() || !self.coordinate_forces.is_empty() {
            let l = &self.layout;
            ws.slots[l.t] = t;
            ws.slots[l.q..l.q + q.len()].copy_from_slice(q);
            ws.slots[l.v..l.v + v.len()].copy_from_slice(v);
            for (i, e) in &self.coordinate_forces {
                ws.buf[*i] += e.eval(&ws.slots, &mut ws.stack);
            }
            for pf in &self.point_forces {
                let fw = Vector3::new(
                    pf.force[0].eval(&ws.slots, &mut ws.stack),
                    pf.force[1].eval(&ws.slots, &mut ws.stack),
                    pf.force[2].eval(&ws.slots, &mut ws.stack),
                );
                let p = Vector3::new(
                    S::from(pf.point[0]),
                    S::from(pf.point[1]),
                    S::from(pf.point[2]),
                );
                tree::body_point_force(&self.tree, &mut ws.data, q, pf.body, &p, &fw, &mut ws.buf);
            }
        }
    }
}
