//! Tests of the kinematic-tree module against closed-form Lagrangians and internal identities.

use super::*;
use crate::scalar::Scalar;
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use num_dual::Dual64;

const EPS: f64 = f64::EPSILON;

/// xorshift64* in [-1, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545F4914F6CDD1D);
        (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

fn inr(a: f64, b: f64, c: f64, off: f64) -> [[f64; 3]; 3] {
    [
        [a, off, 0.05 * a],
        [off, b, -0.03 * a],
        [0.05 * a, -0.03 * a, c],
    ]
}

/// A tree exercising every joint type, several joints per body, anchors, a massless coordinate
/// body, a welded body and two roots.
fn zoo(fields: Fields) -> Model {
    Model::new(&zoo_specs(), fields).unwrap()
}

/// [`zoo`] with armature on every joint type, reference positions on hinges and slides and
/// gravity compensation (partial, full, over-compensating and negative).
fn zoo_extras(fields: Fields) -> Model {
    let mut specs = zoo_specs();
    for b in specs.iter_mut() {
        b.gravcomp = match b.name.as_str() {
            "base" => 0.5,
            "arm2" => 1.0,
            "tip" => 2.0,
            "pend" => -0.3,
            _ => 0.0,
        };
        for j in b.joints.iter_mut() {
            (j.armature, j.reference) = match j.name.as_str() {
                "float" => (0.02, 0.0),
                "shoulder" => (0.03, 0.0),
                "elbow" => (0.05, 0.3),
                "extend" => (0.1, -0.2),
                "roll" => (0.0, 0.4),
                "push" => (0.07, 0.0),
                "swing" => (0.2, -0.5),
                _ => (0.0, 0.0),
            };
        }
    }
    Model::new(&specs, fields).unwrap()
}

fn zoo_specs() -> Vec<BodySpec> {
    vec![
        BodySpec::new(
            "base",
            WORLD,
            2.0,
            [0.1, -0.05, 0.02],
            inr(0.3, 0.4, 0.5, 0.05),
        )
        .at([0.1, 0.2, 0.3])
        .rotated([0.9, 0.1, 0.2, 0.3])
        .joint(JointSpec::free("float").with_damping(0.05)),
        BodySpec::new(
            "arm1",
            "base",
            1.2,
            [0.2, 0.05, -0.03],
            inr(0.2, 0.25, 0.3, -0.03),
        )
        .at([0.3, 0.1, 0.0])
        .rotated([0.8, 0.2, -0.1, 0.3])
        .joint(
            JointSpec::ball("shoulder")
                .with_anchor([0.05, 0.0, 0.1])
                .with_damping(0.1),
        ),
        BodySpec::new(
            "arm2",
            "arm1",
            0.8,
            [0.1, 0.0, 0.02],
            inr(0.1, 0.12, 0.15, 0.01),
        )
        .at([0.4, 0.0, 0.0])
        .joint(
            JointSpec::hinge("elbow", [0.2, 1.0, 0.1])
                .with_anchor([0.02, 0.01, 0.0])
                .with_spring(3.0, 0.2)
                .with_damping(0.2),
        )
        .joint(JointSpec::slide("extend", [1.0, 0.3, 0.0]).with_spring(2.0, 0.1)),
        BodySpec::massless("coord", "arm2")
            .at([0.1, 0.1, 0.0])
            .joint(JointSpec::hinge("yaw", [0.0, 0.0, 1.0])),
        BodySpec::point_mass("tip", "coord", 0.5, [0.05, 0.3, 0.1])
            .at([0.2, 0.0, 0.0])
            .rotated([0.7, 0.0, 0.7, 0.1])
            .joint(JointSpec::hinge("roll", [1.0, 0.0, 0.0]))
            .joint(JointSpec::slide("push", [0.0, 1.0, 0.0]).with_damping(0.3)),
        BodySpec::new(
            "weld",
            "arm1",
            0.3,
            [0.0, 0.1, 0.0],
            inr(0.01, 0.012, 0.015, 0.001),
        )
        .at([0.0, 0.0, 0.2])
        .rotated([0.5, 0.5, 0.5, 0.5]),
        BodySpec::new(
            "pend",
            WORLD,
            1.0,
            [0.0, 0.0, -0.5],
            inr(0.05, 0.05, 0.02, 0.0),
        )
        .at([1.0, 0.0, 0.0])
        .joint(JointSpec::hinge("swing", [0.0, 1.0, 0.0]).with_anchor([0.0, 0.0, 0.2])),
    ]
}

fn zoo_fields() -> Fields {
    Fields {
        gravity: [0.3, -0.2, -9.81],
        attractors: vec![Attractor {
            point: [3.0, -2.0, 4.0],
            mu: 5.0,
        }],
    }
}

/// Random state with unit quaternions; `scale` for the coordinates.
fn random_state(model: &Model, rng: &mut Rng) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut q: Vec<f64> = (0..model.nq()).map(|_| rng.next()).collect();
    normalize_quaternions(model, &mut q);
    let v = (0..model.nv()).map(|_| rng.next()).collect();
    let a = (0..model.nv()).map(|_| rng.next()).collect();
    (q, v, a)
}

fn max_abs(m: &DMatrix<f64>) -> f64 {
    m.iter().fold(0.0, |s, x| s.max(x.abs()))
}

/// `x + eps d` over Dual64.
fn seeded(x: &[f64], d: &[f64]) -> Vec<Dual64> {
    x.iter().zip(d).map(|(&a, &b)| Dual64::new(a, b)).collect()
}

#[test]
fn names_and_sizes() {
    let m = zoo(Fields::default());
    assert_eq!(m.nq(), 7 + 4 + 2 + 1 + 2 + 1);
    assert_eq!(m.nv(), 6 + 3 + 2 + 1 + 2 + 1);
    assert_eq!(
        &m.q_names()[..8],
        &[
            "float.x",
            "float.y",
            "float.z",
            "float.qw",
            "float.qx",
            "float.qy",
            "float.qz",
            "shoulder.qw"
        ]
    );
    assert_eq!(
        &m.v_names()[..7],
        &[
            "float.vx",
            "float.vy",
            "float.vz",
            "float.wx",
            "float.wy",
            "float.wz",
            "shoulder.wx"
        ]
    );
    let j = m.joint_id("extend").unwrap();
    assert_eq!(m.joint_q_range(j), 12..13);
    assert_eq!(m.joint_v_range(j), 10..11);
    let q0 = neutral(&m);
    assert_eq!(q0[7], 1.0);
    assert!((q0[0] - 0.1).abs() < EPS && (q0[3] - 0.9 / (0.95f64).sqrt()).abs() < 4.0 * EPS);
}

/// Columns of M equal rnea(q, 0, e_i) - rnea(q, 0, 0) (Featherstone ch. 6); also
/// rnea(q, v, a) = M a + rnea(q, v, 0).
#[test]
fn crba_matches_rnea() {
    for m in [zoo(zoo_fields()), zoo_extras(zoo_fields())] {
        crba_matches_rnea_on(&m);
    }
}

fn crba_matches_rnea_on(m: &Model) {
    let m = m.clone();
    let mut d = TreeData::<f64>::new(&m);
    let mut rng = Rng(0x1234_5678_9abc_def1);
    let g = Vector3::new(0.3, -0.2, -9.81);
    let nv = m.nv();
    let mut mm = DMatrix::zeros(0, 0);
    for _ in 0..20 {
        let (q, v, a) = random_state(&m, &mut rng);
        crba(&m, &mut d, &q, &mut mm);
        let scale = max_abs(&mm);
        assert!(max_abs(&(&mm - mm.transpose())) <= 8.0 * EPS * scale);
        let zero = vec![0.0; nv];
        let t0 = rnea(&m, &mut d, &q, &zero, &zero, &g).clone();
        let mut cols = DMatrix::zeros(nv, nv);
        for i in 0..nv {
            let mut e = zero.clone();
            e[i] = 1.0;
            let ti = rnea(&m, &mut d, &q, &zero, &e, &g).clone();
            cols.set_column(i, &(ti - &t0));
        }
        let err = max_abs(&(&cols - &mm));
        assert!(err <= 64.0 * EPS * scale.max(9.81), "crba vs rnea: {err:e}");
        let bias0 = rnea(&m, &mut d, &q, &v, &zero, &g).clone();
        let full = rnea(&m, &mut d, &q, &v, &a, &g).clone();
        let err2 = (full - bias0 - &mm * DVector::from_vec(a.clone())).amax();
        assert!(err2 <= 64.0 * EPS * 20.0, "rnea linear in a: {err2:e}");
        // M positive definite
        assert!(mm.clone().cholesky().is_some());
    }
}

fn double_pendulum(m1: f64, m2: f64, l1: f64, l2: f64, j1: f64, j2: f64, g0: f64) -> Model {
    let iso = |j: f64| [[j, 0.0, 0.0], [0.0, j, 0.0], [0.0, 0.0, j]];
    let bodies = vec![
        BodySpec::new("link1", WORLD, m1, [l1, 0.0, 0.0], iso(j1))
            .joint(JointSpec::hinge("theta1", [0.0, 0.0, 1.0])),
        BodySpec::new("link2", "link1", m2, [l2, 0.0, 0.0], iso(j2))
            .at([l1, 0.0, 0.0])
            .joint(JointSpec::hinge("theta2", [0.0, 0.0, 1.0])),
    ];
    Model::new(
        &bodies,
        Fields {
            gravity: [0.0, -g0, 0.0],
            attractors: vec![],
        },
    )
    .unwrap()
}

