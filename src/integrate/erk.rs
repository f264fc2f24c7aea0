//! Explicit Runge-Kutta methods: classical RK4 (fixed step, cubic Hermite dense output),
//! Dormand-Prince 5(4) (Dormand & Prince 1980, dense output of Shampine 1986, HNW I, II.5 and II.6)
//! and DOP853 (Dormand-Prince 8(5,3) with the 7th-order dense output of HNW I, II.10).

// Coefficients keep their published digits; index loops mirror the formulas.
#![allow(
    clippy::excessive_precision,
    clippy::needless_range_loop,
    clippy::too_many_arguments
)]

use std::ops::ControlFlow;

use super::control::StepControl;
use super::{
    fixed_step_count, h_min, initial_step, rms, Accept, DenseOutput, DriverOptions,
    IntegratorStats, OdeProblem, Outcome,
};

/// Which explicit method to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    Rk4,
    Dopri5,
    Dop853,
}

/// Most stages any explicit method here stores (DOP853: 12 + FSAL + 3 dense-output stages).
const MAX_STAGES: usize = 16;
/// Most coefficient vectors of a dense-output polynomial (DOP853: 8).
const MAX_RCONT: usize = 8;

// ---------------------------------------------------------------------------------------------
// Classical RK4 (Kutta 1901).
const RK4_C: [f64; 4] = [0.0, 0.5, 0.5, 1.0];
const RK4_A: [&[f64]; 4] = [&[], &[0.5], &[0.0, 0.5], &[0.0, 0.0, 1.0]];
const RK4_B: [f64; 4] = [1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0];

// ---------------------------------------------------------------------------------------------
// Dormand & Prince (1980) 5(4), HNW I, Table II.5.2. Stage 7 is evaluated at (t + h, y1) (FSAL).
const DP5_C: [f64; 7] = [0.0, 0.2, 0.3, 0.8, 8.0 / 9.0, 1.0, 1.0];
const DP5_A: [&[f64]; 6] = [
    &[],
    &[0.2],
    &[3.0 / 40.0, 9.0 / 40.0],
    &[44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0],
    &[
        19372.0 / 6561.0,
        -25360.0 / 2187.0,
        64448.0 / 6561.0,
        -212.0 / 729.0,
    ],
    &[
        9017.0 / 3168.0,
        -355.0 / 33.0,
        46732.0 / 5247.0,
        49.0 / 176.0,
        -5103.0 / 18656.0,
    ],
];
/// 5th-order weights (= row 7 of A).
const DP5_B: [f64; 6] = [
    35.0 / 384.0,
    0.0,
    500.0 / 1113.0,
    125.0 / 192.0,
    -2187.0 / 6784.0,
    11.0 / 84.0,
];
/// b - b^ (5th minus 4th order weights), over stages 1..7.
const DP5_E: [f64; 7] = [
    71.0 / 57600.0,
    0.0,
    -71.0 / 16695.0,
    71.0 / 1920.0,
    -17253.0 / 339200.0,
    22.0 / 525.0,
    -1.0 / 40.0,
];
/// Shampine's (1986) dense output: coefficient of the 5th interpolation term, over stages 1..7.
const DP5_D: [f64; 7] = [
    -12715105075.0 / 11282082432.0,
    0.0,
    87487479700.0 / 32700410799.0,
    -10690763975.0 / 1880347072.0,
    701980252875.0 / 199316789632.0,
    -1453857185.0 / 822651844.0,
    69997945.0 / 29380423.0,
];

