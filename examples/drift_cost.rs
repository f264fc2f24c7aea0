//! Extra CPU of projection over 10^4 periods, measured robustly on a noisy shared machine
//! (`progmo::problems::hard::measure_drift_cost`: projection on / off alternate and the minimum of
//! each is compared). Issue 5's target: residual < 1e-12 for at most +15 %. `progmo bench --only
//! drift` reports the same measurement.
//!
//! Run: `cargo run --release --example drift_cost [ROUNDS]` (default 7).

fn main() {
    let rounds: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(7);
    let d = progmo::problems::hard::measure_drift_cost(rounds);
    println!(
        "10^4 periods ({} steps), min of {}: projection {:.1} ms, none {:.1} ms, extra {:+.1} % \\
         (max residual: projection {:.1e}, none {:.1e})",
        d.steps,
        d.rounds,
        d.projection_s * 1e3,
        d.none_s * 1e3,
        (d.projection_s / d.none_s - 1.0) * 100.0,
        d.residual_projection,
        d.residual_none
    );
}
