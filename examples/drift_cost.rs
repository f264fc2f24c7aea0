//! Extra CPU of projection over 10^4 periods, measured robustly on a noisy shared machine: the two
//! runs (projection on / off, same problem and tolerances as `cargo bench --bench core -- drift`)
//! alternate `ROUNDS` times in one process and the minimum of each is compared (the minimum is the
//! run least disturbed by other load). Issue 5's target: at most +15 %.
//!
//! Run: `cargo run --release --example drift_cost [ROUNDS]` (default 7).

use progmo::problems::hard;
use progmo::solve::{solve_into, DriftControl, Sample, SampleSink, Settings};
use std::time::Instant;

struct Discard;
impl SampleSink for Discard {
    fn sample(&mut self, _: &Sample<'_>) {}
}

fn main() {
    let rounds: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(7);
    let p = hard::ten_thousand_periods();
    let settings = |d| Settings {
        rtol: 1e-8,
        atol: 1e-10,
        drift: d,
        ..Settings::default()
    };
    let on = settings(DriftControl::Projection {
        tol: 1e-12,
        max_iter: 8,
    });
    let off = settings(DriftControl::None);
    let (mut best_on, mut best_off) = (f64::INFINITY, f64::INFINITY);
    let mut residual_on = 0.0;
    for k in 0..rounds {
        let t = Instant::now();
        let sol = solve_into(&p, &on, &mut Discard);
        best_on = best_on.min(t.elapsed().as_secs_f64());
        residual_on = sol.max_residual.iter().fold(0.0f64, |m, x| m.max(*x));
        let t = Instant::now();
        let _ = solve_into(&p, &off, &mut Discard);
        best_off = best_off.min(t.elapsed().as_secs_f64());
        eprintln!("round {}/{rounds}: best so far {best_on:.3} s vs {best_off:.3} s", k + 1);
    }
    println!(
        "10^4 periods, min of {rounds}: projection {:.1} ms, none {:.1} ms, extra {:+.1} % (max residual with projection {:.1e})",
        best_on * 1e3,
        best_off * 1e3,
        (best_on / best_off - 1.0) * 100.0,
        residual_on
    );
}
