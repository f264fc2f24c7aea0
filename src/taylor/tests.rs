//! Taylor arithmetic against an independent route (num-dual's third-order duals, chain rule in
//! derivative form), closed-form series, and identities that hold coefficient by coefficient.

use super::Taylor;
use num_dual::{Dual3_64, Dual64, DualNum};
use num_traits::Signed;

type T8 = Taylor<f64, 8>;

/// The input series x = x0 + a s + b s^2 + c s^3 in both representations.
fn pair(x0: f64) -> (Taylor<f64, 4>, Dual3_64) {
    let (a, b, c) = (0.7, -0.3, 0.45);
    (
        Taylor::from_coefficients(&[x0, a, b, c]),
        Dual3_64::new(x0, a, 2.0 * b, 6.0 * c),
    )
}

fn close(a: f64, b: f64, what: &str) {
    let tol = 1e-13 * (1.0 + a.abs().max(b.abs()));
    assert!((a - b).abs() <= tol, "{what}: {a} vs {b}");
}

/// Coefficients of y against the Dual3's derivatives over k!.
fn same(y: Taylor<f64, 4>, d: Dual3_64, what: &str) {
    let fact = [1.0, 1.0, 2.0, 6.0];
    let dv = [d.re, d.v1, d.v2, d.v3];
    for k in 0..4 {
        close(
            y.coefficient(k),
            dv[k] / fact[k],
            &format!("{what}, coefficient {k}"),
        );
    }
}

#[test]
fn every_function_matches_third_order_duals() {
    type F = fn(Taylor<f64, 4>) -> Taylor<f64, 4>;
    type G = fn(Dual3_64) -> Dual3_64;
    #[rustfmt::skip]
    let cases: Vec<(&str, f64, F, G)> = vec![
        ("sin", 0.4, |x| x.sin(), |x| x.sin()),
        ("cos", 0.4, |x| x.cos(), |x| x.cos()),
        ("tan", 0.4, |x| x.tan(), |x| x.tan()),
        ("exp", 0.4, |x| x.exp(), |x| x.exp()),
        ("exp2", 0.4, |x| x.exp2(), |x| x.exp2()),
        ("exp_m1", 0.4, |x| x.exp_m1(), |x| x.exp_m1()),
        ("ln", 1.7, |x| x.ln(), |x| x.ln()),
        ("ln_1p", 0.7, |x| x.ln_1p(), |x| x.ln_1p()),
        ("log", 1.7, |x| x.log(3.0), |x| x.log(3.0)),
        ("log2", 1.7, |x| x.log2(), |x| x.log2()),
        ("log10", 1.7, |x| x.log10(), |x| x.log10()),
        ("sqrt", 1.7, |x| x.sqrt(), |x| x.sqrt()),
        ("cbrt", -1.7, |x| x.cbrt(), |x| x.cbrt()),
        ("powf", 1.7, |x| x.powf(2.5), |x| x.powf(2.5)),
        ("powf negative base, integer", -1.3, |x| x.powf(3.0), |x| x.powf(3.0)),
        ("powi", -1.3, |x| x.powi(5), |x| x.powi(5)),
        ("powi negative", 1.3, |x| x.powi(-3), |x| x.powi(-3)),
        ("recip", -1.3, |x| x.recip(), |x| x.recip()),
        ("asin", 0.3, |x| x.asin(), |x| x.asin()),
        ("acos", 0.3, |x| x.acos(), |x| x.acos()),
        ("atan", 0.3, |x| x.atan(), |x| x.atan()),
        ("sinh", 0.3, |x| x.sinh(), |x| x.sinh()),
        ("cosh", 0.3, |x| x.cosh(), |x| x.cosh()),
        ("tanh", 0.3, |x| x.tanh(), |x| x.tanh()),
        ("asinh", 0.3, |x| x.asinh(), |x| x.asinh()),
        ("acosh", 1.3, |x| x.acosh(), |x| x.acosh()),
        ("atanh", 0.3, |x| x.atanh(), |x| x.atanh()),
        ("sph_j0", 0.8, |x| x.sph_j0(), |x| x.sph_j0()),
        ("sph_j1", 0.8, |x| x.sph_j1(), |x| x.sph_j1()),
        ("sph_j2", 0.8, |x| x.sph_j2(), |x| x.sph_j2()),
        ("atan2", 0.8, |x| x.atan2(x * x - 2.0), |x| x.atan2(x * x - 2.0)),
        ("quotient", 0.8, |x| x.sin() / (x + 3.0), |x| x.sin() / (x + 3.0)),
        ("product", 0.8, |x| x.sin() * x.exp(), |x| x.sin() * x.exp()),
        ("abs", -0.8, |x| x.abs(), |x| x.abs()),
    ];
    for (name, x0, f, g) in cases {
        let (t, d) = pair(x0);
        same(f(t), g(d), name);
    }
}