// ---------------------------------------------------------------------------------------------
// DOP853: Dormand-Prince 8(5,3), coefficients of HNW I, II.10 (as published with DOP853).
const DP8_C: [f64; 16] = [
    0.0,
    0.526001519587677318785587544488e-01,
    0.789002279381515978178381316732e-01,
    0.118350341907227396726757197510e+00,
    0.281649658092772603273242802490e+00,
    1.0 / 3.0,
    0.25,
    0.307692307692307692307692307692e+00,
    0.651282051282051282051282051282e+00,
    0.6,
    0.857142857142857142857142857142e+00,
    1.0,
    1.0,
    0.1,
    0.2,
    0.777777777777777777777777777778e+00,
];
const DP8_A: [&[f64]; 16] = [
    &[],
    &[5.26001519587677318785587544488e-2],
    &[
        1.97250569845378994544595329183e-2,
        5.91751709536136983633785987549e-2,
    ],
    &[
        2.95875854768068491816892993775e-2,
        0.0,
        8.87627564304205475450678981324e-2,
    ],
    &[
        2.41365134159266685502369798665e-1,
        0.0,
        -8.84549479328286085344864962717e-1,
        9.24834003261792003115737966543e-1,
    ],
    &[
        3.7037037037037037037037037037e-2,
        0.0,
        0.0,
        1.70828608729473871279604482173e-1,
        1.25467687566822425016691814123e-1,
    ],
    &[
        3.7109375e-2,
        0.0,
        0.0,
        1.70252211019544039314978060272e-1,
        6.02165389804559606850219397283e-2,
        -1.7578125e-2,
    ],
    &[
        3.70920001185047927108779319836e-2,
        0.0,
        0.0,
        1.70383925712239993810214054705e-1,
        1.07262030446373284651809199168e-1,
        -1.53194377486244017527936158236e-2,
        8.27378916381402288758473766002e-3,
    ],
    &[
        6.24110958716075717114429577812e-1,
        0.0,
        0.0,
        -3.36089262944694129406857109825e0,
        -8.68219346841726006818189891453e-1,
        2.75920996994467083049415600797e1,
        2.01540675504778934086186788979e1,
        -4.34898841810699588477366255144e1,
    ],
    &[
        4.77662536438264365890433908527e-1,
        0.0,
        0.0,
        -2.48811461997166764192642586468e0,
        -5.90290826836842996371446475743e-1,
        2.12300514481811942347288949897e1,
        1.52792336328824235832596922938e1,
        -3.32882109689848629194453265587e1,
        -2.03312017085086261358222928593e-2,
    ],
    &[
        -9.3714243008598732571704021658e-1,
        0.0,
        0.0,
        5.18637242884406370830023853209e0,
        1.09143734899672957818500254654e0,
        -8.14978701074692612513997267357e0,
        -1.85200656599969598641566180701e1,
        2.27394870993505042818970056734e1,
        2.49360555267965238987089396762e0,
        -3.0467644718982195003823669022e0,
    ],
    &[
        2.27331014751653820792359768449e0,
        0.0,
        0.0,
        -1.05344954667372501984066689879e1,
        -2.00087205822486249909675718444e0,
        -1.79589318631187989172765950534e1,
        2.79488845294199600508499808837e1,
        -2.85899827713502369474065508674e0,
        -8.87285693353062954433549289258e0,
        1.23605671757943030647266201528e1,
        6.43392746015763530355970484046e-1,
    ],
    // Stage 13 is f(t + h, y1) (FSAL), not formed from this table.
    &[],
    // Stages 14-16: extra stages of the dense output.
    &[
        5.61675022830479523392909219681e-2,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        2.53500210216624811088794765333e-1,
        -2.46239037470802489917441475441e-1,
        -1.24191423263816360469010140626e-1,
        1.5329179827876569731206322685e-1,
        8.20105229563468988491666602057e-3,
        7.56789766054569976138603589584e-3,
        -8.298e-3,
    ],
    &[
        3.18346481635021405060768473261e-2,
        0.0,
        0.0,
        0.0,
        0.0,
        2.83009096723667755288322961402e-2,
        5.35419883074385676223797384372e-2,
        -5.49237485713909884646569340306e-2,
        0.0,
        0.0,
        -1.08347328697249322858509316994e-4,
        3.82571090835658412954920192323e-4,
        -3.40465008687404560802977114492e-4,
        1.41312443674632500278074618366e-1,
    ],
    &[
        -4.28896301583791923408573538692e-1,
        0.0,
        0.0,
        0.0,
        0.0,
        -4.69762141536116384314449447206e0,
        7.68342119606259904184240953878e0,
        4.06898981839711007970213554331e0,
        3.56727187455281109270669543021e-1,
        0.0,
        0.0,
        0.0,
        -1.39902416515901462129418009734e-3,
        2.9475147891527723389556272149e0,
        -9.15095847217987001081870187138e0,
    ],
];
/// 8th-order weights over stages 1..12.
const DP8_B: [f64; 12] = [
    5.42937341165687622380535766363e-2,
    0.0,
    0.0,
    0.0,
    0.0,
    4.45031289275240888144113950566e0,
    1.89151789931450038304281599044e0,
    -5.8012039600105847814672114227e0,
    3.1116436695781989440891606237e-1,
    -1.52160949662516078556178806805e-1,
    2.01365400804030348374776537501e-1,
    4.47106157277725905176885569043e-2,
];
/// 3rd-order embedded weights: b - (bhh1 e1 + bhh2 e9 + bhh3 e12) is the 3rd-order error.
const DP8_BHH: [f64; 3] = [
    0.244094488188976377952755905512e+00,
    0.733846688281611857341361741547e+00,
    0.220588235294117647058823529412e-01,
];
/// 5th-order error weights over stages 1..12.
const DP8_ER: [f64; 12] = [
    0.1312004499419488073250102996e-01,
    0.0,
    0.0,
    0.0,
    0.0,
    -0.1225156446376204440720569753e+01,
    -0.4957589496572501915214079952e+00,
    0.1664377182454986536961530415e+01,
    -0.3503288487499736816886487290e+00,
    0.3341791187130174790297318841e+00,
    0.8192320648511571246570742613e-01,
    -0.2235530786388629525884427845e-01,
];
/// Dense output coefficients d_{4..7, j} over stages 1..16 (stages 2-5 do not enter).
const DP8_D: [[f64; 16]; 4] = [
    [
        -0.84289382761090128651353491142e+01,
        0.0,
        0.0,
        0.0,
        0.0,
        0.56671495351937776962531783590e+00,
        -0.30689499459498916912797304727e+01,
        0.23846676565120698287728149680e+01,
        0.21170345824450282767155149946e+01,
        -0.87139158377797299206789907490e+00,
        0.22404374302607882758541771650e+01,
        0.63157877876946881815570249290e+00,
        -0.88990336451333310820698117400e-01,
        0.18148505520854727256656404962e+02,
        -0.91946323924783554000451984436e+01,
        -0.44360363875948939664310572000e+01,
    ],
    [
        0.10427508642579134603413151009e+02,
        0.0,
        0.0,
        0.0,
        0.0,
        0.24228349177525818288430175319e+03,
        0.16520045171727028198505394887e+03,
        -0.37454675472269020279518312152e+03,
        -0.22113666853125306036270938578e+02,
        0.77334326684722638389603898808e+01,
        -0.30674084731089398182061213626e+02,
        -0.93321305264302278729567221706e+01,
        0.15697238121770843886131091075e+02,
        -0.31139403219565177677282850411e+02,
        -0.93529243588444783865713862664e+01,
        0.35816841486394083752465898540e+02,
    ],
    [
        0.19985053242002433820987653617e+02,
        0.0,
        0.0,
        0.0,
        0.0,
        -0.38703730874935176555105901742e+03,
        -0.18917813819516756882830838328e+03,
        0.52780815920542364900561016686e+03,
        -0.11573902539959630126141871134e+02,
        0.68812326946963000169666922661e+01,
        -0.10006050966910838403183860980e+01,
        0.77771377980534432092869265740e+00,
        -0.27782057523535084065932004339e+01,
        -0.60196695231264120758267380846e+02,
        0.84320405506677161018159903784e+02,
        0.11992291136182789328035130030e+02,
    ],
    [
        -0.25693933462703749003312586129e+02,
        0.0,
        0.0,
        0.0,
        0.0,
        -0.15418974869023643374053993627e+03,
        -0.23152937917604549567536039109e+03,
        0.35763911791061412378285349910e+03,
        0.93405324183624310003907691704e+02,
        -0.37458323136451633156875139351e+02,
        0.10409964950896230045147246184e+03,
        0.29840293426660503123344363579e+02,
        -0.43533456590011143754432175058e+02,
        0.96324553959188282948394950600e+02,
        -0.39177261675615439165231486172e+02,
        -0.14972683625798562581422125276e+03,
    ],
];

