//! The servo analysis of a scene with `[[actuators]]` as `progmo validate` and `summary.json` report
//! it (issue 17): realization, relative degrees, index, and the internal dynamics
//! ([`crate::servo::internal`]): its dimension 2n - sum r_i, the frozen-time eigenvalues of its
//! linearization (at t0, and sampled along the motion), and the growth a perturbed run shows.

use super::{Scene, SceneSystem};
use crate::programme::Constraints;
use crate::servo::internal::Eigenvalue;
use crate::servo::{Analysis, Servo};
use crate::solve::Settings;

/// Samples of the motion at which the linearization is evaluated (evenly spread over the output).
pub const LINEARIZATION_SAMPLES: usize = 41;

/// Size of the perturbation of the growth run, relative to max(1, |x0|): large against the
/// solver's tolerances (the separation must be measurable), small enough to stay linear.
pub const PERTURBATION: f64 = 1e-6;

/// What the servo analysis reports.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ServoReport {
    /// At t0: realization, relative degrees, index, decoupling conditioning.
    #[serde(flatten)]
    pub analysis: Analysis,
    /// The internal dynamics.
    pub internal: Internal,
}

/// The internal (zero) dynamics.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Internal {
    /// 2n - sum r_i (0: flat, nothing left free).
    pub dimension: usize,
    /// Frozen-time eigenvalues of N^T J N at t0, largest real part first.
    pub eigenvalues_t0: Vec<Eigenvalue>,
    /// Along the motion (None: not computed, or dimension 0).
    pub along: Option<Along>,
    /// The separation of a perturbed run (None: not computed, or dimension 0).
    pub growth: Option<Growth>,
    /// "stable" (every frozen real part < 0 along the motion), "unstable" (some > 0), "marginal".
    pub stability: Option<&'static str>,
    /// With a positive largest real part: ln(1/rtol)/max_re, the time within which an error at the
    /// solver's relative tolerance grows to order one at that rate.
    pub horizon: Option<f64>,
}

/// Frozen-time eigenvalues along the solved motion.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Along {
    /// Number of states linearized.
    pub samples: usize,
    /// Largest real part over them, where, and the eigenvalues there.
    pub max_real: f64,
    pub t_max_real: f64,
    pub eigenvalues_at_max: Vec<Eigenvalue>,
    /// Smallest "largest real part" over the samples.
    pub min_max_real: f64,
}

/// A run started off the motion along the internal directions (projected onto the hidden
/// constraints), compared with the unperturbed run at the output samples (max norm over (q, v)).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Growth {
    pub initial_separation: f64,
    pub final_separation: f64,
    pub max_separation: f64,
    /// ln(final/initial)/(t_end - t0): the mean exponential rate seen.
    pub rate: f64,
    pub t_end: f64,
}

impl Scene {
    /// The servo analysis of a scene with `[[actuators]]` (None otherwise, or when the programme
    /// is not realizable at t0: [`Scene::servo_analysis`] reports that). With `along`, the scene
    /// is solved twice with `settings` (the motion, and a perturbed run) to report the
    /// eigenvalues along the motion and the growth seen.
    pub fn servo_report(&self, settings: &Settings, along: bool) -> Option<ServoReport> {
        let analysis = self.servo_analysis()?.ok()?;
        let SceneSystem::Tree(p) = &self.system else {
            return None;
        };
        let act = p.constraints.actuation()?;
        let servo = Servo::new(&p.model, &p.constraints, act).reduced(analysis.reduction.as_ref());
        let (deg, bn, tol) = (
            &analysis.degrees,
            &analysis.b_norms,
            settings.rank_dependent,
        );
        let n = p.v0.len();
        // one hidden constraint per derivative below each (effective) row's degree
        let dimension = (2 * n).saturating_sub(servo.hidden_names(deg).len());
        let lin0 = servo
            .internal_linearization(p.t0, &p.q0, &p.v0, deg, bn, tol)
            .ok()?;
        let mut internal = Internal {
            dimension,
            eigenvalues_t0: lin0.eigenvalues.clone(),
            along: None,
            growth: None,
            stability: None,
            horizon: None,
        };
        if along && dimension > 0 {
            let sol = self.solve(settings);
            let tr = &sol.trajectory;
            let count = tr.len().min(LINEARIZATION_SAMPLES);
            let mut a: Option<Along> = None;
            for j in 0..count {
                let k = if count > 1 {
                    j * (tr.len() - 1) / (count - 1)
                } else {
                    0
                };
                let Ok(lin) =
                    servo.internal_linearization(tr.t[k], tr.q_at(k), tr.v_at(k), deg, bn, tol)
                else {
                    continue;
                };
                let top = lin.eigenvalues[0].re;
                let x = a.get_or_insert(Along {
                    samples: 0,
                    max_real: f64::NEG_INFINITY,
                    t_max_real: tr.t[k],
                    eigenvalues_at_max: vec![],
                    min_max_real: f64::INFINITY,
                });
                x.samples += 1;
                x.min_max_real = x.min_max_real.min(top);
                if top > x.max_real {
                    (x.max_real, x.t_max_real) = (top, tr.t[k]);
                    x.eigenvalues_at_max = lin.eigenvalues;
                }
            }
            if let Some(x) = &a {
                internal.stability = Some(if x.max_real < 0.0 {
                    "stable"
                } else if x.max_real > 0.0 {
                    "unstable"
                } else {
                    "marginal"
                });
                if x.max_real > 0.0 {
                    internal.horizon = Some((1.0 / settings.rtol).ln() / x.max_real);
                }
            }
            internal.along = a;
            internal.growth =
                self.perturbed_growth(settings, &lin0.basis, deg, analysis.reduction.as_ref(), tr);
        }
        Some(ServoReport { analysis, internal })
    }