/// Planar double pendulum (relative angles, masses at the link ends with central inertias J1, J2):
/// M11 = J1 + J2 + m1 l1² + m2 (l1² + l2² + 2 l1 l2 cos θ2), M12 = J2 + m2 (l2² + l1 l2 cos θ2),
/// M22 = J2 + m2 l2²; G = (m2 l1 l2 s2 (2 θ1' θ2' + θ2'²), -m2 l1 l2 s2 θ1'²); gravity -g0 ŷ:
/// Q = -∂V/∂θ with V = g0 (m1 l1 s1 + m2 (l1 s1 + l2 s12)).
#[test]
fn double_pendulum_closed_form() {
    let (m1, m2, l1, l2, j1, j2, g0) = (1.3, 0.7, 0.9, 0.6, 0.02, 0.03, 9.81);
    let model = double_pendulum(m1, m2, l1, l2, j1, j2, g0);
    let mut d = TreeData::<f64>::new(&model);
    let mut rng = Rng(42);
    let (mut mm, mut gg, mut qq) = (DMatrix::zeros(0, 0), DVector::zeros(0), DVector::zeros(0));
    for _ in 0..10 {
        let q = [3.0 * rng.next(), 3.0 * rng.next()];
        let v = [2.0 * rng.next(), 2.0 * rng.next()];
        let (s2, c2) = (q[1].sin(), q[1].cos());
        let m12 = j2 + m2 * (l2 * l2 + l1 * l2 * c2);
        let mex = DMatrix::from_row_slice(
            2,
            2,
            &[
                j1 + j2 + m1 * l1 * l1 + m2 * (l1 * l1 + l2 * l2 + 2.0 * l1 * l2 * c2),
                m12,
                m12,
                j2 + m2 * l2 * l2,
            ],
        );
        mass_matrix(&model, &mut d, &q, &mut mm);
        assert!(
            max_abs(&(&mm - &mex)) <= 8.0 * EPS * max_abs(&mex),
            "{mm} vs {mex}"
        );
        velocity_terms(&model, &mut d, &q, &v, &mut gg);
        let h = m2 * l1 * l2 * s2;
        let gex = DVector::from_vec(vec![
            h * (2.0 * v[0] * v[1] + v[1] * v[1]),
            -h * v[0] * v[0],
        ]);
        assert!(
            (&gg - &gex).amax() <= 16.0 * EPS * (1.0 + gex.amax()),
            "{gg} vs {gex}"
        );
        applied_forces(&model, &mut d, 0.0, &q, &v, &mut qq);
        let c1 = q[0].cos();
        let c12 = (q[0] + q[1]).cos();
        let qex = DVector::from_vec(vec![
            -g0 * ((m1 + m2) * l1 * c1 + m2 * l2 * c12),
            -g0 * m2 * l2 * c12,
        ]);
        assert!((&qq - &qex).amax() <= 16.0 * EPS * 20.0, "{qq} vs {qex}");
    }
}

/// Mass matrix over Dual64 with q seeded along a direction d: the dual part is dM/dq · d =
/// -m2 l1 l2 sin θ2 d2 [[2, 1], [1, 0]].
#[test]
fn double_pendulum_mass_matrix_derivative_over_duals() {
    let (m1, m2, l1, l2) = (1.3, 0.7, 0.9, 0.6);
    let model = double_pendulum(m1, m2, l1, l2, 0.02, 0.03, 9.81);
    let mut d = TreeData::<Dual64>::new(&model);
    let mut mm = DMatrix::zeros(0, 0);
    for (q, dir) in [([0.3, -1.1], [0.7, 1.3]), ([2.0, 2.5], [-0.4, 0.9])] {
        mass_matrix(&model, &mut d, &seeded(&q, &dir), &mut mm);
        let k = -m2 * l1 * l2 * q[1].sin() * dir[1];
        let ex = [2.0 * k, k, k, 0.0];
        for (i, e) in ex.iter().enumerate() {
            let got = mm[(i / 2, i % 2)].eps;
            assert!((got - e).abs() <= 8.0 * EPS, "{got} vs {e}");
        }
    }
}

fn spherical_particle(m: f64, mu: f64) -> Model {
    // x = r cosθ cosφ, y = r cosθ sinφ, z = r sinθ: rotate by φ about z, then by θ about -y
    // (elevation), then slide along x.
    let bodies = vec![BodySpec::point_mass("particle", WORLD, m, [0.0; 3])
        .joint(JointSpec::hinge("phi", [0.0, 0.0, 1.0]))
        .joint(JointSpec::hinge("theta", [0.0, -1.0, 0.0]))
        .joint(JointSpec::slide("r", [1.0, 0.0, 0.0]))];
    let fields = Fields {
        gravity: [0.0; 3],
        attractors: vec![Attractor {
            point: [0.0; 3],
            mu,
        }],
    };
    Model::new(&bodies, fields).unwrap()
}

/// Particle in spherical coordinates (phi, theta, r) in ONE body: A = m diag(r² cos²θ, r², 1),
/// G from the Lagrangian, Newtonian attraction Q_r = -mu m / r², and the position map.
#[test]
fn spherical_particle_closed_form() {
    let (m, mu) = (1.7, 2.3);
    let model = spherical_particle(m, mu);
    assert_eq!(model.q_names(), &["phi", "theta", "r"]);
    let mut d = TreeData::<f64>::new(&model);
    let mut rng = Rng(7);
    let (mut mm, mut gg, mut qq) = (DMatrix::zeros(0, 0), DVector::zeros(0), DVector::zeros(0));
    for _ in 0..10 {
        let q = [3.0 * rng.next(), 1.4 * rng.next(), 1.5 + rng.next()];
        let v = [rng.next(), rng.next(), rng.next()];
        let (ph, th, r) = (q[0], q[1], q[2]);
        let (st, ct) = (th.sin(), th.cos());
        let p = point_position(&model, &mut d, &q, 0, &Vector3::zeros());
        let pex = Vector3::new(r * ct * ph.cos(), r * ct * ph.sin(), r * st);
        assert!((p - pex).amax() <= 8.0 * EPS * r);
        mass_matrix(&model, &mut d, &q, &mut mm);
        let mex =
            DMatrix::from_diagonal(&DVector::from_vec(vec![m * r * r * ct * ct, m * r * r, m]));
        assert!(
            max_abs(&(&mm - &mex)) <= 16.0 * EPS * max_abs(&mex),
            "{mm} vs {mex}"
        );
        velocity_terms(&model, &mut d, &q, &v, &mut gg);
        let (dph, dth, dr) = (v[0], v[1], v[2]);
        let gex = DVector::from_vec(vec![
            -2.0 * m * (r * ct * ct * dr * dph - r * r * ct * st * dth * dph),
            -m * (2.0 * r * dr * dth + r * r * ct * st * dph * dph),
            m * (r * ct * ct * dph * dph + r * dth * dth),
        ]);
        assert!(
            (&gg - &gex).amax() <= 32.0 * EPS * (1.0 + gex.amax()),
            "{gg} vs {gex}"
        );
        applied_forces(&model, &mut d, 0.0, &q, &v, &mut qq);
        let qex = DVector::from_vec(vec![0.0, 0.0, -mu * m / (r * r)]);
        assert!(
            (&qq - &qex).amax() <= 16.0 * EPS * qex.amax(),
            "{qq} vs {qex}"
        );
    }
}

fn ball_body(mass: f64, com: [f64; 3], ic: Matrix3<f64>, g: [f64; 3]) -> Model {
    let i: [[f64; 3]; 3] = ic.transpose().into();
    let bodies = vec![BodySpec::new("top", WORLD, mass, com, i)
        .at([0.2, -0.1, 0.5])
        .rotated([0.9, -0.3, 0.1, 0.2])
        .joint(JointSpec::ball("pivot"))];
    Model::new(
        &bodies,
        Fields {
            gravity: g,
            attractors: vec![],
        },
    )
    .unwrap()
}