impl Kind {
    /// Number of stages that form y1 (the FSAL stage, evaluated at (t + h, y1), follows them).
    fn stages(self) -> usize {
        match self {
            Kind::Rk4 => 4,
            Kind::Dopri5 => 6,
            Kind::Dop853 => 12,
        }
    }
    fn c(self) -> &'static [f64] {
        match self {
            Kind::Rk4 => &RK4_C,
            Kind::Dopri5 => &DP5_C,
            Kind::Dop853 => &DP8_C,
        }
    }
    fn a(self) -> &'static [&'static [f64]] {
        match self {
            Kind::Rk4 => &RK4_A,
            Kind::Dopri5 => &DP5_A,
            Kind::Dop853 => &DP8_A,
        }
    }
    fn b(self) -> &'static [f64] {
        match self {
            Kind::Rk4 => &RK4_B,
            Kind::Dopri5 => &DP5_B,
            Kind::Dop853 => &DP8_B,
        }
    }
    /// Number of coefficient vectors of the dense-output polynomial.
    fn rcont_terms(self) -> usize {
        match self {
            Kind::Rk4 => 4,
            Kind::Dopri5 => 5,
            Kind::Dop853 => 8,
        }
    }
    /// Order of the error estimator (for the initial-step heuristic and the controller exponent).
    fn err_order(self) -> usize {
        match self {
            Kind::Rk4 => 4,
            Kind::Dopri5 => 4,
            Kind::Dop853 => 7,
        }
    }
}