#[test]
fn closed_form_series_to_degree_seven() {
    let s = T8::from_coefficients(&[0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    let mut fact = 1.0;
    let (e, (sn, cs)) = (s.exp(), s.sin_cos());
    for k in 0..8 {
        if k > 0 {
            fact *= k as f64;
        }
        close(e.coefficient(k), 1.0 / fact, "exp(s)");
        let (sk, ck) = match k % 4 {
            0 => (0.0, 1.0),
            1 => (1.0, 0.0),
            2 => (0.0, -1.0),
            _ => (-1.0, 0.0),
        };
        close(sn.coefficient(k), sk / fact, "sin(s)");
        close(cs.coefficient(k), ck / fact, "cos(s)");
    }
    // ln(1 + s) = sum (-1)^(k+1) s^k / k; 1 / (1 - s) = sum s^k; sqrt(1 + s): binomial
    let (l, g) = ((s + 1.0).ln(), (-s + 1.0).recip());
    let r = (s + 1.0).sqrt();
    let mut binom = 1.0;
    for k in 1..8 {
        let sign = if k % 2 == 1 { 1.0 } else { -1.0 };
        close(l.coefficient(k), sign / k as f64, "ln(1 + s)");
        close(g.coefficient(k), 1.0, "1 / (1 - s)");
        binom *= (0.5 - (k - 1) as f64) / k as f64;
        close(r.coefficient(k), binom, "sqrt(1 + s)");
    }
}

#[test]
fn identities_hold_in_every_coefficient() {
    let x = T8::from_coefficients(&[0.6, 0.8, -0.25, 0.1, 0.3, -0.2, 0.05, 0.15]);
    let one = T8::from(1.0);
    let checks: Vec<(&str, T8, T8)> = vec![
        ("exp(ln x) = x", x.ln().exp(), x),
        (
            "sin^2 + cos^2 = 1",
            x.sin() * x.sin() + x.cos() * x.cos(),
            one,
        ),
        ("sqrt(x)^2 = x", x.sqrt() * x.sqrt(), x),
        ("x^2.5 x^-2.5 = 1", x.powf(2.5) * x.powf(-2.5), one),
        ("cbrt(x)^3 = x", x.cbrt().powi(3), x),
        ("atan(tan x) = x", x.tan().atan(), x),
        ("asin(sin x) = x", x.sin().asin(), x),
        ("acos(cos x) = x", x.cos().acos(), x),
        ("atan2(sin x, cos x) = x", x.sin().atan2(x.cos()), x),
        ("asinh(sinh x) = x", x.sinh().asinh(), x),
        ("acosh(cosh x) = x", x.cosh().acosh(), x),
        ("atanh(tanh x) = x", x.tanh().atanh(), x),
        ("(x / y) y = x", (x / (x + 2.0)) * (x + 2.0), x),
        (
            "x^7 by powi = by products",
            x.powi(7),
            x * x * x * x * x * x * x,
        ),
    ];
    for (name, a, b) in checks {
        for k in 0..8 {
            close(
                a.coefficient(k),
                b.coefficient(k),
                &format!("{name}, coefficient {k}"),
            );
        }
    }
}

#[test]
fn coefficients_over_dual_numbers_carry_their_derivative() {
    // d/dp of the series of exp(p sin s) at p = 0.7: s-coefficients of sin(s) exp(p sin s)
    let p = Dual64::new(0.7, 1.0);
    let mut c = [Dual64::from(0.0); 6];
    c[1] = Dual64::from(1.0);
    let s = Taylor::<Dual64, 6>::from_coefficients(&c);
    let y = s.sin().scale(&p).exp();
    let sp = Taylor::<f64, 6>::from_coefficients(&[0.0, 1.0, 0.0, 0.0, 0.0, 0.0]);
    let want = sp.sin() * (sp.sin() * 0.7).exp();
    for k in 0..6 {
        close(
            y.coefficient(k).eps,
            want.coefficient(k),
            &format!("coefficient {k}"),
        );
    }
}

#[test]
fn remainder_keeps_the_derivatives() {
    let x = Taylor::<f64, 3>::from_coefficients(&[7.5, 1.0, 0.5]);
    let r = x % 2.0;
    assert_eq!(r.coefficients(), [1.5, 1.0, 0.5]);
    let y = x % Taylor::from_coefficients(&[2.0, 0.25]);
    // n = trunc(7.5 / 2) = 3: x - 3 y
    assert_eq!(y.coefficients(), [1.5, 0.25, 0.5]);
}

#[test]
fn constants_stay_constants_and_lengths_follow_the_operands() {
    let c = Taylor::<f64, 6>::constant(2.0);
    let x = Taylor::<f64, 6>::from_coefficients(&[0.5, 1.0, 0.25]);
    assert_eq!((c * c).coefficients(), [4.0]);
    assert_eq!(c.sin().coefficients(), [2.0f64.sin()]);
    assert_eq!((c * x).coefficients(), [1.0, 2.0, 0.5]);
    assert_eq!((x / c).coefficients(), [0.25, 0.5, 0.125]);
    assert_eq!(x.exp().coefficients().len(), 3);
    // the same series at a longer length agrees in its first coefficients
    let long = Taylor::<f64, 6>::from_coefficients(&[0.5, 1.0, 0.25, 0.0, 0.0, 0.0]);
    for (a, b) in x
        .atan2(c)
        .coefficients()
        .iter()
        .zip(long.atan2(c).coefficients())
    {
        close(*a, *b, "atan2 at two lengths");
    }
}