/// Rigid body on a ball joint: M = I_O (body frame, constant), G = -ω x (I_O ω) (Euler);
/// heavy top: Q = c x (Rᵀ m g) in the body frame.
#[test]
fn ball_joint_euler_and_heavy_top() {
    let ic = Matrix3::new(0.3, 0.02, -0.01, 0.02, 0.4, 0.03, -0.01, 0.03, 0.5);
    let mut rng = Rng(99);
    // (a) principal axes, CoM at the pivot
    let diag = Matrix3::from_diagonal(&Vector3::new(0.3, 0.4, 0.6));
    let model = ball_body(2.0, [0.0; 3], diag, [0.0; 3]);
    let mut d = TreeData::<f64>::new(&model);
    let (mut mm, mut gg, mut qq) = (DMatrix::zeros(0, 0), DVector::zeros(0), DVector::zeros(0));
    for _ in 0..5 {
        let (q, v, _) = random_state(&model, &mut rng);
        mass_matrix(&model, &mut d, &q, &mut mm);
        assert!(max_abs(&(&mm - DMatrix::from_iterator(3, 3, diag.iter().cloned()))) <= 4.0 * EPS);
        velocity_terms(&model, &mut d, &q, &v, &mut gg);
        let w = Vector3::new(v[0], v[1], v[2]);
        let gex = -w.cross(&(diag * w));
        assert!((Vector3::new(gg[0], gg[1], gg[2]) - gex).amax() <= 8.0 * EPS);
    }
    // (b) heavy top: CoM offset, general inertia, gravity
    let (mass, com) = (1.5, Vector3::new(0.05, -0.02, 0.3));
    let gvec = Vector3::new(0.0, 0.0, -9.81);
    let model = ball_body(mass, [com[0], com[1], com[2]], ic, [0.0, 0.0, -9.81]);
    let mut d = TreeData::<f64>::new(&model);
    let io = ic + (Matrix3::identity() * com.dot(&com) - com * com.transpose()) * mass;
    for _ in 0..5 {
        let (q, v, _) = random_state(&model, &mut rng);
        mass_matrix(&model, &mut d, &q, &mut mm);
        assert!(max_abs(&(&mm - DMatrix::from_iterator(3, 3, io.iter().cloned()))) <= 8.0 * EPS);
        velocity_terms(&model, &mut d, &q, &v, &mut gg);
        let w = Vector3::new(v[0], v[1], v[2]);
        let gex = -w.cross(&(io * w));
        assert!((Vector3::new(gg[0], gg[1], gg[2]) - gex).amax() <= 16.0 * EPS);
        applied_forces(&model, &mut d, 0.0, &q, &v, &mut qq);
        let (r, _) = body_pose(&model, &mut d, &q, 0);
        let qex = com.cross(&(r.transpose() * gvec * mass));
        assert!(
            (Vector3::new(qq[0], qq[1], qq[2]) - qex).amax() <= 32.0 * EPS * 15.0,
            "{qq} {qex}"
        );
    }
}

/// Free body under gravity: the CoM accelerates with g and the angular part obeys Euler's equations
/// about the CoM, I_c ω' = -ω x I_c ω (body frame).
#[test]
fn free_body_falls() {
    let ic = Matrix3::new(0.3, 0.02, -0.01, 0.02, 0.4, 0.03, -0.01, 0.03, 0.5);
    let com = Vector3::new(0.1, -0.2, 0.05);
    let i: [[f64; 3]; 3] = ic.into();
    let g = [0.5, -0.3, -9.81];
    let bodies =
        vec![BodySpec::new("b", WORLD, 1.7, [com[0], com[1], com[2]], i)
            .joint(JointSpec::free("root"))];
    let model = Model::new(
        &bodies,
        Fields {
            gravity: g,
            attractors: vec![],
        },
    )
    .unwrap();
    let mut d = TreeData::<f64>::new(&model);
    let mut rng = Rng(5);
    let (mut mm, mut gg, mut qq) = (DMatrix::zeros(0, 0), DVector::zeros(0), DVector::zeros(0));
    for _ in 0..5 {
        let (q, v, _) = random_state(&model, &mut rng);
        mass_matrix(&model, &mut d, &q, &mut mm);
        velocity_terms(&model, &mut d, &q, &v, &mut gg);
        applied_forces(&model, &mut d, 0.0, &q, &v, &mut qq);
        let acc = mm.clone().cholesky().unwrap().solve(&(&gg + &qq));
        // v[0..3] is the world velocity of the body origin, so acc[0..3] is its acceleration:
        // a_com = a_O + R (ω' x c + ω x (ω x c)).
        let w = Vector3::new(v[3], v[4], v[5]);
        let wdot = Vector3::new(acc[3], acc[4], acc[5]);
        let (r, _) = body_pose(&model, &mut d, &q, 0);
        let acom =
            Vector3::new(acc[0], acc[1], acc[2]) + r * (wdot.cross(&com) + w.cross(&w.cross(&com)));
        assert!(
            (acom - Vector3::from(g)).amax() <= 64.0 * EPS * 10.0,
            "{acom}"
        );
        let (acom2, alpha_w) = point_acceleration(&model, &mut d, &q, &v, acc.as_slice(), 0, &com);
        assert!((acom2 - acom).amax() <= 64.0 * EPS * 10.0);
        assert!((r * wdot - alpha_w).amax() <= 16.0 * EPS);
        let euler = ic * wdot + w.cross(&(ic * w));
        assert!(euler.amax() <= 64.0 * EPS, "{euler}");
    }
}

/// dT/dt along (q' = qdot(q, v), v' = A⁻¹ G) vanishes for a free conservative system without
/// fields, with T = ½ vᵀ A(q) v evaluated over Dual64 — checks G against A (skew-symmetry of
/// Ȧ - 2C). Also T from body velocities equals ½ vᵀ A v.
#[test]
fn kinetic_energy_is_conserved_by_g() {
    for m in [zoo(Fields::default()), zoo_extras(Fields::default())] {
        kinetic_energy_is_conserved_on(&m);
    }
}

fn kinetic_energy_is_conserved_on(model: &Model) {
    let model = model.clone();
    let mut d = TreeData::<f64>::new(&model);
    let mut dd = TreeData::<Dual64>::new(&model);
    let mut rng = Rng(2024);
    let (mut mm, mut gg, mut qd) = (DMatrix::zeros(0, 0), DVector::zeros(0), DVector::zeros(0));
    let mut md = DMatrix::zeros(0, 0);
    for _ in 0..10 {
        let (q, v, _) = random_state(&model, &mut rng);
        mass_matrix(&model, &mut d, &q, &mut mm);
        velocity_terms(&model, &mut d, &q, &v, &mut gg);
        let acc = mm.clone().cholesky().unwrap().solve(&gg);
        qdot(&model, &q, &v, &mut qd);
        let (qs, vs) = (seeded(&q, qd.as_slice()), seeded(&v, acc.as_slice()));
        mass_matrix(&model, &mut dd, &qs, &mut md);
        let vv = DVector::from_vec(vs.clone());
        let t = vv.dot(&(&md * &vv)) * 0.5;
        assert!(
            t.eps.abs() <= 1e3 * EPS * t.re,
            "dT/dt = {:e}, T = {}",
            t.eps,
            t.re
        );
        let t2 = kinetic_energy(&model, &mut dd, &qs, &vs);
        assert!((t2 - t).re.abs() <= 64.0 * EPS * t.re && (t2 - t).eps.abs() <= 1e3 * EPS * t.re);
    }
}

/// Full energy balance with gravity, attraction, springs and dampers (and, on [`zoo_extras`],
/// armature in T, gravity compensation in V, reference positions):
/// d(T + V)/dt = -Σ d v² along the motion, over Dual64.
#[test]
fn energy_balance_with_fields() {
    for m in [zoo(zoo_fields()), zoo_extras(zoo_fields())] {
        energy_balance_on(&m);
    }
}

fn energy_balance_on(model: &Model) {
    let model = model.clone();
    let mut d = TreeData::<f64>::new(&model);
    let mut dd = TreeData::<Dual64>::new(&model);
    let mut rng = Rng(77);
    let (mut mm, mut gg, mut qq, mut qd) = (
        DMatrix::zeros(0, 0),
        DVector::zeros(0),
        DVector::zeros(0),
        DVector::zeros(0),
    );
    for _ in 0..10 {
        let (q, v, _) = random_state(&model, &mut rng);
        mass_matrix(&model, &mut d, &q, &mut mm);
        velocity_terms(&model, &mut d, &q, &v, &mut gg);
        applied_forces(&model, &mut d, 0.0, &q, &v, &mut qq);
        let acc = mm.clone().cholesky().unwrap().solve(&(&gg + &qq));
        qdot(&model, &q, &v, &mut qd);
        let (qs, vs) = (seeded(&q, qd.as_slice()), seeded(&v, acc.as_slice()));
        let e = kinetic_energy(&model, &mut dd, &qs, &vs) + potential_energy(&model, &mut dd, &qs);
        let mut diss = 0.0;
        for j in model.joints() {
            for k in 0..j.nv {
                diss -= j.damping * v[j.iv + k] * v[j.iv + k];
            }
        }
        assert!(
            (e.eps - diss).abs() <= 1e3 * EPS * (1.0 + e.re.abs()),
            "{} vs {diss}",
            e.eps
        );
    }
}