/// The PI step-size controller of DOPRI5 / DOP853 (HNW I, IV.2, (2.43c)), with their codes'
/// parameters.
fn controller(kind: Kind) -> StepControl {
    match kind {
        // DOPRI5: beta = 0.04, expo1 = 1/5 - 0.75 beta, 0.2 <= h_new/h <= 10.
        Kind::Dopri5 | Kind::Rk4 => StepControl::pi(0.2 - 0.04 * 0.75, 0.04, 0.9, 0.2, 10.0),
        // DOP853: beta = 0 (pure I controller), expo1 = 1/8, 1/3 <= h_new/h <= 6.
        Kind::Dop853 => StepControl::pi(1.0 / 8.0, 0.0, 0.9, 0.333, 6.0),
    }
}

/// Dense output of the explicit methods in Hairer's nested form
/// y(t0 + s h) = r1 + s (r2 + s' (r3 + s (r4 + s' (r5 + ...)))), s' = 1 - s, with
/// r1 = y0, r2 = y1 - y0, r3 = h f0 - r2, r4 = r2 - h f1 - r3 (the cubic Hermite interpolant,
/// used alone by RK4) and further terms from the method's dense-output coefficients.
pub(crate) struct PolyDense<'a> {
    t0: f64,
    h: f64,
    n: usize,
    r: &'a [f64],
}

impl DenseOutput for PolyDense<'_> {
    fn eval(&self, t: f64, out: &mut [f64]) {
        let n = self.n;
        let terms = self.r.len() / n;
        let s = (t - self.t0) / self.h;
        let s1 = 1.0 - s;
        for i in 0..n {
            let mut acc = self.r[(terms - 1) * n + i];
            // Term k (1-based, k >= 2) is multiplied by s for even k, by s' for odd k.
            for k in (2..=terms).rev() {
                let m = if k % 2 == 0 { s } else { s1 };
                acc = self.r[(k - 2) * n + i] + m * acc;
            }
            out[i] = acc;
        }
    }
}

/// The dense output of a step whose problem declared it unneeded ([`OdeProblem::needs_dense`]):
/// NaN, so a misuse shows as a non-finite sample rather than a plausible wrong one.
struct NoDense;

impl DenseOutput for NoDense {
    fn eval(&self, _t: f64, out: &mut [f64]) {
        out.fill(f64::NAN);
    }
}

/// What a piece of an attempted step decides (the step drivers of this module and of Radau IIA):
/// go on with a `T`, retry the step from the same point (`Break(None)`, the state holding the new
/// step size) or end the run with an outcome.
pub(super) type Attempt<E, T = ()> = ControlFlow<Option<Outcome<E>>, T>;

/// The settings of one run of [`ErkWork::run`], fixed at its start.
struct ErkSettings {
    kind: Kind,
    t0: f64,
    t1: f64,
    fixed: Option<f64>,
    nfixed: Option<usize>,
    adaptive: bool,
}

/// The state [`ErkWork::run`] carries from one attempted step to the next.
struct ErkState {
    t: f64,
    /// Proposed size of the next step.
    h: f64,
    /// Steps taken in fixed-step mode.
    ifixed: usize,
    last_rejected: bool,
    ctl: StepControl,
}

/// Workspace of the explicit methods.
pub(crate) struct ErkWork {
    n: usize,
    /// Stages k_j = f(t + c_j h, Y_j), stage j at [j n, (j+1) n).
    k: Vec<f64>,
    ytmp: Vec<f64>,
    ynew: Vec<f64>,
    sc: Vec<f64>,
    err: Vec<f64>,
    rcont: Vec<f64>,
}

