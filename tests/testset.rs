//! IVP Test Set problems as progmo scenes (`references/testset/`), compared with the published
//! reference solutions in mixed significant digits (mescd) against cost.

use progmo::integrate::Method;
use progmo::scene::Scene;
use progmo::solve::{Output, Settings, Solution};
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn load(name: &str) -> Scene {
    Scene::load(root().join("references/testset").join(name)).expect("scene loads")
}

/// Car axis reference at t = 3: version (a), R/ex_reference.R "caraxis" (quad-precision GAMD),
/// y = (xl, yl, xr, yr, xl', yl', xr', yr', lambda1, lambda2).
const CARAXIS_REF: [f64; 10] = [
    0.493455784275402809122e-1,
    0.496989460230171153861,
    0.104174252488542151681e1,
    0.373911027265361256927,
    -0.770583684040972357970e-1,
    0.744686658723778553466e-2,
    0.175568157537232222276e-1,
    0.770341043779251976443,
    -0.473688659084893324729e-2,
    -0.110468033125734368808e-2,
];

/// Mixed significant digits as in the test set: -log10(max_i |y_i - ref_i| / (atol/rtol + |ref_i|)).
fn mescd(y: &[f64], reference: &[f64], ratio: f64) -> f64 {
    let e = y
        .iter()
        .zip(reference)
        .map(|(y, r)| (y - r).abs() / (ratio + r.abs()))
        .fold(0.0, f64::max);
    -e.log10()
}

fn worst_component(y: &[f64], reference: &[f64], ratio: f64) -> usize {
    let mut best = (0, -1.0);
    for (i, (y, r)) in y.iter().zip(reference).enumerate() {
        let e = (y - r).abs() / (ratio + r.abs());
        if e > best.1 {
            best = (i + 1, e);
        }
    }
    best.0
}

fn method_name(m: &Method) -> &'static str {
    match m {
        Method::Radau5 => "radau5",
        Method::Dop853 => "dop853",
        Method::Dopri5 => "dopri5",
        Method::Rk4 { .. } => "rk4",
    }
}

struct Row {
    method: &'static str,
    rtol: f64,
    atol: f64,
    steps: usize,
    rejected: usize,
    rhs: usize,
    jac: usize,
    lu: usize,
    scd_state: f64,
    scd_all: f64,
    /// Relative digits of the multipliers: -log10(max |l - ref| / |ref|).
    scd_lambda_rel: f64,
    /// 1-based index of the component with the largest scaled error (y(1:10)).
    worst: usize,
}

/// y at the end of a caraxis solve, in the test set's order; lambda in row order (axle, road)
/// is re-ordered to (road = lambda1, axle = lambda2).
fn caraxis_y(scene: &Scene, sol: &Solution) -> [f64; 10] {
    let tr = &sol.trajectory;
    let k = tr.len() - 1;
    assert!((tr.t[k] - 3.0).abs() < 1e-14, "last sample at t = 3");
    let rows: Vec<String> = scene.rows().iter().map(|r| r.name.clone()).collect();
    let road = rows.iter().position(|r| r == "road").unwrap();
    let axle = rows.iter().position(|r| r == "axle").unwrap();
    let (q, v, l) = (tr.q_at(k), tr.v_at(k), tr.lambda_at(k));
    [
        q[0], q[1], q[2], q[3], v[0], v[1], v[2], v[3], l[road], l[axle],
    ]
}

