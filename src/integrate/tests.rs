//! Tests of the integrators: accuracy against closed forms, observed convergence orders of the
//! methods and of their dense outputs, stiffness, the `accepted` hook, error propagation and a
//! regression snapshot of the counters.

use super::radau5::RadauConsts;
use super::*;

/// Why a test problem stopped.
#[derive(Debug, Clone, PartialEq)]
struct Stop(f64);

#[derive(Clone, Copy, Debug)]
enum Eq {
    /// y' = -y.
    Decay,
    /// Prothero-Robinson y' = lambda (y - cos t) - sin t, y = cos t.
    ProtheroRobinson(f64),
    /// y1' = y2, y2' = -y1.
    Harmonic,
    /// y1' = y1 (1 - y1), y2' = -y1 y2, y(0) = (0.1, 1): y1 = e^t/(e^t + 9), y2 = 10/(e^t + 9).
    Logistic2,
    /// Van der Pol in Hairer's scaling: y1' = y2, y2' = ((1 - y1^2) y2 - y1) / eps.
    VanDerPol(f64),
}

impl Eq {
    fn dim(self) -> usize {
        match self {
            Eq::Decay | Eq::ProtheroRobinson(_) => 1,
            _ => 2,
        }
    }
    fn y0(self) -> Vec<f64> {
        match self {
            Eq::Decay | Eq::ProtheroRobinson(_) => vec![1.0],
            Eq::Harmonic => vec![1.0, 0.0],
            Eq::Logistic2 => vec![0.1, 1.0],
            Eq::VanDerPol(_) => vec![2.0, -0.66],
        }
    }
    fn exact(self, t: f64) -> Vec<f64> {
        match self {
            Eq::Decay => vec![(-t).exp()],
            Eq::ProtheroRobinson(_) => vec![t.cos()],
            Eq::Harmonic => vec![t.cos(), -t.sin()],
            Eq::Logistic2 => {
                let e = t.exp();
                vec![e / (e + 9.0), 10.0 / (e + 9.0)]
            }
            Eq::VanDerPol(_) => panic!("no closed form"),
        }
    }
}

/// A configurable test problem that logs what the integrator does.
struct Prob {
    eq: Eq,
    /// Project y onto the unit circle after each step (returns `Accept::Changed`).
    project: bool,
    /// `rhs` returns Err(Stop(t)) for t > this.
    fail_after: Option<f64>,
    /// `rhs` returns NaN for t > this.
    nan_after: Option<f64>,
    /// `accepted` returns Err for t1 > this.
    fail_accept_after: Option<f64>,
    /// `jacobian` returns Err for t > this.
    fail_jac_after: Option<f64>,
    /// (t0, t1) of every accepted step.
    log: Vec<(f64, f64)>,
    /// Evaluate the dense output at t0 + theta (t1 - t0) of every step.
    probe: Option<f64>,
    probes: Vec<(f64, Vec<f64>)>,
}

impl Prob {
    fn new(eq: Eq) -> Self {
        Prob {
            eq,
            project: false,
            fail_after: None,
            nan_after: None,
            fail_accept_after: None,
            fail_jac_after: None,
            log: Vec::new(),
            probe: None,
            probes: Vec::new(),
        }
    }
}