enum Trial {
    Ok,
    NonFinite,
}

impl ErkWork {
    pub(crate) fn new(n: usize) -> Self {
        ErkWork {
            n,
            k: vec![0.0; MAX_STAGES * n],
            ytmp: vec![0.0; n],
            ynew: vec![0.0; n],
            sc: vec![0.0; n],
            err: vec![0.0; n],
            rcont: vec![0.0; MAX_RCONT * n],
        }
    }

    /// Stage `s`: Y = y + h sum_j a_sj k_j, k_s = f(t + c_s h, Y).
    fn stage<P: OdeProblem>(
        &mut self,
        problem: &mut P,
        row: &[f64],
        tc: f64,
        y: &[f64],
        h: f64,
        s: usize,
        stats: &mut IntegratorStats,
    ) -> Result<(), P::Error> {
        let n = self.n;
        for i in 0..n {
            let mut acc = 0.0;
            for (j, &a) in row.iter().enumerate() {
                if a != 0.0 {
                    acc += a * self.k[j * n + i];
                }
            }
            self.ytmp[i] = y[i] + h * acc;
        }
        stats.rhs_evals += 1;
        let (ytmp, k) = (&self.ytmp, &mut self.k[s * n..(s + 1) * n]);
        problem.rhs(tc, ytmp, k)
    }

    /// One trial step of size h from (t, y) with k_1 = f(t, y) in stage 0: fills the stages,
    /// `ynew` and (if `want_err`) returns the error norm.
    #[allow(clippy::too_many_arguments)]
    fn trial<P: OdeProblem>(
        &mut self,
        kind: Kind,
        problem: &mut P,
        t: f64,
        y: &[f64],
        h: f64,
        want_err: bool,
        opts: &DriverOptions,
        stats: &mut IntegratorStats,
    ) -> Result<(Trial, f64), P::Error> {
        let n = self.n;
        let (c, a, b) = (kind.c(), kind.a(), kind.b());
        for s in 1..kind.stages() {
            self.stage(problem, a[s], t + c[s] * h, y, h, s, stats)?;
        }
        for i in 0..n {
            let mut acc = 0.0;
            for (j, &bj) in b.iter().enumerate() {
                if bj != 0.0 {
                    acc += bj * self.k[j * n + i];
                }
            }
            self.ynew[i] = y[i] + h * acc;
        }
        if !self.ynew.iter().all(|v| v.is_finite()) {
            return Ok((Trial::NonFinite, f64::NAN));
        }
        if kind == Kind::Dopri5 {
            // FSAL stage 7 enters the error estimate.
            stats.rhs_evals += 1;
            let s = kind.stages();
            problem.rhs(t + h, &self.ynew, &mut self.k[s * n..(s + 1) * n])?;
        }
        if !want_err {
            return Ok((Trial::Ok, 0.0));
        }
        problem.error_scale(y, &self.ynew, opts.atol, opts.rtol, &mut self.sc);
        let err = match kind {
            Kind::Rk4 => 0.0,
            Kind::Dopri5 => {
                for i in 0..n {
                    let mut acc = 0.0;
                    for (j, &e) in DP5_E.iter().enumerate() {
                        if e != 0.0 {
                            acc += e * self.k[j * n + i];
                        }
                    }
                    self.err[i] = h * acc;
                }
                rms(&self.err, &self.sc)
            }
            Kind::Dop853 => {
                // HNW I, II.10: err = |h| E5^2 / sqrt(n (E5^2 + 0.01 E3^2)) with E5, E3 the
                // scaled 2-norms of the 5th- and 3rd-order error estimates.
                let (mut e5, mut e3) = (0.0, 0.0);
                for i in 0..n {
                    let mut acc5 = 0.0;
                    let mut accb = 0.0;
                    for j in 0..12 {
                        let kj = self.k[j * n + i];
                        acc5 += DP8_ER[j] * kj;
                        accb += DP8_B[j] * kj;
                    }
                    let acc3 = accb
                        - DP8_BHH[0] * self.k[i]
                        - DP8_BHH[1] * self.k[8 * n + i]
                        - DP8_BHH[2] * self.k[11 * n + i];
                    e5 += (acc5 / self.sc[i]).powi(2);
                    e3 += (acc3 / self.sc[i]).powi(2);
                }
                let mut deno = e5 + 0.01 * e3;
                if deno <= 0.0 {
                    deno = 1.0;
                }
                h.abs() * e5 * (1.0 / (n as f64 * deno)).sqrt()
            }
        };
        if !err.is_finite() {
            return Ok((Trial::NonFinite, err));
        }
        Ok((Trial::Ok, err))
    }