#[test]
#[allow(clippy::too_many_lines)] // over 100 lines before the lint: to split, not to grow
fn caraxis_digits_against_cost() {
    let scene = load("caraxis.toml");
    let mut table = Vec::new();
    let cases: Vec<(Method, f64)> = vec![
        (Method::Radau5, 1e-4),
        (Method::Radau5, 1e-6),
        (Method::Radau5, 1e-8),
        (Method::Radau5, 1e-10),
        (Method::Radau5, 1e-12),
        (Method::Dop853, 1e-4),
        (Method::Dop853, 1e-6),
        (Method::Dop853, 1e-8),
        (Method::Dop853, 1e-10),
        (Method::Dop853, 1e-12),
    ];
    for (method, tol) in cases {
        let settings = Settings {
            integrator: method,
            rtol: tol,
            atol: tol,
            output: Output::Every(3.0),
            ..scene.settings.clone()
        };
        let sol = scene.solve(&settings);
        assert!(
            sol.code.is_success(),
            "{} at {tol:e}: {:?}",
            method_name(&method),
            sol.code
        );
        let y = caraxis_y(&scene, &sol);
        let s = &sol.stats.integrator;
        table.push(Row {
            method: method_name(&method),
            rtol: tol,
            atol: tol,
            steps: s.steps,
            rejected: s.rejected,
            rhs: s.rhs_evals,
            jac: s.jacobian_evals,
            lu: s.lu_decompositions,
            scd_state: mescd(&y[..8], &CARAXIS_REF[..8], tol / tol),
            scd_all: mescd(&y, &CARAXIS_REF, tol / tol),
            scd_lambda_rel: mescd(&y[8..], &CARAXIS_REF[8..], 0.0),
            worst: worst_component(&y, &CARAXIS_REF, 1.0),
        });
    }
    println!("caraxis, t = 3, reference (a) R/ex_reference.R; mescd with atol/rtol = 1");
    println!("| method | rtol = atol | steps | rejected | rhs_evals | jacobian_evals | LU | mescd y(1:8) | mescd y(1:10) | worst i | lambda rel. digits |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for r in &table {
        println!(
            "| {} | {:.0e} | {} | {} | {} | {} | {} | {:.3} | {:.3} | {} | {:.2} |",
            r.method,
            r.rtol,
            r.steps,
            r.rejected,
            r.rhs,
            r.jac,
            r.lu,
            r.scd_state,
            r.scd_all,
            r.worst,
            r.scd_lambda_rel
        );
        let _ = r.atol;
    }
    // What is asserted (measured values in references/testset/README.md): the digits of the
    // 10 published components at t = 3 (8 state components + 2 multipliers; the multipliers never
    // limit) against the quad-precision reference, per method, at the two tightest tolerances,
    // and that tightening the tolerance by 100 gains digits (>= 1.4 per step of 100).
    let get = |m: &str, tol: f64| {
        table
            .iter()
            .find(|r| r.method == m && r.rtol == tol)
            .unwrap()
    };
    let floors = [
        ("dop853", 1e-10, 8.3),
        ("dop853", 1e-12, 10.3),
        ("radau5", 1e-10, 7.95),
        ("radau5", 1e-12, 9.6),
    ];
    for (m, tol, floor) in floors {
        let r = get(m, tol);
        assert!(
            r.scd_state >= floor,
            "{m} at {tol:e}: {:.3} digits < {floor}",
            r.scd_state
        );
        assert!(
            r.scd_all >= floor,
            "{m} at {tol:e}: lambda: {:.3} digits < {floor}",
            r.scd_all
        );
    }
    for m in ["dop853", "radau5"] {
        for pair in [[1e-4, 1e-6], [1e-6, 1e-8], [1e-8, 1e-10], [1e-10, 1e-12]] {
            let (a, b) = (get(m, pair[0]), get(m, pair[1]));
            assert!(
                b.scd_all >= a.scd_all + 1.4,
                "{m}: {:.2} -> {:.2}",
                a.scd_all,
                b.scd_all
            );
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Rigid slider crank (the rigid part of the Test Set's crank): closed-form comparison.

use num_dual::{Dual64, DualNum};

const M2: f64 = 0.151104;
const M3: f64 = 0.075552;
const L1: f64 = 0.15;
const L2: f64 = 0.30;
const J1: f64 = 0.002727;
const J2: f64 = 0.0045339259;
const OMEGA: f64 = 150.0;

/// Closed form of the rigid crank at time t (any dual type): positions (phi1, phi2, x3) from the
/// loop closure with cos(phi2) > 0, velocities differentiated by hand, and T = 1/2 v^T A v.
fn crank_closed_form(t: Dual64) -> ([Dual64; 3], [Dual64; 3], Dual64) {
    let rho = L1 / L2;
    let phi1 = t * OMEGA;
    let (s, c) = (phi1.sin(), phi1.cos());
    let sin2 = s * (-rho);
    let phi2 = sin2.asin();
    let cos2 = (-(sin2 * sin2) + 1.0).sqrt();
    let x3 = c * L1 + cos2 * L2;
    let dphi1 = Dual64::from_re(OMEGA);
    let dphi2 = c * (-rho * OMEGA) / cos2;
    let dx3 = s * (-L1 * OMEGA) - sin2 * dphi2 * L2;
    let a11 = J1 + M2 * L1 * L1;
    let a12 = (phi1 - phi2).cos() * (0.5 * L1 * L2 * M2);
    let tkin =
        (dphi1 * dphi1 * a11 + dphi1 * dphi2 * a12 * 2.0 + dphi2 * dphi2 * J2 + dx3 * dx3 * M3)
            * 0.5;
    ([phi1, phi2, x3], [dphi1, dphi2, dx3], tkin)
}

/// Reference y = (phi1, phi2, x3, phi1', phi2', x3', lambda_drive) at t; lambda_drive = (dT/dt)/Omega.
fn crank_reference(t: f64) -> [f64; 7] {
    let td = Dual64::from_re(t).derivative();
    let (q, v, tkin) = crank_closed_form(td);
    // The hand-derived velocities must equal the exact derivatives of the positions.
    for i in 0..3 {
        assert!(
            (v[i].re - q[i].eps).abs() <= 1e-12 * (1.0 + v[i].re.abs()),
            "closed form v{i}"
        );
    }
    [
        q[0].re,
        q[1].re,
        q[2].re,
        v[0].re,
        v[1].re,
        v[2].re,
        tkin.eps / OMEGA,
    ]
}

/// Published reference of the FLEXIBLE crank at t = 0.1 (Ex_crank.f `cranksoln`): y(1:3), y(8:10), y(24).
const CRANK_FLEX_REF: [f64; 7] = [
    0.1500000000000104e+002,
    -0.3311734988256260e+000,
    0.1697373328427860e+000,
    0.1500000000000000e+003,
    0.6025346755138369e+002,
    -0.8753116326670527e+001,
    0.2529857947066878e+002,
];

/// Digits of a rigid-crank solve against the closed form: min over samples of the mescd of q, v
/// and lambda(drive), with atol/rtol = 1.
fn crank_digits(sol: &Solution, drive: usize) -> (f64, f64, f64) {
    let tr = &sol.trajectory;
    let (mut dq, mut dv, mut dl) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
    for k in 0..tr.len() {
        let r = crank_reference(tr.t[k]);
        dq = dq.min(mescd(tr.q_at(k), &r[..3], 1.0));
        dv = dv.min(mescd(tr.v_at(k), &r[3..6], 1.0));
        dl = dl.min(mescd(&[tr.lambda_at(k)[drive]], &r[6..], 1.0));
    }
    (dq, dv, dl)
}

#[test]
fn crank_rigid_closed_form_digits_against_cost() {
    let scene = load("crank_rigid.toml");
    let rows: Vec<String> = scene.rows().iter().map(|r| r.name.clone()).collect();
    let drive = rows.iter().position(|r| r == "drive").unwrap();
    let cases: Vec<(Method, f64)> = vec![
        (Method::Radau5, 1e-6),
        (Method::Radau5, 1e-8),
        (Method::Radau5, 1e-10),
        (Method::Dop853, 1e-6),
        (Method::Dop853, 1e-8),
        (Method::Dop853, 1e-10),
        (Method::Dop853, 1e-12),
    ];
    println!("rigid crank vs closed form, t in [0, 0.1]; mescd (atol/rtol = 1), minimum over the samples:");
    println!("  'steps' = at every accepted (projected) step; 'dense' = dense output every 0.001 s (projected)");
    println!("| method | rtol = atol | steps | rhs_evals | q (steps) | v (steps) | lambda_drive (steps) | q (dense) | v (dense) | lambda_drive (dense) |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let mut results = Vec::new();
    for (method, tol) in cases {
        let base = Settings {
            integrator: method,
            rtol: tol,
            atol: tol,
            ..scene.settings.clone()
        };
        let at_steps = scene.solve(&Settings {
            output: Output::Steps,
            ..base.clone()
        });
        let dense = scene.solve(&Settings {
            output: Output::Every(0.001),
            ..base
        });
        for sol in [&at_steps, &dense] {
            assert!(
                sol.code.is_success(),
                "{} at {tol:e}: {:?}",
                method_name(&method),
                sol.code
            );
            let k = sol.trajectory.len() - 1;
            assert!((sol.trajectory.t[k] - 0.1).abs() < 1e-15);
        }
        let a = crank_digits(&at_steps, drive);
        let d = crank_digits(&dense, drive);
        let s = &at_steps.stats.integrator;
        println!(
            "| {} | {:.0e} | {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
            method_name(&method),
            tol,
            s.steps,
            s.rhs_evals,
            a.0,
            a.1,
            a.2,
            d.0,
            d.1,
            d.2
        );
        results.push((method_name(&method), tol, a, d));
    }
    let r = crank_reference(0.1);
    println!(
        "closed form at t = 0.1: phi1 = {:.16e}, phi2 = {:.16e}, x3 = {:.16e}",
        r[0], r[1], r[2]
    );
    println!(
        "  phi1' = {:.16e}, phi2' = {:.16e}, x3' = {:.16e}, lambda_drive = {:.16e}",
        r[3], r[4], r[5], r[6]
    );
    // Not a check of progmo: how far the rigid mechanism is from the published FLEXIBLE crank
    // (test set sign: AM w - F + GP^T lambda = 0, so its lambda3 = -lambda_drive).
    let rigid = [r[0], r[1], r[2], r[3], r[4], r[5], -r[6]];
    println!(
        "rigid closed form vs published flexible crank at t = 0.1: mescd positions {:.2}, velocities {:.2}, lambda3 rel. digits {:.2} (rigid {:.6}, flexible {:.6})",
        mescd(&rigid[..3], &CRANK_FLEX_REF[..3], 1.0),
        mescd(&rigid[3..6], &CRANK_FLEX_REF[3..6], 1.0),
        mescd(&rigid[6..], &CRANK_FLEX_REF[6..], 0.0),
        rigid[6],
        CRANK_FLEX_REF[6]
    );
    // Asserted (measured values in references/testset/README.md; floors just below the worst
    // measured): s = n, so at every accepted step the projection alone fixes q and v (to its
    // 1e-12 residual) whatever the tolerance: >= 11 digits in q, 10 in v, 9.5 in lambda_drive for
    // every case. Between steps (dense output, projected like the step ends): at rtol = atol =
    // 1e-10 >= 8.8 digits in q and 8 in v and lambda_drive for both methods (the floor of the
    // interpolant before projection; now exceeded).
    for (m, tol, a, d) in &results {
        assert!(
            a.0 >= 11.0 && a.1 >= 10.0 && a.2 >= 9.5,
            "{m} at {tol:e}, steps: {a:?}"
        );
        if *tol == 1e-10 {
            assert!(
                d.0 >= 8.8 && d.1 >= 8.0 && d.2 >= 8.0,
                "{m} at 1e-10, dense: {d:?}"
            );
        }
    }
}