    /// The perturbed run of [`Growth`]: x0 + eps N 1 / |N 1|, projected onto the hidden constraints.
    fn perturbed_growth(
        &self,
        settings: &Settings,
        basis: &nalgebra::DMatrix<f64>,
        degrees: &[usize],
        reduction: Option<&crate::servo::Reduction>,
        reference: &crate::solve::Trajectory,
    ) -> Option<Growth> {
        let mut scene = self.clone();
        let SceneSystem::Tree(p) = &mut scene.system else {
            return None;
        };
        let n = p.v0.len();
        let dir: Vec<f64> = (0..2 * n).map(|i| basis.row(i).sum()).collect();
        let norm = dir.iter().map(|x| x * x).sum::<f64>().sqrt();
        let size = p.q0.iter().chain(&p.v0).fold(1.0f64, |m, x| m.max(x.abs()));
        let eps = PERTURBATION * size / norm;
        for i in 0..n {
            p.q0[i] += eps * dir[i];
            p.v0[i] += eps * dir[n + i];
        }
        {
            let act = p.constraints.actuation()?;
            let servo = Servo::new(&p.model, &p.constraints, act).reduced(reduction);
            let (t0, mut q, mut v) = (p.t0, p.q0.clone(), p.v0.clone());
            let out = servo.project(t0, &mut q, &mut v, degrees, 1e-14 * size, 20);
            if !out.converged {
                return None;
            }
            (p.q0, p.v0) = (q, v);
        }
        let sol = scene.solve(settings);
        let tr = &sol.trajectory;
        let len = tr.len().min(reference.len());
        if len < 2 {
            return None;
        }
        let sep = |k: usize| {
            tr.q_at(k)
                .iter()
                .zip(reference.q_at(k))
                .chain(tr.v_at(k).iter().zip(reference.v_at(k)))
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()))
        };
        let seps: Vec<f64> = (0..len).map(sep).collect();
        let (first, last) = (seps[0], seps[len - 1]);
        Some(Growth {
            initial_separation: first,
            final_separation: last,
            max_separation: seps.iter().cloned().fold(0.0, f64::max),
            rate: (last / first).ln() / (reference.t[len - 1] - reference.t[0]),
            t_end: reference.t[len - 1],
        })
    }
}

impl ServoReport {
    /// One line on the internal dynamics (`progmo validate`).
    pub fn internal_line(&self) -> String {
        let i = &self.internal;
        if i.dimension == 0 {
            return "internal dynamics: none (dimension 0: the programme fixes the whole state)"
                .into();
        }
        let eig = i
            .eigenvalues_t0
            .iter()
            .map(|e| {
                format!(
                    "{:.4} {} {:.4}i",
                    e.re,
                    if e.im < 0.0 { '-' } else { '+' },
                    e.im.abs()
                )
            })
            .collect::<Vec<_>>()
            .join(", ");
        format!(
            "internal dynamics: dimension {}, frozen-time eigenvalues at t0: {eig}",
            i.dimension
        )
    }
}