/// Point kinematics: velocity = d/dt position (dual numbers along qdot), Jacobian · v = (ω, v_p),
/// acceleration = d/dt velocity, Ṙ = [ω]x R, and Jᵀ F from `body_point_force` has power F · v_p.
#[test]
fn point_kinematics_consistency() {
    let model = zoo(Fields::default());
    let mut d = TreeData::<f64>::new(&model);
    let mut dd = TreeData::<Dual64>::new(&model);
    let mut rng = Rng(31337);
    let (mut qd, mut jac, mut tau) = (DVector::zeros(0), DMatrix::zeros(0, 0), DVector::zeros(0));
    let p = Vector3::new(0.1, -0.2, 0.3);
    let pd = p.map(Dual64::from_re);
    for _ in 0..5 {
        let (q, v, a) = random_state(&model, &mut rng);
        qdot(&model, &q, &v, &mut qd);
        let (qs, vs) = (seeded(&q, qd.as_slice()), seeded(&v, &a));
        for b in 0..model.bodies().len() {
            let vp = point_velocity(&model, &mut d, &q, &v, b, &p);
            let xs = point_position(&model, &mut dd, &qs, b, &pd);
            assert!((xs.map(|x| x.eps) - vp).amax() <= 64.0 * EPS, "body {b}");
            let w = body_angular_velocity(&model, &mut d, &q, &v, b);
            let (rs, _) = body_pose(&model, &mut dd, &qs, b);
            let (r, _) = body_pose(&model, &mut d, &q, b);
            let rdot = rs.map(|x| x.eps);
            assert!((rdot - super::spatial::skew(&w) * r).amax() <= 64.0 * EPS);
            let (ap, alpha) = point_acceleration(&model, &mut d, &q, &v, &a, b, &p);
            let vps = point_velocity(&model, &mut dd, &qs, &vs, b, &pd);
            assert!((vps.map(|x| x.eps) - ap).amax() <= 256.0 * EPS, "body {b}");
            let ws = body_angular_velocity(&model, &mut dd, &qs, &vs, b);
            assert!((ws.map(|x| x.eps) - alpha).amax() <= 256.0 * EPS);
            point_jacobian(&model, &mut d, &q, b, &p, &mut jac);
            let jv = &jac * DVector::from_vec(v.clone());
            assert!((Vector3::new(jv[0], jv[1], jv[2]) - w).amax() <= 16.0 * EPS);
            assert!((Vector3::new(jv[3], jv[4], jv[5]) - vp).amax() <= 16.0 * EPS);
            let f = Vector3::new(0.3, -1.2, 0.7);
            tau.fill(0.0);
            body_point_force(&model, &mut d, &q, b, &p, &f, &mut tau);
            let power = tau.dot(&DVector::from_vec(v.clone()));
            assert!((power - f.dot(&vp)).abs() <= 64.0 * EPS);
            let quat = body_quaternion(&model, &mut d, &q, b);
            let rq = super::spatial::rot_quat(quat[0], quat[1], quat[2], quat[3]);
            assert!((rq - r).amax() <= 16.0 * EPS);
        }
    }
}

/// The subtree sums of [`weighted_points_jacobian`] against two other routes to the same
/// Jacobian of c = sum_i w_i p_i: the weighted sum of each point's own Jacobian
/// ([`point_jacobian`]: a walk to the root per point), and J_c v = dc/dt by a dual number through
/// the positions. On the zoo (every joint type, several joints per body, a welded body folded into
/// its parent, two roots), with a negative weight and a point listed twice. Control: a point's
/// weight changed in one route only is seen.
#[test]
fn weighted_points_jacobian_matches_the_point_jacobians() {
    let model = zoo(Fields::default());
    let nb = model.bodies().len();
    let (mut d, mut dd) = (
        TreeData::<f64>::new(&model),
        TreeData::<Dual64>::new(&model),
    );
    let mut rng = Rng(2718);
    let points: Vec<(usize, Vector3<f64>, f64)> = (0..nb)
        .chain([nb - 1])
        .map(|b| {
            let p = Vector3::new(rng.next(), rng.next(), rng.next());
            (b, p, if b == 1 { -0.4 } else { 0.5 + rng.next().abs() })
        })
        .collect();
    let (mut sub, mut jc, mut jp) = (vec![], DMatrix::zeros(3, model.nv()), DMatrix::zeros(0, 0));
    let mut qd = DVector::zeros(0);
    for _ in 0..5 {
        let (q, v, _) = random_state(&model, &mut rng);
        forward_kinematics(&model, &mut d, &q);
        weighted_points_jacobian(&model, &d, points.iter().copied(), &mut sub, &mut jc);
        let route = |w_of: &dyn Fn(usize) -> f64, d: &mut TreeData<f64>, jp: &mut DMatrix<f64>| {
            let mut sum = DMatrix::zeros(3, model.nv());
            for (i, (b, p, _)) in points.iter().enumerate() {
                point_jacobian(&model, d, &q, *b, p, jp);
                sum += jp.rows(3, 3) * w_of(i);
            }
            sum
        };
        let sum = route(&|i| points[i].2, &mut d, &mut jp);
        let scale = max_abs(&sum);
        assert!(scale > 0.1);
        assert!(
            max_abs(&(&jc - &sum)) <= 64.0 * EPS * scale,
            "{jc} vs {sum}"
        );
        // control: one weight off by 1 % in the per-point route
        let off = route(
            &|i| points[i].2 * if i == 2 { 1.01 } else { 1.0 },
            &mut d,
            &mut jp,
        );
        assert!(max_abs(&(&jc - &off)) > 1e-4 * scale);
        // J_c v = dc/dt
        qdot(&model, &q, &v, &mut qd);
        let qs = seeded(&q, qd.as_slice());
        let mut cdot = Vector3::zeros();
        for (b, p, w) in &points {
            cdot += point_position(&model, &mut dd, &qs, *b, &p.map(Dual64::from_re))
                .map(|x| x.eps)
                * *w;
        }
        let jv = &jc * DVector::from_vec(v.clone());
        assert!((Vector3::new(jv[0], jv[1], jv[2]) - cdot).amax() <= 64.0 * EPS * scale);
    }
}

/// The velocity-product accelerations the point kinematics read after the forces' RNEA
/// ([`bias`], then [`forward_bias_acceleration`] without a pass of its own) are a gravity-free
/// pass's bit for bit, and the second derivative of each point's position along dv/dt = 0 (a
/// dual number through the velocity). Control: a pass with the base accelerating by -g (the
/// RNEA's former accelerations) is off by g at every point.
#[test]
fn bias_accelerations_reuse_the_inverse_dynamics_pass() {
    let model = zoo(zoo_fields());
    let (mut d, mut own) = (TreeData::<f64>::new(&model), TreeData::<f64>::new(&model));
    let mut dd = TreeData::<Dual64>::new(&model);
    let g = Vector3::from(model.fields.gravity);
    let p = Vector3::new(0.1, -0.2, 0.3);
    let pd = p.map(Dual64::from_re);
    let (mut out, mut qd) = (DVector::zeros(0), DVector::zeros(0));
    let zero = vec![0.0; model.nv()];
    let mut rng = Rng(0xacce1);
    for _ in 0..5 {
        let (q, v, _) = random_state(&model, &mut rng);
        bias(&model, &mut d, &q, &v, &g, &mut out);
        forward_bias_acceleration(&model, &mut d);
        forward_kinematics(&model, &mut own, &q);
        forward_velocity(&model, &mut own, &v);
        forward_bias_acceleration(&model, &mut own);
        qdot(&model, &q, &v, &mut qd);
        let (qs, vs) = (seeded(&q, qd.as_slice()), seeded(&v, &zero));
        let mut with_g = TreeData::<f64>::new(&model);
        forward_kinematics(&model, &mut with_g, &q);
        forward_velocity(&model, &mut with_g, &v);
        forward_acceleration(&model, &mut with_g, &zero, &g);
        for b in 0..model.bodies().len() {
            let (pk, po) = (
                point_kinematics(&model, &d, b, &p),
                point_kinematics(&model, &own, b, &p),
            );
            assert!(pk.acc == po.acc && pk.alpha == po.alpha, "body {b}");
            let vps = point_velocity(&model, &mut dd, &qs, &vs, b, &pd);
            assert!(
                (vps.map(|x| x.eps) - po.acc).amax() <= 256.0 * EPS,
                "body {b}"
            );
            let kept = point_kinematics(&model, &with_g, b, &p).acc;
            assert!(
                (kept - po.acc + g).amax() <= 64.0 * EPS * g.norm(),
                "body {b}"
            );
            assert!((kept - po.acc).amax() > 9.0, "body {b}: the control");
        }
    }
}

/// The free-joint quaternion rate ½ q ⊗ (0, ω_body) agrees with the body rotation's derivative.
#[test]
fn qdot_matches_rotation_rate() {
    let model = zoo(Fields::default());
    let mut dd = TreeData::<Dual64>::new(&model);
    let mut rng = Rng(8);
    let mut qd = DVector::zeros(0);
    let (q, v, _) = random_state(&model, &mut rng);
    qdot(&model, &q, &v, &mut qd);
    // ball quaternion stays unit to first order
    let b = model.joint_q_range(model.joint_id("shoulder").unwrap());
    let dn: f64 = b.clone().map(|i| q[i] * qd[i]).sum();
    assert!(dn.abs() <= 4.0 * EPS);
    let qs = seeded(&q, qd.as_slice());
    let (rs, _) = body_pose(&model, &mut dd, &qs, 0);
    let r = rs.map(|x| x.re);
    let w = Vector3::new(v[3], v[4], v[5]);
    assert!((rs.map(|x| x.eps) - r * super::spatial::skew(&w)).amax() <= 16.0 * EPS);
}

