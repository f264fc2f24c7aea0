//! Step-size selection of the adaptive methods, one controller for DOPRI5, DOP853 and Radau IIA.
//!
//! From the scaled error norm `err` of a step of length h (the step is accepted when err is at
//! most 1) the controller proposes h_new = h / quot with
//! quot = clamp(err^expo / safe, quot_min, quot_max) (HNW I, II.4, (4.13)), corrected by a memory
//! of past steps:
//! - [`StepControl::pi`]: Lund's PI control, quot = err^expo / err_old^beta / safe (HNW I, IV.2,
//!   (2.43c); DOPRI5, DOP853 with beta = 0, i.e. pure I control);
//! - [`StepControl::predictive`]: Gustafsson's predictive control (HNW II, IV.8, (8.25); RADAU5),
//!   the larger of quot and (h_acc / h) (err^2 / err_acc)^expo / safe.
//!
//! After an accepted step h_new is capped by h_max, and by h when the step before was rejected.

/// A step-size controller and its memory of past steps.
pub(crate) struct StepControl {
    expo: f64,
    /// Safety factor (a method may use a smaller one for a step, see [`Self::accepted`]).
    pub(crate) safe: f64,
    quot_min: f64,
    quot_max: f64,
    memory: Memory,
}

enum Memory {
    /// PI control: err of the last accepted step (1e-4 before the first).
    Lund { beta: f64, err_old: f64 },
    /// Predictive control: length and err of the last accepted step, accepted steps so far.
    Gustafsson {
        h_acc: f64,
        err_acc: f64,
        accepted: usize,
    },
}

impl StepControl {
    /// PI control with h_new / h in [fac_min, fac_max].
    pub(crate) fn pi(expo: f64, beta: f64, safe: f64, fac_min: f64, fac_max: f64) -> Self {
        StepControl {
            expo,
            safe,
            quot_min: 1.0 / fac_max,
            quot_max: 1.0 / fac_min,
            memory: Memory::Lund {
                beta,
                err_old: 1e-4,
            },
        }
    }

    /// Predictive control with h / h_new in [quot_min, quot_max].
    pub(crate) fn predictive(expo: f64, safe: f64, quot_min: f64, quot_max: f64) -> Self {
        StepControl {
            expo,
            safe,
            quot_min,
            quot_max,
            memory: Memory::Gustafsson {
                h_acc: 0.0,
                err_acc: 1e-2,
                accepted: 0,
            },
        }
    }

    fn quot(&self, x: f64) -> f64 {
        x.clamp(self.quot_min, self.quot_max)
    }

    /// quot = h / h_new after a rejected step with error `err`, safety factor `safe`.
    pub(crate) fn rejected(&self, err: f64, safe: f64) -> f64 {
        self.quot(err.powf(self.expo) / safe)
    }

    /// h_new after an accepted step of length h with error `err`, safety factor `safe` (the
    /// predictive term always uses [`Self::safe`]); at most `h_max`, and at most h when
    /// `after_rejection`.
    pub(crate) fn accepted(
        &mut self,
        err: f64,
        h: f64,
        safe: f64,
        h_max: f64,
        after_rejection: bool,
    ) -> f64 {
        let e = err.powf(self.expo);
        let quot = match self.memory {
            Memory::Lund {
                beta,
                ref mut err_old,
            } => {
                let q = (e / err_old.powf(beta) / safe).clamp(self.quot_min, self.quot_max);
                *err_old = err.max(1e-4);
                q
            }
            Memory::Gustafsson {
                ref mut h_acc,
                ref mut err_acc,
                ref mut accepted,
            } => {
                let mut q = (e / safe).clamp(self.quot_min, self.quot_max);
                *accepted += 1;
                if *accepted > 1 {
                    let g = (*h_acc / h) * (err * err / *err_acc).powf(self.expo) / self.safe;
                    q = q.max(g.clamp(self.quot_min, self.quot_max));
                }
                *h_acc = h;
                *err_acc = err.max(1e-2);
                q
            }
        };
        let h_new = (h / quot).min(h_max);
        if after_rejection {
            h_new.min(h)
        } else {
            h_new
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// PI control: the first proposal uses err_old = 1e-4, later ones the last err; bounds and
    /// the cap after a rejection hold.
    #[test]
    fn pi_control_follows_2_43c() {
        let (expo, beta) = (0.2 - 0.75 * 0.04, 0.04);
        let mut c = StepControl::pi(expo, beta, 0.9, 0.2, 10.0);
        let h1 = c.accepted(0.5, 1.0, 0.9, f64::INFINITY, false);
        let want = 1.0 / (0.5f64.powf(expo) / 1e-4f64.powf(beta) / 0.9).clamp(0.1, 5.0);
        assert_eq!(h1, want);
        let h2 = c.accepted(0.25, 1.0, 0.9, f64::INFINITY, false);
        let want = 1.0 / (0.25f64.powf(expo) / 0.5f64.powf(beta) / 0.9);
        assert_eq!(h2, want);
        assert_eq!(c.accepted(1e-30, 1.0, 0.9, f64::INFINITY, false), 10.0);
        assert_eq!(c.accepted(1e-30, 1.0, 0.9, 3.0, false), 3.0);
        assert_eq!(c.accepted(1e-30, 1.0, 0.9, f64::INFINITY, true), 1.0);
        assert_eq!(c.rejected(1e30, 0.9), 5.0);
        assert_eq!(c.rejected(2.0, 0.9), 2.0f64.powf(expo) / 0.9);
    }

    /// Predictive control: no prediction on the first accepted step; then the larger of the two
    /// quotients (8.25), i.e. the smaller step.
    #[test]
    fn predictive_control_follows_8_25() {
        let mut c = StepControl::predictive(0.25, 0.9, 0.125, 5.0);
        let h1 = c.accepted(0.01, 1.0, 0.8, f64::INFINITY, false);
        assert_eq!(h1, 1.0 / (0.01f64.powf(0.25) / 0.8));
        // The error grew fiftyfold: the prediction (h_acc / h) (err^2 / err_acc)^(1/4) / 0.9
        // asks for the smaller step.
        let (h, err) = (1.0, 0.5f64);
        let q1 = err.powf(0.25) / 0.8;
        let q2 = (1.0 / h) * (err * err / 0.01f64).powf(0.25) / 0.9;
        assert!(q2 > q1);
        assert_eq!(c.accepted(err, h, 0.8, f64::INFINITY, false), h / q2);
        // Same error on a doubled step: the plain proposal is the smaller step.
        let (h, err) = (2.0, 0.5f64);
        let q1 = err.powf(0.25) / 0.8;
        let q2 = (1.0 / h) * (err * err / 0.5f64).powf(0.25) / 0.9;
        assert!(q2 < q1);
        assert_eq!(c.accepted(err, h, 0.8, f64::INFINITY, false), h / q1);
    }
}