    /// After acceptance: FSAL stage (if not yet done), extra dense stages, dense coefficients.
    fn prepare_dense<P: OdeProblem>(
        &mut self,
        kind: Kind,
        problem: &mut P,
        t: f64,
        y: &[f64],
        h: f64,
        stats: &mut IntegratorStats,
    ) -> Result<(), P::Error> {
        let n = self.n;
        let fs = kind.stages();
        if kind != Kind::Dopri5 {
            stats.rhs_evals += 1;
            problem.rhs(t + h, &self.ynew, &mut self.k[fs * n..(fs + 1) * n])?;
        }
        if kind == Kind::Dop853 {
            for s in 13..16 {
                self.stage(problem, DP8_A[s], t + DP8_C[s] * h, y, h, s, stats)?;
            }
        }
        for i in 0..n {
            let dy = self.ynew[i] - y[i];
            let bspl = h * self.k[i] - dy;
            self.rcont[i] = y[i];
            self.rcont[n + i] = dy;
            self.rcont[2 * n + i] = bspl;
            self.rcont[3 * n + i] = dy - h * self.k[fs * n + i] - bspl;
        }
        match kind {
            Kind::Rk4 => {}
            Kind::Dopri5 => {
                for i in 0..n {
                    let mut acc = 0.0;
                    for (j, &d) in DP5_D.iter().enumerate() {
                        acc += d * self.k[j * n + i];
                    }
                    self.rcont[4 * n + i] = h * acc;
                }
            }
            Kind::Dop853 => {
                for (m, d) in DP8_D.iter().enumerate() {
                    for i in 0..n {
                        let mut acc = 0.0;
                        for (j, &dj) in d.iter().enumerate() {
                            if dj != 0.0 {
                                acc += dj * self.k[j * n + i];
                            }
                        }
                        self.rcont[(4 + m) * n + i] = h * acc;
                    }
                }
            }
        }
        Ok(())
    }