impl OdeProblem for Prob {
    type Error = Stop;
    fn dim(&self) -> usize {
        self.eq.dim()
    }
    fn rhs(&mut self, t: f64, y: &[f64], dy: &mut [f64]) -> Result<(), Stop> {
        if self.fail_after.is_some_and(|tf| t > tf) {
            return Err(Stop(t));
        }
        match self.eq {
            Eq::Decay => dy[0] = -y[0],
            Eq::ProtheroRobinson(l) => dy[0] = l * (y[0] - t.cos()) - t.sin(),
            Eq::Harmonic => {
                dy[0] = y[1];
                dy[1] = -y[0];
            }
            Eq::Logistic2 => {
                dy[0] = y[0] * (1.0 - y[0]);
                dy[1] = -y[0] * y[1];
            }
            Eq::VanDerPol(eps) => {
                dy[0] = y[1];
                dy[1] = ((1.0 - y[0] * y[0]) * y[1] - y[0]) / eps;
            }
        }
        if self.nan_after.is_some_and(|tn| t > tn) {
            dy[0] = f64::NAN;
        }
        Ok(())
    }
    fn jacobian(&mut self, t: f64, y: &[f64], j: &mut DMatrix<f64>) -> Result<(), Stop> {
        if self.fail_jac_after.is_some_and(|tf| t > tf) {
            return Err(Stop(t));
        }
        match self.eq {
            Eq::Decay => j[(0, 0)] = -1.0,
            Eq::ProtheroRobinson(l) => j[(0, 0)] = l,
            Eq::Harmonic => {
                j.copy_from_slice(&[0.0, -1.0, 1.0, 0.0]);
            }
            Eq::Logistic2 => {
                // column-major [[1 - 2 y1, 0], [-y2, -y1]]
                j.copy_from_slice(&[1.0 - 2.0 * y[0], -y[1], 0.0, -y[0]]);
            }
            Eq::VanDerPol(eps) => {
                j.copy_from_slice(&[
                    0.0,
                    (-2.0 * y[0] * y[1] - 1.0) / eps,
                    1.0,
                    (1.0 - y[0] * y[0]) / eps,
                ]);
            }
        }
        Ok(())
    }
    fn accepted(
        &mut self,
        t0: f64,
        t1: f64,
        y: &mut [f64],
        dense: &dyn DenseOutput,
    ) -> Result<Accept, Stop> {
        self.log.push((t0, t1));
        if let Some(th) = self.probe {
            let tp = t0 + th * (t1 - t0);
            let mut out = vec![0.0; y.len()];
            dense.eval(tp, &mut out);
            self.probes.push((tp, out));
        }
        if self.fail_accept_after.is_some_and(|tf| t1 > tf) {
            y[0] = 42.0;
            return Err(Stop(t1));
        }
        if self.project {
            let r = (y[0] * y[0] + y[1] * y[1]).sqrt();
            y[0] /= r;
            y[1] /= r;
            return Ok(Accept::Changed);
        }
        Ok(Accept::Unchanged)
    }
}

fn opts(tol: f64) -> DriverOptions {
    DriverOptions {
        rtol: tol,
        atol: tol,
        ..Default::default()
    }
}

fn run(
    method: Method,
    o: DriverOptions,
    p: &mut Prob,
    t0: f64,
    t1: f64,
) -> (Outcome<Stop>, IntegratorStats, Vec<f64>) {
    let mut y = p.eq.y0();
    let mut integ = Integrator::new(method, o, p.dim());
    let (out, st) = integ.integrate(p, t0, t1, &mut y);
    (out, st, y)
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// Least-squares slope of log(err) against log(h).
fn slope(hs: &[f64], errs: &[f64]) -> f64 {
    let x: Vec<f64> = hs.iter().map(|h| h.ln()).collect();
    let y: Vec<f64> = errs.iter().map(|e| e.ln()).collect();
    let m = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / m, y.iter().sum::<f64>() / m);
    let sxy: f64 = x.iter().zip(&y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx) * (a - mx)).sum();
    sxy / sxx
}

const ADAPTIVE: [Method; 3] = [Method::Dopri5, Method::Dop853, Method::Radau5];

fn fixed(h: f64) -> DriverOptions {
    DriverOptions {
        fixed_step: Some(h),
        // Radau's Newton iteration is stopped relative to the (transformed) tolerance: make it
        // converge far below the discretisation error.
        rtol: 1e-12,
        atol: 1e-12,
        ..Default::default()
    }
}

/// Global errors at T of fixed-step runs on the nonlinear Logistic2 problem.
fn global_errors(method: Method, t_end: f64, ns: &[usize]) -> (Vec<f64>, Vec<f64>) {
    let mut hs = Vec::new();
    let mut errs = Vec::new();
    for &n in ns {
        let h = t_end / n as f64;
        let m = match method {
            Method::Rk4 { .. } => Method::Rk4 { h },
            m => m,
        };
        let mut p = Prob::new(Eq::Logistic2);
        let (out, st, y) = run(m, fixed(h), &mut p, 0.0, t_end);
        assert_eq!(out, Outcome::Finished);
        assert_eq!(st.steps, n);
        // Fixed-step Radau may retry a step once with a fresh Jacobian; nothing else is rejected.
        assert!(st.rejected == 0 || method == Method::Radau5, "{st:?}");
        hs.push(h);
        errs.push(max_abs_diff(&y, &Eq::Logistic2.exact(t_end)));
    }
    (hs, errs)
}

#[test]
fn explore_orders() {
    for (m, ns) in [
        (Method::Rk4 { h: 0.0 }, vec![40usize, 80, 160, 320]),
        (Method::Dopri5, vec![40, 80, 160, 320]),
        (Method::Dop853, vec![10, 14, 20, 28]),
        (Method::Radau5, vec![5, 10, 20, 40, 80, 160]),
    ] {
        let (hs, errs) = global_errors(m, 10.0, &ns);
        eprintln!("{m:?} {errs:?} slope {}", slope(&hs, &errs));
    }
}
