use progmo::problems::particle;
use progmo::solve::*;
fn main() {
    let p = particle::example_2_1_through_rd0();
    let sol = solve(&p, &Settings::default());
    let tr = &sol.trajectory;
    println!("{:?} n={}", sol.code, tr.len());
    for k in 0..tr.len().min(40) { print!("{:.3}:{:.3} ", tr.t[k], tr.v_at(k)[2]); }
    println!();
    let p = particle::example_2_1();
    let mut s = Settings::default(); s.rtol=1e-6; s.atol=1e-8; s.drift = DriftControl::Baumgarte{alpha:5.0,beta:5.0};
    s.output = Output::Every(0.5);
    let sol = solve(&p, &s);
    let tr = &sol.trajectory;
    for k in 0..tr.len() { print!("{:.1}:{:.2e} ", tr.t[k], tr.residual_at(k)[0]); }
}