    /// The step driver of the explicit methods. `fixed` is the fixed step (always for RK4).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn run<P: OdeProblem>(
        &mut self,
        kind: Kind,
        fixed: Option<f64>,
        opts: &DriverOptions,
        problem: &mut P,
        t0: f64,
        t1: f64,
        y: &mut [f64],
        stats: &mut IntegratorStats,
    ) -> Outcome<P::Error> {
        let n = self.n;
        let ctl = controller(kind);
        let t = t0;
        stats.rhs_evals += 1;
        if let Err(error) = problem.rhs(t, y, &mut self.k[..n]) {
            return Outcome::Problem { t, error };
        }
        if !self.k[..n].iter().all(|v| v.is_finite()) {
            return Outcome::NonFinite { t };
        }
        // Fixed-step mode: number of steps and the running index.
        let fixed = fixed.filter(|h| *h > 0.0);
        let set = ErkSettings {
            kind,
            t0,
            t1,
            fixed,
            nfixed: fixed.map(|h| fixed_step_count(t0, t1, h)),
            adaptive: fixed.is_none(),
        };
        let h = match self.first_step(&set, opts, problem, y, stats) {
            Ok(h) => h,
            Err(error) => return Outcome::Problem { t, error },
        };
        let mut st = ErkState {
            t,
            h,
            ifixed: 0,
            last_rejected: false,
            ctl,
        };
        loop {
            if let ControlFlow::Break(Some(outcome)) =
                self.attempt(&set, &mut st, opts, problem, y, stats)
            {
                return outcome;
            }
        }
    }

    /// The first step size: the fixed one, the user's h0 or the estimate of `initial_step`.
    fn first_step<P: OdeProblem>(
        &mut self,
        set: &ErkSettings,
        opts: &DriverOptions,
        problem: &mut P,
        y: &[f64],
        stats: &mut IntegratorStats,
    ) -> Result<f64, P::Error> {
        let n = self.n;
        Ok(match (set.fixed, opts.h0) {
            (Some(h), _) => h,
            (None, Some(h0)) => h0.min(opts.h_max),
            (None, None) => {
                let (k0, rest) = self.k.split_at_mut(n);
                initial_step(
                    problem,
                    set.t0,
                    y,
                    k0,
                    set.kind.err_order(),
                    opts.atol,
                    opts.rtol,
                    opts.h_max,
                    set.t1 - set.t0,
                    &mut self.sc,
                    &mut self.ytmp,
                    &mut rest[..n],
                    stats,
                )?
            }
        })
    }

    /// One attempted step from `st.t`, accepted or rejected.
    fn attempt<P: OdeProblem>(
        &mut self,
        set: &ErkSettings,
        st: &mut ErkState,
        opts: &DriverOptions,
        problem: &mut P,
        y: &mut [f64],
        stats: &mut IntegratorStats,
    ) -> Attempt<P::Error> {
        let (t, t1) = (st.t, set.t1);
        let attempts = stats.steps + stats.rejected;
        if attempts >= opts.max_steps {
            return ControlFlow::Break(Some(Outcome::MaxSteps { t }));
        }
        // Step length of this attempt and whether it lands on t1.
        let (hs, last) = match (set.fixed, set.nfixed) {
            (Some(hf), Some(nf)) => {
                if st.ifixed + 1 >= nf {
                    (t1 - t, true)
                } else {
                    (hf, false)
                }
            }
            _ => {
                if st.h < h_min(opts, t) {
                    return ControlFlow::Break(Some(Outcome::StepTooSmall { t, h: st.h }));
                }
                if t + 1.01 * st.h >= t1 {
                    (t1 - t, true)
                } else {
                    (st.h, false)
                }
            }
        };
        let err = self.checked_trial(set, st, opts, problem, hs, y, stats)?;
        let mut hnew = st.h;
        if set.adaptive {
            if err > 1.0 {
                stats.rejected += 1;
                st.h = hs / st.ctl.rejected(err, st.ctl.safe);
                st.last_rejected = true;
                return ControlFlow::Break(None);
            }
            hnew = st
                .ctl
                .accepted(err, hs, st.ctl.safe, opts.h_max, st.last_rejected);
            st.last_rejected = false;
        }
        self.accept(set, st, opts, problem, hs, hnew, last, y, stats)
    }

    /// The trial step of size `hs`, going on with its error norm; a failed evaluation or a
    /// non-finite result rejects the step.
    fn checked_trial<P: OdeProblem>(
        &mut self,
        set: &ErkSettings,
        st: &mut ErkState,
        opts: &DriverOptions,
        problem: &mut P,
        hs: f64,
        y: &[f64],
        stats: &mut IntegratorStats,
    ) -> Attempt<P::Error, f64> {
        let (t, adaptive) = (st.t, set.adaptive);
        let want_err = adaptive && set.kind != Kind::Rk4;
        let (trial, err) = match self.trial(set.kind, problem, t, y, hs, want_err, opts, stats) {
            Ok(r) => r,
            // A failed evaluation inside a trial step (a stage past a singular point) is not
            // evidence about the trajectory: reject and shrink, and report the error only when
            // the step cannot shrink any more, so that the stop is localized.
            Err(error) => {
                stats.rejected += 1;
                st.h = hs * 0.25;
                st.last_rejected = true;
                if !adaptive || st.h < h_min(opts, t) {
                    return ControlFlow::Break(Some(Outcome::Problem { t, error }));
                }
                return ControlFlow::Break(None);
            }
        };
        if let Trial::NonFinite = trial {
            stats.rejected += 1;
            if !adaptive {
                return ControlFlow::Break(Some(Outcome::NonFinite { t }));
            }
            st.h = hs * 0.25;
            st.last_rejected = true;
            if st.h < h_min(opts, t) {
                return ControlFlow::Break(Some(Outcome::NonFinite { t }));
            }
            return ControlFlow::Break(None);
        }
        ControlFlow::Continue(err)
    }

    /// An accepted step: dense output if wanted, the new y, the `accepted` hook, the FSAL stage
    /// and the next step size `hnew`.
    fn accept<P: OdeProblem>(
        &mut self,
        set: &ErkSettings,
        st: &mut ErkState,
        opts: &DriverOptions,
        problem: &mut P,
        hs: f64,
        hnew: f64,
        last: bool,
        y: &mut [f64],
        stats: &mut IntegratorStats,
    ) -> Attempt<P::Error> {
        let (n, kind, fs) = (self.n, set.kind, set.kind.stages());
        let t = st.t;
        // Accepted. Without dense output this step, the stage f(t + h, y_new) waits until the
        // problem has seen (and perhaps projected) y_new: it is then f at the state the next
        // step starts from, the same value FSAL would give when nothing changed.
        let want_dense = problem.needs_dense(t, t + hs);
        if want_dense {
            if let Err(error) = self.prepare_dense(kind, problem, t, y, hs, stats) {
                // As for a failed stage: shrink while the step can.
                stats.rejected += 1;
                st.h = hs * 0.25;
                st.last_rejected = true;
                if !set.adaptive || st.h < h_min(opts, t) {
                    return ControlFlow::Break(Some(Outcome::Problem { t, error }));
                }
                return ControlFlow::Break(None);
            }
        }
        let t_fsal = t + hs;
        y.copy_from_slice(&self.ynew);
        let tnew = if last {
            set.t1
        } else if let Some(hf) = set.fixed {
            set.t0 + (st.ifixed + 1) as f64 * hf
        } else {
            t + hs
        };
        stats.steps += 1;
        st.ifixed += 1;
        let acc = if want_dense {
            let dense = PolyDense {
                t0: t,
                h: hs,
                n,
                r: &self.rcont[..kind.rcont_terms() * n],
            };
            problem.accepted(t, tnew, y, &dense)
        } else {
            problem.accepted(t, tnew, y, &NoDense)
        };
        st.t = tnew;
        let t = tnew;
        // Dormand-Prince 5(4) has its FSAL stage from the error estimate already.
        let fsal_ready = want_dense || kind == Kind::Dopri5;
        match acc {
            Err(error) => return ControlFlow::Break(Some(Outcome::Problem { t, error })),
            Ok(Accept::Unchanged) if fsal_ready => {
                self.k.copy_within(fs * n..(fs + 1) * n, 0);
            }
            Ok(Accept::Unchanged) => {
                // The deferred FSAL stage, at the abscissa t + h of the method.
                stats.rhs_evals += 1;
                if let Err(error) = problem.rhs(t_fsal, y, &mut self.k[..n]) {
                    return ControlFlow::Break(Some(Outcome::Problem { t, error }));
                }
            }
            Ok(Accept::Changed) => {
                stats.rhs_evals += 1;
                if let Err(error) = problem.rhs(t, y, &mut self.k[..n]) {
                    return ControlFlow::Break(Some(Outcome::Problem { t, error }));
                }
            }
        }
        if last {
            return ControlFlow::Break(Some(Outcome::Finished));
        }
        st.h = hnew;
        ControlFlow::Continue(())
    }
}