/// Nested duals: the second derivative of T along a line is available (generic scalar).
#[test]
fn works_over_second_order_duals() {
    use num_dual::Dual2_64;
    let model = double_pendulum(1.0, 1.0, 1.0, 1.0, 0.0001, 0.0001, 9.81);
    let mut d = TreeData::<Dual2_64>::new(&model);
    let th = Dual2_64::from_re(0.4).derivative();
    let q = [Dual2_64::from_re(0.1), th];
    let mut mm = DMatrix::zeros(0, 0);
    mass_matrix(&model, &mut d, &q, &mut mm);
    // M11 = J1 + J2 + 1 + 2 + 2 cos θ2: second derivative -2 cos θ2
    assert!((mm[(0, 0)].v2 + 2.0 * 0.4f64.cos()).abs() <= 8.0 * EPS);
    fn is_scalar<S: Scalar>(_: &S) {}
    is_scalar(&mm[(0, 0)]);
}

#[test]
fn validation_errors() {
    let ok = |b: Vec<BodySpec>| Model::new(&b, Fields::default());
    let err = |b: Vec<BodySpec>| ok(b).unwrap_err().to_string();
    let iso = [[0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.1]];
    let e = err(vec![BodySpec::new("neg", WORLD, -1.0, [0.0; 3], iso)]);
    assert!(
        e.contains("'neg'") && e.contains("mass must be positive"),
        "{e}"
    );
    let e = err(vec![BodySpec::new(
        "npd",
        WORLD,
        1.0,
        [0.0; 3],
        [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]],
    )]);
    assert!(
        e.contains("'npd'") && e.contains("not positive definite nor semi-definite"),
        "{e}"
    );
    let e = err(vec![BodySpec::new(
        "tri",
        WORLD,
        1.0,
        [0.0; 3],
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 3.0]],
    )]);
    assert!(e.contains("'tri'") && e.contains("triangle"), "{e}");
    let e = err(vec![BodySpec::new(
        "asym",
        WORLD,
        1.0,
        [0.0; 3],
        [[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    )]);
    assert!(e.contains("symmetric"), "{e}");
    let e = err(vec![
        BodySpec::new("b", WORLD, 1.0, [0.0; 3], iso).joint(JointSpec::hinge("h0", [0.0; 3]))
    ]);
    assert!(
        e.contains("'h0'") && e.contains("'b'") && e.contains("axis"),
        "{e}"
    );
    let e = err(vec![BodySpec::new("orphan", "nobody", 1.0, [0.0; 3], iso)]);
    assert!(
        e.contains("'orphan'") && e.contains("unknown parent 'nobody'"),
        "{e}"
    );
    let e = err(vec![
        BodySpec::new("a", WORLD, 1.0, [0.0; 3], iso),
        BodySpec::new("b", "a", 1.0, [0.0; 3], iso).joint(JointSpec::free("f")),
    ]);
    assert!(e.contains("'f'") && e.contains("free joint"), "{e}");
    let e = err(vec![BodySpec::new(
        "z",
        WORLD,
        0.0,
        [0.0; 3],
        [[0.0; 3]; 3],
    )]);
    assert!(e.contains("massless"), "{e}");
    // mass 0 with an inertia (a rotor) is a semi-definite body
    assert!(ok(vec![BodySpec::new("rotor", WORLD, 0.0, [0.0; 3], iso)]).is_ok());
    let mut ml = BodySpec::massless("m", WORLD);
    ml.mass = 1.0;
    assert!(err(vec![ml]).contains("flagged massless"));
    let e = err(vec![
        BodySpec::new("a", WORLD, 1.0, [0.0; 3], iso).joint(JointSpec::hinge("j", [1.0, 0.0, 0.0])),
        BodySpec::new("a", WORLD, 1.0, [0.0; 3], iso),
    ]);
    assert!(e.contains("duplicate body"), "{e}");
    let e = err(vec![BodySpec::new("a", WORLD, 1.0, [0.0; 3], iso)
        .joint(JointSpec::ball("s").with_spring(1.0, 0.0))]);
    assert!(e.contains("springs"), "{e}");
    // accepted: point mass, massless, rod-free PD
    assert!(ok(vec![
        BodySpec::massless("m", WORLD).joint(JointSpec::slide("x", [1.0, 0.0, 0.0])),
        BodySpec::point_mass("p", "m", 1.0, [0.0; 3])
    ])
    .is_ok());
}

/// Serde round trip of the specifications (the scene layer deserialises them).
#[test]
fn spec_serde_roundtrip() {
    let b = BodySpec::new(
        "a",
        WORLD,
        1.0,
        [0.0; 3],
        [[0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.1]],
    )
    .joint(JointSpec::hinge("h", [0.0, 0.0, 1.0]).with_damping(0.5));
    let s = serde_json::to_string(&b).unwrap();
    let b2: BodySpec = serde_json::from_str(&s).unwrap();
    assert_eq!(b, b2);
    let j: JointSpec =
        serde_json::from_str(r#"{"name": "q", "type": "slide", "axis": [1, 0, 0]}"#).unwrap();
    assert_eq!(j, JointSpec::slide("q", [1.0, 0.0, 0.0]));
}

/// Springs and dampers of hinge/slide joints: Q = -k (q - q_ref) - d v; ball/free dampers -d v.
#[test]
fn springs_and_dampers() {
    let bodies = vec![
        BodySpec::massless("m", WORLD)
            .joint(
                JointSpec::hinge("h", [0.0, 0.0, 1.0])
                    .with_spring(3.0, 0.25)
                    .with_damping(0.5),
            )
            .joint(JointSpec::slide("s", [1.0, 0.0, 0.0]).with_spring(2.0, -0.5)),
        BodySpec::new(
            "b",
            "m",
            1.0,
            [0.0; 3],
            [[0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.1]],
        )
        .joint(JointSpec::ball("ball").with_damping(0.7)),
    ];
    let model = Model::new(&bodies, Fields::default()).unwrap();
    let mut d = TreeData::<f64>::new(&model);
    let q = [0.75, 0.5, 1.0, 0.0, 0.0, 0.0];
    let v = [2.0, -1.0, 0.25, 0.5, -1.0];
    let mut qq = DVector::zeros(0);
    applied_forces(&model, &mut d, 0.0, &q, &v, &mut qq);
    let ex = [
        -3.0 * 0.5 - 0.5 * 2.0,
        -2.0 * 1.0,
        -0.7 * 0.25,
        -0.7 * 0.5,
        0.7,
    ];
    for (i, e) in ex.iter().enumerate() {
        assert!((qq[i] - e).abs() <= 4.0 * EPS, "{i}: {} vs {e}", qq[i]);
    }
    assert!((potential_energy(&model, &mut d, &q) - (1.5 * 0.25 + 1.0)).abs() <= 4.0 * EPS);
}

/// Couple hook: power of `body_torque` is τ · ω_world; a non-unit quaternion gives the same
/// mass matrix as its normalisation (implicit normalisation).
#[test]
fn torque_hook_and_quaternion_scaling() {
    let model = zoo(Fields::default());
    let mut d = TreeData::<f64>::new(&model);
    let mut rng = Rng(11);
    let (q, v, _) = random_state(&model, &mut rng);
    let tq = Vector3::new(0.4, 0.1, -0.9);
    let mut tau = DVector::zeros(model.nv());
    for b in 0..model.bodies().len() {
        tau.fill(0.0);
        body_torque(&model, &mut d, &q, b, &tq, &mut tau);
        let w = body_angular_velocity(&model, &mut d, &q, &v, b);
        let p = tau.dot(&DVector::from_vec(v.clone()));
        assert!((p - tq.dot(&w)).abs() <= 32.0 * EPS, "body {b}");
    }
    let (mut m1, mut m2) = (DMatrix::zeros(0, 0), DMatrix::zeros(0, 0));
    mass_matrix(&model, &mut d, &q, &mut m1);
    let mut q2 = q.clone();
    for x in &mut q2[3..11] {
        *x *= 1.7; // free and ball quaternions
    }
    mass_matrix(&model, &mut d, &q2, &mut m2);
    assert!(max_abs(&(&m1 - &m2)) <= 64.0 * EPS * max_abs(&m1));
}

/// Charts: (q ⊕ δ) ⊖ q = δ; d/dε (q ⊕ ε v) at 0 = qdot(q, v) and d/dε ((q ⊕ ε v) ⊖ q) = v over
/// Dual64 (the series branches at δ = 0 carry exact derivatives).
#[test]
fn configuration_charts() {
    let model = zoo(Fields::default());
    let mut rng = Rng(4242);
    let (mut q1, mut dl, mut qd) = (DVector::zeros(0), DVector::zeros(0), DVector::zeros(0));
    let (mut q1d, mut dld) = (DVector::zeros(0), DVector::zeros(0));
    for k in 0..10 {
        let (q, v, _) = random_state(&model, &mut rng);
        let s = [1e-3, 0.1, 1.0][k % 3];
        let delta: Vec<f64> = v.iter().map(|x| x * s).collect();
        integrate_configuration(&model, &q, &delta, &mut q1);
        difference_configuration(&model, &q, q1.as_slice(), &mut dl);
        let err = (&dl - DVector::from_vec(delta.clone())).amax();
        assert!(err <= 16.0 * EPS, "{err:e}");
        let qs: Vec<Dual64> = q.iter().map(|&x| Dual64::from_re(x)).collect();
        let ev: Vec<Dual64> = v.iter().map(|&x| Dual64::new(0.0, x)).collect();
        integrate_configuration(&model, &qs, &ev, &mut q1d);
        qdot(&model, &q, &v, &mut qd);
        assert!((q1d.map(|x| x.eps) - &qd).amax() <= 4.0 * EPS);
        difference_configuration(&model, &qs, q1d.as_slice(), &mut dld);
        assert!((dld.map(|x| x.eps) - DVector::from_vec(v.clone())).amax() <= 8.0 * EPS);
    }
    let q = [0.6f64, 0.0, 0.8, 0.0];
    let l = quat_log(&q);
    let e = quat_exp(&l);
    assert!((0..4).all(|i| (e[i] - q[i]).abs() <= 4.0 * EPS));
    assert!((l[1] - 2.0 * 0.8f64.atan2(0.6)).abs() <= 4.0 * EPS);
}

/// Anchored joints rotate about the anchor (MuJoCo `pos`): the anchor stays fixed, and the anchored
/// hinge's inertia is I_yy + m d² about the axis.
#[test]
fn anchors_are_fixed_points() {
    let model = zoo(Fields::default());
    let mut d = TreeData::<f64>::new(&model);
    let mut rng = Rng(3);
    let pend = model.body_id("pend").unwrap();
    let arm1 = model.body_id("arm1").unwrap();
    let sh = model.joint_q_range(model.joint_id("shoulder").unwrap());
    let a_pend = Vector3::new(0.0, 0.0, 0.2);
    let a_sh = Vector3::new(0.05, 0.0, 0.1);
    let (q0, _, _) = random_state(&model, &mut rng);
    let p0 = point_position(&model, &mut d, &q0, pend, &a_pend);
    let s0 = point_position(&model, &mut d, &q0, arm1, &a_sh);
    assert!((p0 - Vector3::new(1.0, 0.0, 0.2)).amax() <= 4.0 * EPS);
    let mut mm = DMatrix::zeros(0, 0);
    for _ in 0..5 {
        let (mut q, _, _) = random_state(&model, &mut rng);
        q[..7].copy_from_slice(&q0[..7]); // same base pose
        let p = point_position(&model, &mut d, &q, pend, &a_pend);
        assert!((p - p0).amax() <= 4.0 * EPS);
        let s = point_position(&model, &mut d, &q, arm1, &a_sh);
        assert!((s - s0).amax() <= 16.0 * EPS, "{} {}", s, s0);
        // hinge angle theta about y: CoM = (1,0,0) + a + R_y(theta) (c - a)
        let th = q[model.nq() - 1];
        let com = point_position(&model, &mut d, &q, pend, &Vector3::new(0.0, 0.0, -0.5));
        let ex = Vector3::new(1.0 - 0.7 * th.sin(), 0.0, 0.2 - 0.7 * th.cos());
        assert!((com - ex).amax() <= 8.0 * EPS, "{com} {ex}");
        mass_matrix(&model, &mut d, &q, &mut mm);
        let n = model.nv() - 1;
        assert!((mm[(n, n)] - (0.05 + 1.0 * 0.49)).abs() <= 8.0 * EPS);
        assert!(q[sh.start] != q0[sh.start]);
    }
}

/// The articulated-body factorization (Table 7.1 in world coordinates): `A^-1 x` and `A x` against
/// the CRBA's A on every joint type at random states, over f64 and Dual64 (values and derivatives
/// along q). Negative control: a factorization left at another q misses by far more.
#[test]
fn articulated_body_factorization_matches_crba() {
    for m in [zoo(zoo_fields()), zoo_extras(zoo_fields())] {
        aba_matches_crba_on(&m);
    }
}

fn aba_matches_crba_on(m: &Model) {
    let m = m.clone();
    let nv = m.nv();
    let mut d = TreeData::<f64>::new(&m);
    let mut dd = TreeData::<Dual64>::new(&m);
    let mut rng = Rng(0x51ab_c0de_1234_0015);
    let (mut mm, mut mmd) = (DMatrix::zeros(0, 0), DMatrix::zeros(0, 0));
    for trial in 0..20 {
        let (q, x, _) = random_state(&m, &mut rng);
        let dq: Vec<f64> = (0..m.nq()).map(|_| rng.next()).collect();
        crba(&m, &mut d, &q, &mut mm);
        let rc = aba_factor(&m, &mut d, &q).unwrap();
        assert!(rc > 0.0 && rc <= 1.0);
        let mut ax = vec![0.0; nv];
        mass_mul(&m, &mut d, &x, &mut ax);
        let want = &mm * DVector::from_column_slice(&x);
        let scale = max_abs(&mm) * x.iter().fold(0.0f64, |s, v| s.max(v.abs()));
        let err = (DVector::from_column_slice(&ax) - &want).amax();
        assert!(err <= 64.0 * EPS * scale, "A x: {err:e}");
        // A^-1 (A x) = x, and A^-1 x against a dense Cholesky solve, relative to eps cond(A)
        let cond = {
            let e = mm.clone().symmetric_eigenvalues();
            e.max() / e.min()
        };
        let mut y = ax.clone();
        aba_solve(&m, &mut d, &mut y);
        let err = y
            .iter()
            .zip(&x)
            .fold(0.0f64, |s, (a, b)| s.max((a - b).abs()));
        assert!(
            err <= 64.0 * EPS * cond,
            "A^-1 A x: {err:e} (cond {cond:.1e})"
        );
        let dense = mm
            .clone()
            .cholesky()
            .unwrap()
            .solve(&DVector::from_column_slice(&x));
        let mut z = x.clone();
        aba_solve(&m, &mut d, &mut z);
        let err = (DVector::from_column_slice(&z) - &dense).amax();
        assert!(err <= 64.0 * EPS * cond * dense.amax(), "A^-1 x: {err:e}");
        // the block solve (the formulation's 1 + s solves in one sweep): each column as a solve
        // of its own, bit for bit (the columns' scratch kept apart)
        let cols = 1 + trial % 3;
        let mut block: Vec<f64> = (0..nv * cols).map(|_| rng.next()).collect();
        let mut each = block.clone();
        aba_solve_block(&m, &mut d, &mut block, cols);
        for col in each.chunks_mut(nv) {
            aba_solve(&m, &mut d, col);
        }
        assert_eq!(block, each, "block solve, {cols} columns");
        if trial == 0 {
            // negative control: the factorization of another q does not invert this A
            let (q2, _, _) = random_state(&m, &mut rng);
            aba_factor(&m, &mut d, &q2).unwrap();
            let mut w = ax.clone();
            aba_solve(&m, &mut d, &mut w);
            let off = w
                .iter()
                .zip(&x)
                .fold(0.0f64, |s, (a, b)| s.max((a - b).abs()));
            assert!(off > 1e-3, "stale factorization went unnoticed: {off:e}");
        }
        // over Dual64 along dq: d(A x)/dq matches the CRBA's dual A; A^-1 (A x) = x keeps a zero
        // derivative part (the factor 10 stands for the sums of up to nv = 15 terms of that size)
        let qd = seeded(&q, &dq);
        let xd: Vec<Dual64> = x.iter().map(|&v| Dual64::from_re(v)).collect();
        crba(&m, &mut dd, &qd, &mut mmd);
        aba_factor(&m, &mut dd, &qd).unwrap();
        let mut axd = vec![Dual64::from_re(0.0); nv];
        mass_mul(&m, &mut dd, &xd, &mut axd);
        let wantd = &mmd * DVector::from_column_slice(&xd);
        let dscale = scale.max(mmd.iter().fold(0.0f64, |s, v| s.max(v.eps.abs())));
        for k in 0..nv {
            assert!((axd[k].re - wantd[k].re).abs() <= 64.0 * EPS * scale);
            assert!((axd[k].eps - wantd[k].eps).abs() <= 64.0 * EPS * dscale * 10.0);
        }
        aba_solve(&m, &mut dd, &mut axd);
        for k in 0..nv {
            assert!((axd[k].re - x[k]).abs() <= 64.0 * EPS * cond);
            assert!(
                axd[k].eps.abs() <= 64.0 * EPS * cond * 10.0,
                "{:e}",
                axd[k].eps
            );
        }
    }
}

/// A massless leaf on a hinge makes A singular: the factorization names its dof (the dense
/// Cholesky of the same A fails too, or is at round-off).
#[test]
fn articulated_body_factorization_reports_a_singular_a() {
    let bodies = vec![
        BodySpec::point_mass("a", WORLD, 1.0, [0.5, 0.0, 0.0])
            .joint(JointSpec::hinge("j0", [0.0, 0.0, 1.0])),
        BodySpec::massless("b", "a")
            .at([0.5, 0.0, 0.0])
            .joint(JointSpec::hinge("j1", [0.0, 0.0, 1.0])),
    ];
    let m = Model::new(&bodies, Fields::default()).unwrap();
    let mut d = TreeData::<f64>::new(&m);
    let e = aba_factor(&m, &mut d, &[0.3, 0.2]).unwrap_err();
    assert_eq!(e.column, 1);
}

/// A single hinge with armature: `A = m l² + I_zz + armature` (closed form); the RNEA sees it
/// (`tau = A a` at rest without gravity), the ABA inverts it and `T = ½ A v²`. Negative control:
/// the same model with the armature zeroed misses the closed form by the armature.
#[test]
fn armature_closed_form() {
    let (m, l, izz, arm) = (1.5, 0.4, 0.02, 0.3);
    let body = |arm: f64| {
        BodySpec::new(
            "b",
            WORLD,
            m,
            [l, 0.0, 0.0],
            [[0.01, 0.0, 0.0], [0.0, 0.015, 0.0], [0.0, 0.0, izz]],
        )
        .joint(JointSpec::hinge("h", [0.0, 0.0, 1.0]).with_armature(arm))
    };
    let want = m * l * l + izz + arm;
    let model = Model::new(&[body(arm)], Fields::default()).unwrap();
    let mut d = TreeData::<f64>::new(&model);
    let mut a = DMatrix::zeros(0, 0);
    for q in [0.0, 0.7, -2.1] {
        crba(&model, &mut d, &[q], &mut a);
        assert!(
            (a[(0, 0)] - want).abs() <= 4.0 * EPS * want,
            "{}",
            a[(0, 0)]
        );
        let tau = rnea(&model, &mut d, &[q], &[0.0], &[2.0], &Vector3::zeros())[0];
        assert!((tau - 2.0 * want).abs() <= 8.0 * EPS * want);
        aba_factor(&model, &mut d, &[q]).unwrap();
        let mut x = [3.0];
        aba_solve(&model, &mut d, &mut x);
        assert!((x[0] - 3.0 / want).abs() <= 8.0 * EPS * x[0]);
        let mut y = [0.0];
        mass_mul(&model, &mut d, &[3.0], &mut y);
        assert!((y[0] - 3.0 * want).abs() <= 8.0 * EPS * y[0]);
        let t = kinetic_energy(&model, &mut d, &[q], &[2.0]);
        assert!((t - 0.5 * want * 4.0).abs() <= 8.0 * EPS * t);
    }
    // negative control: armature zeroed
    let bare = Model::new(&[body(0.0)], Fields::default()).unwrap();
    let mut d = TreeData::<f64>::new(&bare);
    crba(&bare, &mut d, &[0.7], &mut a);
    assert!((a[(0, 0)] - want).abs() > 0.9 * arm);
    // ball and free joints: armature on each of their dofs' diagonal entries
    let spec = |arm: f64, free: bool| {
        let j = if free {
            JointSpec::free("j")
        } else {
            JointSpec::ball("j")
        };
        BodySpec::new("b", WORLD, m, [l, 0.1, 0.0], inr(0.02, 0.03, 0.04, 0.004))
            .joint(j.with_armature(arm))
    };
    for free in [false, true] {
        let with = Model::new(&[spec(arm, free)], Fields::default()).unwrap();
        let without = Model::new(&[spec(0.0, free)], Fields::default()).unwrap();
        let mut rng = Rng(5);
        let (q, _, _) = random_state(&with, &mut rng);
        let (mut a1, mut a0) = (DMatrix::zeros(0, 0), DMatrix::zeros(0, 0));
        crba(&with, &mut with.data(), &q, &mut a1);
        crba(&without, &mut without.data(), &q, &mut a0);
        let diff = a1 - a0;
        let want = DMatrix::<f64>::identity(with.nv(), with.nv()) * arm;
        assert!(max_abs(&(diff - want)) <= 16.0 * EPS * 10.0);
    }
}

/// Gravity compensation: a pendulum with gravcomp = 1 feels no gravity (Q = 0, V constant); with
/// gravcomp = 0.25 it feels 3/4 of it; the force acts at the CoM (J_comᵀ), so a welded child's
/// compensation reaches its parent's joint. Negative control: gravcomp = 0 feels gravity.
#[test]
fn gravcomp_closed_form() {
    let (m, l, g) = (2.0, 0.5, 9.81);
    let model = |gc: f64, child_gc: f64| {
        let b = BodySpec::new(
            "p",
            WORLD,
            m,
            [0.0, 0.0, -l],
            [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]],
        )
        .joint(JointSpec::hinge("h", [0.0, 1.0, 0.0]))
        .with_gravcomp(gc);
        let c = BodySpec::point_mass("c", "p", 1.0, [0.3, 0.0, 0.0])
            .at([0.0, 0.0, -l])
            .with_gravcomp(child_gc);
        Model::new(
            &[b, c],
            Fields {
                gravity: [0.0, 0.0, -g],
                attractors: vec![],
            },
        )
        .unwrap()
    };
    let mut f = DVector::zeros(0);
    for q in [0.3, -1.2, 2.5] {
        let full = model(1.0, 1.0);
        let mut d = full.data::<f64>();
        applied_forces(&full, &mut d, 0.0, &[q], &[0.0], &mut f);
        assert!(f[0].abs() <= 32.0 * EPS * m * g * l, "{}", f[0]);
        natural_forces(&full, &mut d, &[q], &[0.0], &mut f);
        assert!(f[0].abs() <= 32.0 * EPS * m * g * l, "{}", f[0]);
        let v0 = potential_energy(&full, &mut d, &[0.0]);
        assert!((potential_energy(&full, &mut d, &[q]) - v0).abs() <= 32.0 * EPS * m * g * l);
        // closed form: pendulum p (CoM at distance l) and point c at (0.3, 0, -l) in p's frame
        let q_of = |gc_p: f64, gc_c: f64| {
            let (s, cq) = q.sin_cos();
            // generalized force of gravity on a CoM at body point (x, 0, z), world
            // z = -x sin q + z cos q: Q = (-m g) dz/dq = m g (x cos q + z sin q)
            let tp = (1.0 - gc_p) * m * g * (-l * s);
            let tc = (1.0 - gc_c) * 1.0 * g * (0.3 * cq - l * s);
            tp + tc
        };
        for (gp, gc) in [(0.25, 0.0), (0.0, 1.0), (0.0, 0.0), (-0.5, 2.0)] {
            let mdl = model(gp, gc);
            let mut d = mdl.data::<f64>();
            applied_forces(&mdl, &mut d, 0.0, &[q], &[0.0], &mut f);
            let want = q_of(gp, gc);
            assert!(
                (f[0] - want).abs() <= 64.0 * EPS * m * g,
                "{} vs {want}",
                f[0]
            );
        }
        // negative control: without compensation the full-gravity torque is far from 0
        let none = model(0.0, 0.0);
        applied_forces(&none, &mut none.data(), 0.0, &[q], &[0.0], &mut f);
        assert!(f[0].abs() > 0.1);
    }
}

/// Reference positions (MuJoCo `ref`): a hinge turns by q - ref and a slide moves by q - ref, so
/// q = ref is the pose of the placements (and the neutral configuration); the spring reference is
/// absolute in q. Negative control: the same pose at q = 0 differs.
#[test]
fn reference_position_closed_form() {
    let (l, r, rs) = (0.4, 0.7, -0.2);
    let b = BodySpec::point_mass("b", WORLD, 1.0, [l, 0.0, 0.0])
        .joint(
            JointSpec::hinge("h", [0.0, 0.0, 1.0])
                .with_reference(r)
                .with_spring(3.0, 0.1),
        )
        .joint(JointSpec::slide("s", [0.0, 0.0, 1.0]).with_reference(rs));
    let model = Model::new(&[b], Fields::default()).unwrap();
    let mut d = model.data::<f64>();
    let n = neutral(&model);
    assert_eq!(n.as_slice(), &[r, rs]);
    for (q, z) in [(0.0, 0.5), (r, rs), (1.9, -0.3)] {
        let p = point_position(&model, &mut d, &[q, z], 0, &Vector3::new(l, 0.0, 0.0));
        let want = Vector3::new(l * (q - r).cos(), l * (q - r).sin(), z - rs);
        assert!((p - want).amax() <= 4.0 * EPS, "{p} vs {want}");
        // spring: -k (q - springref), independent of ref
        let mut f = DVector::zeros(0);
        applied_forces(&model, &mut d, 0.0, &[q, z], &[0.0, 0.0], &mut f);
        assert!((f[0] + 3.0 * (q - 0.1)).abs() <= 4.0 * EPS * 3.0);
        let v = potential_energy(&model, &mut d, &[q, z]);
        assert!((v - 1.5 * (q - 0.1) * (q - 0.1)).abs() <= 8.0 * EPS);
    }
    // negative control: at q = 0 the body is not in the placements' pose
    let p = point_position(&model, &mut d, &[0.0, 0.0], 0, &Vector3::new(l, 0.0, 0.0));
    assert!((p - Vector3::new(l, 0.0, 0.0)).amax() > 0.1);
    // refused on ball and free joints
    let bad = BodySpec::point_mass("b", WORLD, 1.0, [l, 0.0, 0.0])
        .joint(JointSpec::ball("j").with_reference(0.1));
    assert!(Model::new(&[bad], Fields::default()).is_err());
    let bad = BodySpec::point_mass("b", WORLD, 1.0, [l, 0.0, 0.0])
        .joint(JointSpec::hinge("j", [0.0, 0.0, 1.0]).with_armature(-1.0));
    assert!(Model::new(&[bad], Fields::default()).is_err());
}

/// [`zoo_extras`]' bodies plus welded bodies in every position a robot file puts them: a weld on
/// a weld (rotated, with gravity compensation), a moving body below welds, a massless and a point
/// mass weld, and a weld on a body welded to the world.
fn welded_specs() -> Vec<BodySpec> {
    let mut specs = zoo_specs();
    specs.extend([
        BodySpec::new(
            "weld2",
            "weld",
            0.4,
            [0.02, 0.0, 0.1],
            inr(0.02, 0.03, 0.02, 0.004),
        )
        .at([0.1, -0.2, 0.05])
        .rotated([0.6, -0.2, 0.5, 0.1])
        .with_gravcomp(0.7),
        BodySpec::new(
            "below",
            "weld2",
            0.6,
            [0.1, 0.05, 0.0],
            inr(0.05, 0.04, 0.06, 0.0),
        )
        .at([0.0, 0.3, 0.1])
        .rotated([0.9, 0.0, 0.3, -0.2])
        .joint(JointSpec::hinge("knee", [0.3, 0.2, 1.0]).with_anchor([0.05, 0.0, 0.0])),
        BodySpec::point_mass("toe", "below", 0.2, [0.0, 0.1, -0.05]).at([0.2, 0.0, 0.0]),
        BodySpec::massless("frame", "tip")
            .at([0.0, 0.1, 0.2])
            .rotated([0.5, 0.5, -0.5, 0.5]),
        BodySpec::new(
            "table",
            WORLD,
            5.0,
            [0.0, 0.0, 0.4],
            inr(0.5, 0.5, 0.6, 0.0),
        )
        .at([2.0, 0.0, 0.0]),
        BodySpec::point_mass("lamp", "table", 0.3, [0.0, 0.0, 0.2]).at([0.1, 0.1, 0.8]),
    ]);
    specs
}

/// `specs` with a hinge at each welded body (not on the world): a tree whose links are not folded.
fn hinged_welds(specs: &[BodySpec]) -> Vec<BodySpec> {
    specs
        .iter()
        .map(|b| {
            if b.joints.is_empty() && b.parent != WORLD {
                let h = JointSpec::hinge(&format!("{}_hold", b.name), [0.3, -0.5, 0.8]);
                b.clone().joint(h)
            } else {
                b.clone()
            }
        })
        .collect()
}

/// Every body's pose, point velocity, acceleration and Jacobian equal in `f` at (q, v, a) and
/// in `r` at the same state lifted by `vix` (r's entries of f's velocities; the others 0).
fn same_point_kinematics(
    f: &Model,
    r: &Model,
    state: [&[f64]; 3],
    lifted: [&[f64]; 3],
    vix: &[usize],
) {
    let ([q, v, a], [qr, vr, ar]) = (state, lifted);
    let (mut df, mut dr) = (f.data::<f64>(), r.data::<f64>());
    let (mut jf, mut jr) = (DMatrix::zeros(0, 0), DMatrix::zeros(0, 0));
    let p = Vector3::new(0.05, -0.1, 0.2);
    for b in 0..f.bodies().len() {
        let name = &f.bodies()[b].name;
        let br = r.body_id(name).unwrap();
        let (pa, alpha) = point_acceleration(f, &mut df, q, v, a, b, &p);
        let (pra, ralpha) = point_acceleration(r, &mut dr, qr, vr, ar, br, &p);
        assert!(
            (pa - pra).amax() <= 256.0 * EPS * pra.amax().max(1.0),
            "{name}: acceleration"
        );
        assert!(
            (alpha - ralpha).amax() <= 256.0 * EPS * ralpha.amax().max(1.0),
            "{name}: alpha"
        );
        let (rf, pf) = body_pose(f, &mut df, q, b);
        let (rr, pr) = body_pose(r, &mut dr, qr, br);
        assert!(
            (rf - rr).amax() <= 16.0 * EPS && (pf - pr).amax() <= 16.0 * EPS,
            "{name}: pose"
        );
        let vp = point_velocity(f, &mut df, q, v, b, &p);
        let vpr = point_velocity(r, &mut dr, qr, vr, br, &p);
        assert!(
            (vp - vpr).amax() <= 64.0 * EPS * vpr.amax().max(1.0),
            "{name}: velocity"
        );
        point_jacobian(f, &mut df, q, b, &p, &mut jf);
        point_jacobian(r, &mut dr, qr, br, &p, &mut jr);
        for (k, &i) in vix.iter().enumerate() {
            for row in 0..6 {
                assert!(
                    (jf[(row, k)] - jr[(row, i)]).abs() <= 16.0 * EPS,
                    "{name}: J[{row}, {k}]"
                );
            }
        }
    }
}

/// Folding the welded bodies into their moving ancestor's link (model.rs `fold_welded`) leaves A,
/// G + Q, T, V and every body's point kinematics as the unfolded tree computes them. The
/// reference is the same tree with a hinge at each welded body, held at q = 0, v = 0, dv/dt = 0:
/// its links are not folded. Negative control: a weld placed 1 mm off moves the bodies.
#[test]
fn folded_welds_match_the_unfolded_tree() {
    let fields = zoo_fields();
    let specs = welded_specs();
    let folded = Model::new(&specs, fields.clone()).unwrap();
    let reference = Model::new(&hinged_welds(&specs), fields.clone()).unwrap();
    let mut shifted_specs = specs.clone();
    shifted_specs
        .iter_mut()
        .find(|b| b.name == "weld2")
        .unwrap()
        .pos[1] += 1e-3;
    let shifted = Model::new(&shifted_specs, fields).unwrap();
    // every welded body with a moving ancestor is folded; the world's welds (table, lamp) are one link
    assert_eq!(folded.links.len(), folded.joints().len() + 1);
    assert!(reference.links.len() > folded.links.len());
    let index = |names: &[String], of: &[String]| -> Vec<usize> {
        (names.iter())
            .map(|n| of.iter().position(|m| m == n).unwrap())
            .collect()
    };
    let qix = index(folded.q_names(), reference.q_names());
    let vix = index(folded.v_names(), reference.v_names());
    let lift = |x: &[f64], ix: &[usize], n: usize| {
        let mut y = vec![0.0; n];
        for (k, &i) in ix.iter().enumerate() {
            y[i] = x[k];
        }
        y
    };
    let (mut df, mut dr, mut ds) = (
        folded.data::<f64>(),
        reference.data::<f64>(),
        shifted.data(),
    );
    let (mut af, mut ar) = (DMatrix::zeros(0, 0), DMatrix::zeros(0, 0));
    let (mut ff, mut fr) = (DVector::zeros(0), DVector::zeros(0));
    let mut rng = Rng(0xf01d_5eed);
    let mut control = 0.0f64;
    for _ in 0..5 {
        let (q, v, a) = random_state(&folded, &mut rng);
        let (qr, vr) = (
            lift(&q, &qix, reference.nq()),
            lift(&v, &vix, reference.nv()),
        );
        let acc_r = lift(&a, &vix, reference.nv());
        crba(&folded, &mut df, &q, &mut af);
        crba(&reference, &mut dr, &qr, &mut ar);
        let sub = DMatrix::from_fn(vix.len(), vix.len(), |i, j| ar[(vix[i], vix[j])]);
        assert!((&af - &sub).amax() <= 64.0 * EPS * max_abs(&sub), "A");
        natural_forces(&folded, &mut df, &q, &v, &mut ff);
        natural_forces(&reference, &mut dr, &qr, &vr, &mut fr);
        for (k, &i) in vix.iter().enumerate() {
            assert!(
                (ff[k] - fr[i]).abs() <= 256.0 * EPS * fr.amax(),
                "G + Q[{k}]"
            );
        }
        let tf = kinetic_energy(&folded, &mut df, &q, &v);
        let tr = kinetic_energy(&reference, &mut dr, &qr, &vr);
        assert!((tf - tr).abs() <= 64.0 * EPS * tr.abs(), "T");
        let vf = potential_energy(&folded, &mut df, &q);
        let vrr = potential_energy(&reference, &mut dr, &qr);
        assert!((vf - vrr).abs() <= 64.0 * EPS * vrr.abs().max(1.0), "V");
        same_point_kinematics(&folded, &reference, [&q, &v, &a], [&qr, &vr, &acc_r], &vix);
        for b in 0..folded.bodies().len() {
            let (_, pf) = body_pose(&folded, &mut df, &q, b);
            let (_, ps) = body_pose(&shifted, &mut ds, &q, b);
            control = control.max((ps - pf).amax());
        }
    }
    assert!(
        control > 5e-4,
        "a weld 1 mm off went unnoticed: {control:e}"
    );
    crba_matches_rnea_on(&folded);
    aba_matches_crba_on(&folded);
}
