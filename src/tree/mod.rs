//! Kinematic trees: bodies and joints, CRBA and RNEA generic over the scalar type.
//!
//! A [`Model`] is built once from [`BodySpec`]s (validated, errors name the body/joint); a
//! [`TreeData<S>`] workspace is allocated per model and scalar type `S` (`f64` or dual numbers), and
//! the algorithms (Featherstone, *Rigid Body Dynamics Algorithms*, 2008) allocate nothing per call.
//!
//! Conventions:
//! - Frames: every body has a frame placed in its parent's frame by `pos` and `quat` (w, x, y, z);
//!   its joints then act in sequence (MuJoCo semantics), each joint's axis/anchor expressed in the
//!   frame produced by the preceding joints of the same body (the body frame when unmoved by them).
//!   The CoM and the inertia (about the CoM) are in the body frame. World is z-up only by choice of
//!   the gravity vector.
//! - Quaternions are (w, x, y, z), Hamilton product; `R(quat)` maps body to parent coordinates and
//!   is normalised implicitly (any nonzero quaternion is valid).
//! - Velocities: hinge/slide `v = dq/dt`; ball `v = ω` in the joint's child (body) frame; free
//!   `v = (world linear velocity of the body origin, body-frame ω)` (MuJoCo). See [`qdot`].
//! - Equation of motion (Do Sanh 1998, eq. 2.2): `A(q) dv/dt - G(q, v) = Q(t, q, v)` with
//!   `A` = [`mass_matrix`], `G` = [`velocity_terms`] `= -C(q,v) v`, `Q` = [`applied_forces`]
//!   (+ [`body_point_force`] for user forces). In simulator terms `bias = C v + g = -G - Q_gravity`.
//! - Names of q/v entries: [`Model::q_names`], [`Model::v_names`].
//! - MuJoCo correspondence: body `pos`/`quat`/`gravcomp`, joint `axis`/`pos` (our `anchor`),
//!   `stiffness`, `springref`, `damping`, `armature` and hinge/slide `ref` (our `reference`) map
//!   one to one, with MuJoCo's meaning: q is MuJoCo's qpos, a hinge/slide turns/moves by
//!   `q - ref` (so `q = ref`, [`neutral`], is the pose the placements describe), `springref` is a
//!   value of q, armature adds to `A`'s diagonal (and to `T = ½ vᵀ A v`), gravcomp is a passive
//!   force `-gravcomp m g` at the CoM.
//!
//! ```
//! use progmo::tree::*;
//! use nalgebra::{DMatrix, DVector};
//! // particle in spherical coordinates (phi, theta, r): three joints in ONE body
//! let body = BodySpec::point_mass("p", WORLD, 2.0, [0.0; 3])
//!     .joint(JointSpec::hinge("phi", [0.0, 0.0, 1.0]))
//!     .joint(JointSpec::hinge("theta", [0.0, -1.0, 0.0]))
//!     .joint(JointSpec::slide("r", [1.0, 0.0, 0.0]));
//! let fields = Fields { gravity: [0.0, 0.0, -9.81], attractors: vec![] };
//! let model = Model::new(&[body], fields).unwrap();
//! let mut data = model.data::<f64>();
//! let (q, v) = ([0.1, 0.2, 1.5], [0.3, -0.1, 0.2]);
//! let (mut a, mut g, mut f) = (DMatrix::zeros(3, 3), DVector::zeros(3), DVector::zeros(3));
//! mass_matrix(&model, &mut data, &q, &mut a);
//! velocity_terms(&model, &mut data, &q, &v, &mut g);
//! applied_forces(&model, &mut data, 0.0, &q, &v, &mut f);
//! let dv = a.cholesky().unwrap().solve(&(g + f)); // A dv/dt - G = Q
//! assert_eq!(dv.len(), 3);
//! ```

mod aba;
mod config;
mod dynamics;
mod kinematics;
mod model;
pub mod spatial;

pub use aba::{aba_factor, aba_solve, aba_solve_block, mass_mul};
pub use config::{difference_configuration, integrate_configuration, quat_exp, quat_log};
pub use dynamics::{
    applied_forces, bias, body_point_force, body_torque, crba, gravity_forces, kinetic_energy,
    mass_matrix, natural_forces, potential_energy, rnea, velocity_terms,
};
pub use kinematics::{
    body_angular_velocity, body_frame, body_pose, body_quaternion, for_each_point_column,
    forward_acceleration, forward_bias_acceleration, forward_kinematics, forward_velocity, neutral,
    normalize_quaternions, point_acceleration, point_jacobian, point_kinematics, point_position,
    point_velocity, qdot, weighted_points_jacobian, PointKinematics, SweepPasses, TreeData,
    TreeSweep,
};
pub(crate) use model::JointKind;
pub use model::{
    Attractor, Body, BodySpec, Fields, Joint, JointSpec, JointType, Model, ModelError,
    INERTIA_RTOL, WORLD,
};

#[cfg(test)]
mod tests;