#[cfg(test)]
mod tableau_tests {
    use super::*;

    /// Row sums of A equal c (for every stage formed from the table), the weights satisfy the
    /// quadrature conditions sum b_i c_i^(q-1) = 1/q up to the method's order, and the error
    /// weights of the embedded pairs annihilate constants (sum e_i = 0).
    #[test]
    fn tableaux_are_consistent() {
        for (kind, order) in [(Kind::Rk4, 4), (Kind::Dopri5, 5), (Kind::Dop853, 8)] {
            let (c, a, b) = (kind.c(), kind.a(), kind.b());
            for (s, row) in a.iter().enumerate().skip(1) {
                if row.is_empty() {
                    continue; // DOP853's FSAL stage 13
                }
                let sum: f64 = row.iter().sum();
                assert!(
                    (sum - c[s]).abs() < 1e-13,
                    "{kind:?} stage {s}: {sum} vs {}",
                    c[s]
                );
            }
            for q in 1..=order {
                let lhs: f64 = b.iter().zip(c).map(|(bi, ci)| bi * ci.powi(q - 1)).sum();
                assert!(
                    (lhs - 1.0 / q as f64).abs() < 1e-13,
                    "{kind:?} B({q}): {lhs}"
                );
            }
        }
        assert!(DP5_E.iter().sum::<f64>().abs() < 1e-15);
        assert!(DP8_ER.iter().sum::<f64>().abs() < 1e-13);
        let bsum: f64 = DP8_B.iter().sum();
        assert!((bsum - DP8_BHH.iter().sum::<f64>()).abs() < 1e-13);
    }
}
