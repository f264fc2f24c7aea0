use super::compile::Op;
use super::*;
use num_dual::{Dual, Dual2_64, Dual64};
use std::f64::consts::PI;

fn table() -> SymbolTable {
    [
        "x",
        "y",
        "t",
        "theta",
        "r",
        "r'",
        "r''",
        "tip.x",
        "tip.vel.y",
    ]
    .into_iter()
    .collect()
}

fn ev(src: &str, slots: &[f64]) -> f64 {
    Expr::compile(src, &table())
        .unwrap_or_else(|e| panic!("{src}: {e}"))
        .value(slots)
}

fn rel(a: f64, b: f64) -> f64 {
    if a == b {
        0.0
    } else {
        (a - b).abs() / a.abs().max(b.abs())
    }
}

#[track_caller]
fn close(a: f64, b: f64, what: &str) {
    assert!(rel(a, b) <= 1e-14, "{what}: {a} vs {b} (rel {})", rel(a, b));
}

fn err(src: &str) -> ExprError {
    match Expr::compile(src, &table()) {
        Ok(e) => panic!("`{src}` compiled to {e}"),
        Err(e) => e,
    }
}

// ---------------------------------------------------------------- values

#[test]
fn values_match_closed_forms() {
    type F = fn(f64, f64, f64) -> f64;
    let cases: &[(&str, F)] = &[
        ("x + y*t", |x, y, t| x + y * t),
        ("x - y - t", |x, y, t| x - y - t),
        ("x/y/t", |x, y, t| x / y / t),
        ("(x - 1)/(y + 2)", |x, y, _| (x - 1.0) / (y + 2.0)),
        ("3 - x", |x, _, _| 3.0 - x),
        ("3/x", |x, _, _| 3.0 / x),
        ("y - x*t", |x, y, t| y - x * t),
        ("y/(x + t)", |x, y, t| y / (x + t)),
        ("t/x - 2", |x, _, t| t / x - 2.0),
        ("x*t/4 + (x + 1)*(y - 1)", |x, y, t| {
            x * t / 4.0 + (x + 1.0) * (y - 1.0)
        }),
        ("x^2 + y^3 - t^-2", |x, y, t| x * x + y.powi(3) - t.powi(-2)),
        ("x^0.5 + abs(y)^1.5", |x, y, _| x.sqrt() + y.abs().powf(1.5)),
        ("x^y", |x, y, _| x.powf(y)),
        ("2^x", |x, _, _| 2f64.powf(x)),
        ("sin(x)*cos(y) + tan(t)", |x, y, t| {
            x.sin() * y.cos() + t.tan()
        }),
        ("asin(t/4) + acos(t/5) + atan(x)", |x, _, t| {
            (t / 4.0).asin() + (t / 5.0).acos() + x.atan()
        }),
        ("atan2(y, x) + atan2(-y, -x)", |x, y, _| {
            y.atan2(x) + (-y).atan2(-x)
        }),
        ("exp(-t/2)*log(x) + sqrt(x*x + y*y)", |x, y, t| {
            (-t / 2.0).exp() * x.ln() + (x * x + y * y).sqrt()
        }),
        ("sinh(t) - cosh(t) + tanh(x)", |x, _, t| {
            t.sinh() - t.cosh() + x.tanh()
        }),
        ("2*pi*t", |_, _, t| 2.0 * PI * t),
        ("-x^2", |x, _, _| -(x * x)),
        ("1.5e-3*x + .5 + 2.", |x, _, _| 1.5e-3 * x + 0.5 + 2.0),
        ("x*(y*(t + 1))", |x, y, t| x * (y * (t + 1.0))),
        ("(x + y)*(x - y)/(t + x)^2", |x, y, t| {
            (x + y) * (x - y) / (t + x).powi(2)
        }),
    ];
    let points = [(1.3, 0.7, 0.4), (2.5, -1.2, 1.9), (0.2, 3.0, -0.8)];
    for (src, f) in cases {
        for &(x, y, t) in &points {
            let want = f(x, y, t);
            let mut slots = vec![0.0; table().len()];
            slots[0] = x;
            slots[1] = y;
            slots[2] = t;
            let got = ev(src, &slots);
            if want.is_nan() {
                assert!(got.is_nan(), "{src} at {x},{y},{t}: {got}");
            } else {
                close(got, want, src);
            }
        }
    }
}

#[test]
fn precedence_and_associativity() {
    let s = [0.0; 9];
    assert_eq!(ev("2^3^2", &s), 512.0);
    assert_eq!(ev("(2^3)^2", &s), 64.0);
    assert_eq!(ev("-2^2", &s), -4.0);
    assert_eq!(ev("(-2)^2", &s), 4.0);
    assert_eq!(ev("2*-3", &s), -6.0);
    assert_eq!(ev("2^-1", &s), 0.5);
    assert_eq!(ev("2^-1^2", &s), 0.5); // 2^(-(1^2))
    assert_eq!(ev("8/4/2", &s), 1.0);
    assert_eq!(ev("8-4-2", &s), 2.0);
    assert_eq!(ev("2+3*4", &s), 14.0);
    assert_eq!(ev("--3", &s), 3.0);
    assert_eq!(ev("+3", &s), 3.0);
    assert_eq!(ev("-3*2^2", &s), -12.0);
    assert_eq!(ev("1 - -1", &s), 2.0);
    // With symbols (no constant folding).
    let mut v = [0.0; 9];
    v[0] = 3.0; // x
    v[1] = 2.0; // y
    v[2] = 4.0; // t
    assert_eq!(ev("-x^2", &v), -9.0);
    assert_eq!(ev("y^y^y", &v), 16.0);
    assert_eq!(ev("x/y/t", &v), 3.0 / 2.0 / 4.0);
    assert_eq!(ev("x - y - t", &v), -3.0);
    assert_eq!(ev("x*-y", &v), -6.0);
    assert_eq!(ev("-x*y", &v), -6.0);
    assert_eq!(ev("t^-y", &v), 1.0 / 16.0);
    assert_eq!(ev("x\n +\ty", &v), 5.0);
}

#[test]
fn names_with_dots_and_primes() {
    let t = table();
    let mut v = vec![0.0; t.len()];
    v[t.get("r").unwrap()] = 1.0;
    v[t.get("r'").unwrap()] = 10.0;
    v[t.get("r''").unwrap()] = 100.0;
    v[t.get("tip.x").unwrap()] = 1000.0;
    v[t.get("tip.vel.y").unwrap()] = 10000.0;
    assert_eq!(ev("r + r' + r'' + tip.x + tip.vel.y", &v), 11111.0);

    let lvl = |s: &str| Expr::compile(s, &t).unwrap().time_order();
    assert_eq!(lvl("r + tip.x"), 0);
    assert_eq!(lvl("r' + r"), 1);
    assert_eq!(lvl("r'' - r'*r"), 2);
    assert_eq!(lvl("3"), 0);
    assert_eq!(time_order("a.b''"), 2);
    assert_eq!(base_name("a.b''"), "a.b");

    let e = Expr::compile("r'' + x*r + r", &t).unwrap();
    assert_eq!(e.slots(), &[0, 4, 6]);
    assert!(e.uses(6) && e.uses(4) && !e.uses(5) && !e.uses(1));
    assert_eq!(e.min_slots(), 7);
    // A zero factor does not hide a symbol from level detection.
    assert_eq!(lvl("0*r''"), 2);

    assert_eq!(
        referenced_names("sin(tip.vel.y) + q1'' * q1 + pi - tip.vel.y").unwrap(),
        vec!["tip.vel.y", "q1''", "q1"]
    );
    assert!(referenced_names("sin(").is_err());
}

/// A robot file's name that is not an identifier is written in backquotes; the name the caller
/// sees has them removed, the token keeps the source text for errors.
#[test]
fn backquoted_names() {
    assert_eq!(
        referenced_names("`joint_8.0` + `joint_8.0`' * `link_8.0`.x'' - `a b`.qw").unwrap(),
        vec!["joint_8.0", "joint_8.0'", "link_8.0.x''", "a b.qw"]
    );
    // mixed parts; a quoted identifier is the identifier
    assert_eq!(referenced_names("tip.`x`").unwrap(), vec!["tip.x"]);
    let t: SymbolTable = ["joint_8.0", "joint_8.0'", "link_8.0.x"]
        .into_iter()
        .collect();
    let e = Expr::compile("2*`joint_8.0` + `joint_8.0`' + `link_8.0`.x", &t).unwrap();
    assert_eq!(e.value(&[1.0, 10.0, 100.0]), 112.0);
    assert_eq!(e.time_order(), 1);
    // malformed quotes, located at the opening backquote
    for (src, col, phrase) in [
        ("1 + `joint_8.0", 5, "closing backquote"),
        ("`a'b`", 1, "closing backquote"),
        ("x + ``", 5, "not empty"),
        ("joint_8.0", 1, "backquotes"),
    ] {
        let e = referenced_names(src).unwrap_err();
        assert_eq!(e.column, col, "{src}: {e}");
        assert!(e.message().contains(phrase), "{src}: {e}");
    }
    // an unknown quoted name is shown, and its neighbour suggested, as rows write them
    let e = Expr::compile("`joint_8.1`", &t).unwrap_err();
    assert_eq!(
        e.message(),
        "unknown symbol `` `joint_8.1` `` (did you mean `` `joint_8.0` ``?)"
    );
    for (name, w) in [
        ("q1", "q1"),
        ("tip.x'", "tip.x'"),
        ("joint_8.0'", "`joint_8.0`'"),
        ("link_8.0.qw", "`link_8.0`.qw"),
        ("link-2.wx'", "`link-2`.wx'"),
        ("a.0.b", "`a.0.b`"),
    ] {
        assert_eq!(written(name), w);
        let back = referenced_names(&written(name)).unwrap();
        assert_eq!(back, [name], "{name} round trip");
    }
}

#[test]
fn symbol_table() {
    let mut t = SymbolTable::new();
    assert!(t.is_empty());
    assert_eq!(t.insert("a"), 0);
    assert_eq!(t.insert("b"), 1);
    assert_eq!(t.insert("a"), 0);
    assert_eq!(t.len(), 2);
    assert_eq!(t.get("b"), Some(1));
    assert_eq!(t.get("c"), None);
    assert_eq!(t.name(1), Some("b"));
    assert_eq!(t.names(), &["a".to_string(), "b".to_string()]);
}

#[test]
fn named_constants_are_folded() {
    let mut t: SymbolTable = ["x", "shadow"].into_iter().collect();
    t.define("m", 2.0);
    t.define("l", 0.5);
    t.define("n", 3.0);
    t.define("shadow", 7.0);
    t.define("m", 4.0); // redefinition
    assert_eq!(t.constant("m"), Some(4.0));
    assert_eq!(t.constant_names(), &["m", "l", "n", "shadow"]);
    assert_eq!(t.len(), 2);
    let e = Expr::compile("m*l^2*g0", &{
        let mut t = t.clone();
        t.define("g0", 9.81);
        t
    })
    .unwrap();
    assert_eq!(e.constant(), Some(4.0 * 0.25 * 9.81));
    assert_eq!(e.to_string(), "m*l^2*g0");
    let e = Expr::compile("x^n", &t).unwrap();
    assert_eq!(e.code(), &[Op::Load(0), Op::Powi(3)]);
    assert!(!e.uses(1));
    let d = e.value(&[Dual64::new(-2.0, 1.0), Dual64::new(0.0, 0.0)]);
    assert_eq!((d.re, d.eps), (-8.0, 12.0));
    // A slot wins over a constant of the same name.
    assert_eq!(Expr::compile("shadow", &t).unwrap().code(), &[Op::Load(1)]);
    t.define("bad", f64::NAN);
    let e = Expr::compile("x + bad", &t).unwrap_err();
    assert_eq!((e.column, e.token.as_str()), (5, "bad"));
    assert_eq!(e.message(), "constant subexpression evaluates to NaN");
    let e = Expr::compile("2*mm", &t).unwrap_err();
    assert_eq!(e.message(), "unknown symbol `mm` (did you mean `m`?)");
    let e = Expr::compile("l(2)", &t).unwrap_err();
    assert_eq!(e.message(), "`l` is a symbol, not a function");
}

#[test]
fn bytecode_is_folded_and_specialized() {
    let t = table();
    let code = |s: &str| Expr::compile(s, &t).unwrap().code().to_vec();
    assert_eq!(code("2*pi*3"), vec![Op::Const(2.0 * PI * 3.0)]);
    assert_eq!(
        Expr::compile("2*pi", &t).unwrap().constant(),
        Some(2.0 * PI)
    );
    assert_eq!(Expr::compile("x", &t).unwrap().constant(), None);
    assert_eq!(code("x^2"), vec![Op::Load(0), Op::Square]);
    assert_eq!(code("x^3"), vec![Op::Load(0), Op::Powi(3)]);
    assert_eq!(code("x^(1+2)"), vec![Op::Load(0), Op::Powi(3)]);
    assert_eq!(code("x^-2"), vec![Op::Load(0), Op::Powi(-2)]);
    assert_eq!(code("x^1.5"), vec![Op::Load(0), Op::Powf(1.5)]);
    assert_eq!(code("x^0.5"), vec![Op::Load(0), Op::Sqrt]);
    assert_eq!(code("x^y"), vec![Op::Load(0), Op::Load(1), Op::Pow]);
    assert_eq!(code("(2*3)*x"), vec![Op::Load(0), Op::MulC(6.0)]);
    assert_eq!(code("1 - x"), vec![Op::Load(0), Op::RSubC(1.0)]);
    assert_eq!(code("x*y + t"), vec![Op::Load(0), Op::MulL(1), Op::AddL(2)]);
    assert_eq!(code("2/x"), vec![Op::Load(0), Op::RDivC(2.0)]);
    assert_eq!(code("x/4"), vec![Op::Load(0), Op::DivC(4.0)]);
    assert_eq!(code("y - 1"), vec![Op::Load(1), Op::SubC(1.0)]);
    assert_eq!(
        code("y - x*t"),
        vec![Op::Load(0), Op::MulL(2), Op::RSubL(1)]
    );
    assert_eq!(
        code("y/(x+t)"),
        vec![Op::Load(0), Op::AddL(2), Op::RDivL(1)]
    );
    assert_eq!(
        code("sin(x) - cos(y)"),
        vec![Op::Load(0), Op::Sin, Op::Load(1), Op::Cos, Op::Sub]
    );
    let e = Expr::compile("sin(x)*cos(y) + (x+y)*(t-x)", &t).unwrap();
    assert_eq!(e.max_stack(), 3);
}

#[test]
fn eval_does_not_allocate_and_reuses_stack() {
    let e = Expr::compile("atan2(sin(x)*(y+1), cos(x)*(y-(t+(x*y)^2))) + x", &table()).unwrap();
    let mut stack: Vec<f64> = Vec::with_capacity(e.max_stack());
    let ptr = stack.as_ptr();
    let cap = stack.capacity();
    let slots = [0.3, 0.4, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let a = e.eval(&slots, &mut stack);
    let b = e.eval(&slots, &mut stack);
    assert_eq!(a, b);
    assert_eq!(stack.as_ptr(), ptr);
    assert_eq!(stack.capacity(), cap);
}

#[test]
fn display_round_trips() {
    let t = table();
    for src in [
        "2^3^2",
        "(2^3)^2",
        "-x^2",
        "(-x)^2",
        "x - (y - t)",
        "x - y - t",
        "x/(y*t)",
        "x*y/t",
        "-(x*y)",
        "--x",
        "2*-x",
        "x^-y^2",
        "atan2(y, x - 1)*pi + 1e-20*tip.vel.y + 0.1*r''",
        "(x + y)^(t - 1)",
    ] {
        let e = Expr::compile(src, &t).unwrap();
        let shown = e.to_string();
        let again = Expr::compile(&shown, &t).unwrap_or_else(|err| panic!("{shown}: {err}"));
        assert_eq!(again.code(), e.code(), "{src} -> {shown}");
        assert_eq!(again.to_string(), shown);
    }
    let show = |s: &str| Expr::compile(s, &t).unwrap().to_string();
    assert_eq!(show("2 *  pi*(t)"), "2*pi*t");
    assert_eq!(show("-x^2"), "-x^2");
    assert_eq!(show("(-x)^2"), "(-x)^2");
    assert_eq!(show("x-(y+t)"), "x - (y + t)");
    assert_eq!(show("atan2(y,x)"), "atan2(y, x)");
}

#[test]
fn expr_is_send_sync() {
    fn check<T: Send + Sync + 'static>() {}
    check::<Expr>();
    check::<SymbolTable>();
    check::<ExprError>();
}

// ---------------------------------------------------------------- errors

#[track_caller]
fn check_err(src: &str, column: usize, token: &str, message: &str) -> ExprError {
    let e = err(src);
    assert_eq!(e.column, column, "column of `{src}`: {e}");
    assert_eq!(e.token, token, "token of `{src}`: {e}");
    assert!(
        e.message().contains(message),
        "message of `{src}`: `{}` lacks `{message}`",
        e.message()
    );
    e
}

#[test]
fn error_kinds_and_columns() {
    let e = check_err(
        "sin(thta)",
        5,
        "thta",
        "unknown symbol `thta` (did you mean `theta`?)",
    );
    assert!(
        matches!(e.kind, ExprErrorKind::UnknownSymbol { ref suggestion, .. } if suggestion.as_deref() == Some("theta"))
    );
    check_err("qqqqq + 1", 1, "qqqqq", "unknown symbol `qqqqq`");
    assert!(!err("qqqqq").message().contains("did you mean"));
    check_err("tip.z", 1, "tip.z", "did you mean `tip.x`?");
    check_err(
        "x*(y + 1",
        9,
        "",
        "expected `)` to close `(` opened at column 3",
    );
    check_err(
        "(x + 1 y",
        8,
        "y",
        "expected `)` to close `(` opened at column 1, found `y`",
    );
    check_err(
        "sin(x",
        6,
        "",
        "expected `)` to close `(` opened at column 4",
    );
    check_err(
        "atan2(y x)",
        9,
        "x",
        "expected `,` or `)` in the arguments of `atan2`",
    );
    check_err(
        "1 + atan2(x)",
        5,
        "atan2",
        "function `atan2` takes 2 arguments, got 1",
    );
    check_err(
        "sin(x, y)",
        1,
        "sin",
        "function `sin` takes 1 argument, got 2",
    );
    check_err("sin()", 1, "sin", "takes 1 argument, got 0");
    check_err("x + * 2", 5, "*", "unexpected `*`");
    check_err("*x", 1, "*", "unexpected `*`");
    check_err("x + ,", 5, ",", "unexpected `,`");
    check_err("()", 2, ")", "unexpected `)`");
    check_err(
        "sn(x)",
        1,
        "sn",
        "unknown function `sn` (did you mean `sin`?)",
    );
    check_err(
        "frobnicate(x)",
        1,
        "frobnicate",
        "unknown function `frobnicate`",
    );
    check_err("", 1, "", "empty expression");
    check_err("  \t ", 1, "", "empty expression");
    check_err("x y", 3, "y", "unexpected `y` after a complete expression");
    check_err("(x) (y)", 5, "(", "after a complete expression");
    check_err("x + 1)", 6, ")", "unmatched `)`");
    check_err("x +", 4, "", "unexpected end of input");
    check_err("2x", 2, "x", "write `2*x`");
    check_err("1.5theta", 4, "theta", "write `1.5*theta`");
    check_err("1e", 1, "1e", "malformed number `1e`");
    check_err("x + 1e+", 5, "1e+", "exponent needs digits");
    check_err("1.2.3", 1, "1.2.3", "malformed number `1.2.3`");
    check_err("1e999", 1, "1e999", "out of range");
    check_err("x**2", 2, "**", "`**` is not an operator");
    check_err("θ + 1", 1, "θ", "unexpected character `θ`");
    check_err("x + θ", 5, "θ", "names are ASCII");
    check_err("x # y", 3, "#", "unexpected character `#`");
    check_err("x + 'r", 5, "'", "unexpected character `'`");
    check_err("tip.", 1, "tip.", "expected a name part after `.`");
    check_err("tip.1", 1, "tip.", "expected a name part after `.`");
    check_err("r''' + 1", 1, "r'''", "at most two `'`");
    check_err(
        "x + theta(2)",
        5,
        "theta",
        "`theta` is a symbol, not a function",
    );
    check_err("2*sin + 1", 3, "sin", "function `sin` needs arguments");
    check_err(
        "x + sqrt(-1)",
        5,
        "sqrt(-1)",
        "constant subexpression evaluates to NaN",
    );
    check_err("x*(1/0)", 3, "(1/0)", "evaluates to inf");
    check_err("x + 1e300*1e300", 5, "1e300*1e300", "evaluates to inf");
}

#[test]
fn deep_input_is_an_error_not_a_crash() {
    let deep = "(".repeat(100_000) + "x" + &")".repeat(100_000);
    assert!(matches!(err(&deep).kind, ExprErrorKind::TooDeep { .. }));
    let signs = "-".repeat(100_000) + "x";
    assert!(matches!(err(&signs).kind, ExprErrorKind::TooDeep { .. }));
    let pows = "x^".repeat(100_000) + "x";
    assert!(matches!(err(&pows).kind, ExprErrorKind::TooDeep { .. }));
    let sum = "x+".repeat(100_000) + "x";
    assert!(matches!(err(&sum).kind, ExprErrorKind::TooDeep { .. }));
    let calls = "sin(".repeat(100_000);
    assert!(matches!(err(&calls).kind, ExprErrorKind::TooDeep { .. }));
    // Moderate sizes are fine.
    let ok = "x+".repeat(500) + "x";
    assert_eq!(ev(&ok, &[1.0; 9]), 501.0);
    let nested = "(".repeat(100) + "x" + &")".repeat(100);
    assert_eq!(ev(&nested, &[2.0; 9]), 2.0);
}

#[test]
fn long_flat_sums_and_products_are_allowed_up_to_the_documented_limit() {
    // FORMAT.md: a sum or product of up to 10,000 terms (tree height 10,000). Checked on the
    // default 2 MiB stack of a spawned thread: parse, fold, compile, display, evaluate, drop.
    std::thread::Builder::new()
        .stack_size(2 << 20)
        .spawn(|| {
            let sum = vec!["2*x"; 1000].join(" + ");
            assert_eq!(ev(&sum, &[1.0; 9]), 2000.0);
            let sum = "x+".repeat(9_999) + "x";
            let e = Expr::compile(&sum, &table()).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(e.value(&[1.0; 9]), 10_000.0);
            assert!(e.to_string().len() > 10_000);
            let d = e.value(&[num_dual::Dual64::new(1.0, 1.0); 9]);
            assert_eq!(d.eps, 10_000.0);
            let prod = vec!["x"; 10_000].join("*");
            assert_eq!(ev(&prod, &[1.0; 9]), 1.0);
            let over = "x+".repeat(10_000) + "x";
            assert!(matches!(err(&over).kind, ExprErrorKind::TooDeep { .. }));
        })
        .unwrap()
        .join()
        .unwrap();
}

#[test]
fn caret_and_scene_rendering() {
    let e = err("sin(thta) + 1");
    assert_eq!(e.caret(), "sin(thta) + 1\n    ^^^^");
    assert_eq!(
        e.render("scene.toml", 12, 21),
        "scene.toml:12:25: error: unknown symbol `thta` (did you mean `theta`?)\n    \
         sin(thta) + 1\n        ^^^^"
    );
    assert_eq!(
        e.to_string(),
        "unknown symbol `thta` (did you mean `theta`?) (column 5)"
    );
    // End of input: a single caret after the last char.
    assert_eq!(err("x +").caret(), "x +\n   ^");
    // Multi-line source (TOML multi-line string): line and column follow the newline.
    let e = err("x +\n\t 2*thta");
    assert_eq!(e.column, 9);
    assert_eq!(e.caret(), "\t 2*thta\n\t   ^^^^");
    assert!(e
        .render("a.toml", 3, 10)
        .starts_with("a.toml:4:5: error: unknown symbol `thta`"));
    // Columns count chars, not bytes.
    let e = err("θ*θ");
    assert_eq!(e.caret(), "θ*θ\n^");
}

// ---------------------------------------------------------------- no panics

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn pick<'a, T>(&mut self, xs: &'a [T]) -> &'a T {
        &xs[(self.next() % xs.len() as u64) as usize]
    }
}

/// Compile; when it succeeds, evaluate over f64 and duals and check the stack bound and the
/// Display round trip.
fn exercise(src: &str, t: &SymbolTable) -> bool {
    let e = match Expr::compile(src, t) {
        Ok(e) => e,
        Err(err) => {
            assert!(
                err.column >= 1 && err.column <= src.chars().count() + 1,
                "{src}: {err}"
            );
            let _ = (err.caret(), err.render("f.toml", 3, 7), err.to_string());
            let _ = referenced_names(src);
            return false;
        }
    };
    let slots: Vec<f64> = (0..t.len()).map(|i| 0.3 + 0.7 * i as f64).collect();
    let mut stack = Vec::with_capacity(e.max_stack());
    let cap = stack.capacity();
    let v = e.eval(&slots, &mut stack);
    assert_eq!(stack.capacity(), cap, "{src}");
    let dslots: Vec<Dual64> = slots.iter().map(|&s| Dual64::new(s, 1.0)).collect();
    let mut dstack = e.new_stack();
    let d = e.eval(&dslots, &mut dstack);
    // num-dual computes a/b as a*(1/b) and powers by its own formulas: equal up to rounding.
    if v.is_finite() && d.re.is_finite() {
        assert!(
            (d.re - v).abs() <= 1e-9 * (1.0 + v.abs()),
            "{src}: {} vs {v}",
            d.re
        );
    }
    let shown = e.to_string();
    let again = Expr::compile(&shown, t).unwrap_or_else(|err| panic!("{src} -> {shown}: {err}"));
    assert_eq!(again.code(), e.code(), "{src} -> {shown}");
    let _ = (e.caret_free(), referenced_names(src).unwrap());
    true
}

impl Expr {
    fn caret_free(&self) -> usize {
        self.len()
    }
}

/// A random well-formed expression over the test table.
fn gen_expr(rng: &mut Rng, depth: u32) -> String {
    let atoms = [
        "x",
        "y",
        "t",
        "theta",
        "r'",
        "r''",
        "tip.x",
        "tip.vel.y",
        "2",
        "0.5",
        "1e-3",
        "pi",
        "3",
    ];
    if depth == 0 || rng.next() % 3 == 0 {
        return rng.pick(&atoms).to_string();
    }
    let a = gen_expr(rng, depth - 1);
    let b = gen_expr(rng, depth - 1);
    match rng.next() % 8 {
        0 => format!("{a} + {b}"),
        1 => format!("{a} - {b}"),
        2 => format!("({a})*{b}"),
        3 => format!("{a}/({b})"),
        4 => format!(
            "({a})^{}",
            rng.pick(&["2", "3", "-1", "0.5", "1.5", "y", "(x)"])
        ),
        5 => format!("-{a}"),
        6 => format!("atan2({a}, {b})"),
        _ => format!(
            "{}({a})",
            rng.pick(&["sin", "cos", "tan", "exp", "log", "sqrt", "abs", "sinh", "tanh", "atan"])
        ),
    }
}

#[test]
fn random_input_never_panics() {
    let t = table();
    let pieces = [
        "x",
        "y",
        "t",
        "theta",
        "thta",
        "r'",
        "r''",
        "r'''",
        "tip.x",
        "tip.",
        "tip.vel.y",
        "1",
        "2.5",
        ".5",
        "1e-3",
        "1e",
        "0",
        "+",
        "-",
        "*",
        "/",
        "^",
        "(",
        ")",
        ",",
        "sin",
        "atan2",
        "sqrt",
        "log",
        "abs",
        "pi",
        " ",
        "'",
        ".",
        "e",
        "θ",
        "**",
        "\n",
        "2x",
        "1.2.3",
    ];
    let chars: Vec<char> = "xyt0123456789.+-*/^(),' e_\tθ#;sinco".chars().collect();
    let mut rng = Rng(0x2545_f491_4f6c_dd1d);
    let mut ok = 0;
    for _ in 0..20_000 {
        let n = rng.next() % 24;
        let mut s = String::new();
        for _ in 0..n {
            if rng.next() % 4 == 0 {
                s.push(*rng.pick(&chars));
            } else {
                let p: &&str = rng.pick(&pieces);
                s.push_str(p);
            }
        }
        ok += usize::from(exercise(&s, &t));
    }
    // Random well-formed expressions, and each with one character deleted or inserted.
    for _ in 0..3_000 {
        let src = gen_expr(&mut rng, 4);
        assert!(
            exercise(&src, &t)
                || Expr::compile(&src, &t)
                    .is_err_and(|e| matches!(e.kind, ExprErrorKind::NonFinite { .. })),
            "{src}"
        );
        let cs: Vec<char> = src.chars().collect();
        let i = (rng.next() % (cs.len() as u64 + 1)) as usize;
        let del: String = cs
            .iter()
            .enumerate()
            .filter(|&(j, _)| j != i)
            .map(|(_, c)| c)
            .collect();
        let mut ins = cs.clone();
        ins.insert(i, *rng.pick(&chars));
        ok += usize::from(exercise(&del, &t));
        ok += usize::from(exercise(&ins.into_iter().collect::<String>(), &t));
    }
    // Every prefix and suffix of valid expressions.
    let valid = [
        "atan2(tip.vel.y, -x^2) + sqrt(abs(r''))*exp(-t/2) - 1.5e-3*(theta - pi/4)^3",
        "log(1 + x^y) / (sinh(r') - cosh(r)) + tanh(.5*t)",
    ];
    for v in valid {
        assert!(exercise(v, &t));
        let cs: Vec<char> = v.chars().collect();
        for i in 0..=cs.len() {
            let pre: String = cs[..i].iter().collect();
            let suf: String = cs[i..].iter().collect();
            ok += usize::from(exercise(&pre, &t));
            ok += usize::from(exercise(&suf, &t));
        }
    }
    assert!(
        ok > 100,
        "the fuzz loop should also produce valid expressions ({ok})"
    );
}

// ---------------------------------------------------------------- derivatives

/// Compile `src` over the single variable `x`.
fn unary(src: &str) -> Expr {
    let t: SymbolTable = ["x"].into_iter().collect();
    Expr::compile(src, &t).unwrap()
}

#[test]
#[allow(clippy::too_many_lines)] // over 100 lines before the lint: to split, not to grow
fn first_and_second_derivatives_of_each_function() {
    type F = fn(f64) -> f64;
    // (source, points, f, f', f'')
    let cases: &[(&str, &[f64], F, F, F)] = &[
        (
            "sin(x)",
            &[0.3, -2.0, 4.0],
            |x| x.sin(),
            |x| x.cos(),
            |x| -x.sin(),
        ),
        (
            "cos(x)",
            &[0.3, -2.0, 4.0],
            |x| x.cos(),
            |x| -x.sin(),
            |x| -x.cos(),
        ),
        (
            "tan(x)",
            &[0.3, -1.2],
            |x| x.tan(),
            |x| 1.0 / x.cos().powi(2),
            |x| 2.0 * x.tan() / x.cos().powi(2),
        ),
        (
            "asin(x)",
            &[0.3, -0.8],
            |x| x.asin(),
            |x| 1.0 / (1.0 - x * x).sqrt(),
            |x| x / (1.0 - x * x).powf(1.5),
        ),
        (
            "acos(x)",
            &[0.3, -0.8],
            |x| x.acos(),
            |x| -1.0 / (1.0 - x * x).sqrt(),
            |x| -x / (1.0 - x * x).powf(1.5),
        ),
        (
            "atan(x)",
            &[0.3, -3.0],
            |x| x.atan(),
            |x| 1.0 / (1.0 + x * x),
            |x| -2.0 * x / (1.0 + x * x).powi(2),
        ),
        (
            "exp(x)",
            &[0.3, -3.0],
            |x| x.exp(),
            |x| x.exp(),
            |x| x.exp(),
        ),
        (
            "log(x)",
            &[0.3, 7.0],
            |x| x.ln(),
            |x| 1.0 / x,
            |x| -1.0 / (x * x),
        ),
        (
            "sqrt(x)",
            &[0.3, 7.0],
            |x| x.sqrt(),
            |x| 0.5 / x.sqrt(),
            |x| -0.25 / (x * x.sqrt()),
        ),
        ("abs(x)", &[0.3, -7.0], |x| x.abs(), |x| x.signum(), |_| 0.0),
        (
            "sinh(x)",
            &[0.3, -2.0],
            |x| x.sinh(),
            |x| x.cosh(),
            |x| x.sinh(),
        ),
        (
            "cosh(x)",
            &[0.3, -2.0],
            |x| x.cosh(),
            |x| x.sinh(),
            |x| x.cosh(),
        ),
        (
            "tanh(x)",
            &[0.3, -2.0],
            |x| x.tanh(),
            |x| 1.0 / x.cosh().powi(2),
            |x| -2.0 * x.tanh() / x.cosh().powi(2),
        ),
        ("x^2", &[0.3, -2.0], |x| x * x, |x| 2.0 * x, |_| 2.0),
        (
            "x^3",
            &[0.3, -2.0],
            |x| x.powi(3),
            |x| 3.0 * x * x,
            |x| 6.0 * x,
        ),
        (
            "x^-2",
            &[0.3, -2.0],
            |x| x.powi(-2),
            |x| -2.0 * x.powi(-3),
            |x| 6.0 * x.powi(-4),
        ),
        (
            "x^1.5",
            &[0.3, 2.0],
            |x| x.powf(1.5),
            |x| 1.5 * x.sqrt(),
            |x| 0.75 / x.sqrt(),
        ),
        (
            "x^x",
            &[0.3, 2.0],
            |x| x.powf(x),
            |x| x.powf(x) * (x.ln() + 1.0),
            |x| x.powf(x) * ((x.ln() + 1.0).powi(2) + 1.0 / x),
        ),
        (
            "2^x",
            &[0.3, -2.0],
            |x| 2f64.powf(x),
            |x| 2f64.powf(x) * 2f64.ln(),
            |x| 2f64.powf(x) * 2f64.ln().powi(2),
        ),
        (
            "1/x",
            &[0.3, -2.0],
            |x| 1.0 / x,
            |x| -1.0 / (x * x),
            |x| 2.0 / x.powi(3),
        ),
        (
            "x*sin(x)",
            &[0.3, -2.0],
            |x| x * x.sin(),
            |x| x.sin() + x * x.cos(),
            |x| 2.0 * x.cos() - x * x.sin(),
        ),
        (
            "exp(-x/2)*cos(3*x)",
            &[0.3, 2.0],
            |x| (-x / 2.0).exp() * (3.0 * x).cos(),
            |x| (-x / 2.0).exp() * (-0.5 * (3.0 * x).cos() - 3.0 * (3.0 * x).sin()),
            |x| (-x / 2.0).exp() * (-8.75 * (3.0 * x).cos() + 3.0 * (3.0 * x).sin()),
        ),
    ];
    for (src, points, f, f1, f2) in cases {
        let e = unary(src);
        for &x in *points {
            let v: f64 = e.value(&[x]);
            close(v, f(x), &format!("{src} at {x}"));
            let d = e.value(&[Dual64::new(x, 1.0)]);
            close(d.re, f(x), &format!("{src} dual value at {x}"));
            close(d.eps, f1(x), &format!("{src}' at {x}"));
            let d2 = e.value(&[Dual2_64::new(x, 1.0, 0.0)]);
            close(d2.re, f(x), &format!("{src} dual2 value at {x}"));
            close(d2.v1, f1(x), &format!("{src}' (dual2) at {x}"));
            close(d2.v2, f2(x), &format!("{src}'' at {x}"));
            // Nested duals: second derivative as the derivative of the derivative.
            let n = e.value(&[Dual::new(Dual64::new(x, 1.0), Dual64::new(1.0, 0.0))]);
            close(n.eps.eps, f2(x), &format!("{src}'' (nested) at {x}"));
        }
    }
}

/// Gradient and Hessian of f(y, x) along direction (a, b) from one Dual2 evaluation:
/// d/ds f = f_y a + f_x b, d²/ds² = f_yy a² + 2 f_xy a b + f_xx b².
fn directional(e: &Expr, y: f64, x: f64, a: f64, b: f64) -> Dual2_64 {
    e.value(&[Dual2_64::new(y, a, 0.0), Dual2_64::new(x, b, 0.0)])
}

#[test]
fn atan2_derivatives_in_all_quadrants_and_on_axes() {
    let t: SymbolTable = ["y", "x"].into_iter().collect();
    let e = Expr::compile("atan2(y, x)", &t).unwrap();
    let points: [(f64, f64); 12] = [
        (1.0, 2.0),
        (2.0, 1.0),
        (1.0, -2.0),
        (2.0, -0.5),
        (-1.0, -2.0),
        (-2.0, -1.0),
        (-1.0, 2.0),
        (-3.0, 0.5),
        (1.0, 0.0), // x = 0: num-dual's own atan2 gives NaN here
        (-1.0, 0.0),
        (0.0, 1.0),
        (0.0, -1.0), // on the branch cut
    ];
    for (y, x) in points {
        let r2 = x * x + y * y;
        let (fy, fx) = (x / r2, -y / r2);
        let (fyy, fxx, fxy) = (
            -2.0 * x * y / r2 / r2,
            2.0 * x * y / r2 / r2,
            (y * y - x * x) / r2 / r2,
        );
        assert_eq!(e.value(&[y, x]), y.atan2(x));
        let dy = e.value(&[Dual64::new(y, 1.0), Dual64::new(x, 0.0)]);
        assert_eq!(dy.re, y.atan2(x), "value exact at ({y}, {x})");
        close(dy.eps, fy, &format!("d/dy at ({y}, {x})"));
        let dx = e.value(&[Dual64::new(y, 0.0), Dual64::new(x, 1.0)]);
        close(dx.eps, fx, &format!("d/dx at ({y}, {x})"));
        for (a, b) in [(1.0, 0.0), (0.0, 1.0), (0.6, -0.8)] {
            let d = directional(&e, y, x, a, b);
            assert_eq!(d.re, y.atan2(x));
            let want1 = fy * a + fx * b;
            let want2 = fyy * a * a + 2.0 * fxy * a * b + fxx * b * b;
            if want1 == 0.0 {
                assert!(d.v1.abs() < 1e-16, "({y}, {x}) dir ({a}, {b}): {}", d.v1);
            } else {
                close(d.v1, want1, &format!("dir ({a}, {b}) first at ({y}, {x})"));
            }
            if want2 == 0.0 {
                assert!(d.v2.abs() < 1e-15, "({y}, {x}) dir ({a}, {b}): {}", d.v2);
            } else {
                close(d.v2, want2, &format!("dir ({a}, {b}) second at ({y}, {x})"));
            }
        }
    }
}

#[test]
fn power_with_symbolic_exponent_partials() {
    let t: SymbolTable = ["x", "y"].into_iter().collect();
    let e = Expr::compile("x^y", &t).unwrap();
    for (x, y) in [(1.7f64, 2.3f64), (0.4, -1.5), (3.0, 0.5)] {
        let p = x.powf(y);
        let l = x.ln();
        let fx = y * x.powf(y - 1.0);
        let fy = p * l;
        let fxx = y * (y - 1.0) * x.powf(y - 2.0);
        let fyy = p * l * l;
        let fxy = x.powf(y - 1.0) * (1.0 + y * l);
        let d = e.value(&[Dual2_64::new(x, 1.0, 0.0), Dual2_64::new(y, 0.0, 0.0)]);
        close(d.re, p, "x^y");
        close(d.v1, fx, "d/dx x^y");
        close(d.v2, fxx, "d2/dx2 x^y");
        let d = e.value(&[Dual2_64::new(x, 0.0, 0.0), Dual2_64::new(y, 1.0, 0.0)]);
        close(d.v1, fy, "d/dy x^y");
        close(d.v2, fyy, "d2/dy2 x^y");
        let (a, b) = (0.6, 0.8);
        let d = e.value(&[Dual2_64::new(x, a, 0.0), Dual2_64::new(y, b, 0.0)]);
        close(
            d.v2,
            fxx * a * a + 2.0 * fxy * a * b + fyy * b * b,
            "mixed x^y",
        );
    }
}

#[test]
fn symbolic_integer_exponent_with_negative_base() {
    let t: SymbolTable = ["x", "n"].into_iter().collect();
    let e = Expr::compile("x^n", &t).unwrap();
    for (x, n) in [(-1.5f64, 3.0f64), (-1.5, 2.0), (-0.7, -3.0), (2.0, 3.0)] {
        assert_eq!(e.value(&[x, n]), x.powi(n as i32));
        let d = e.value(&[Dual2_64::new(x, 1.0, 0.0), Dual2_64::new(n, 0.0, 0.0)]);
        close(d.re, x.powi(n as i32), "x^n");
        close(d.v1, n * x.powi(n as i32 - 1), "d/dx x^n");
        close(d.v2, n * (n - 1.0) * x.powi(n as i32 - 2), "d2/dx2 x^n");
    }
}

#[test]
fn chain_rule_through_a_compound_expression() {
    // g(q, v) = l*sin(q) + v^2/2 with q = q0 + s, v = v0 + 2 s: dg/ds and d2g/ds2.
    let t: SymbolTable = ["q", "q'"].into_iter().collect();
    let e = Expr::compile("l*sin(q) + q'^2/2", &{
        let mut t = t.clone();
        t.insert("l");
        t
    });
    let e = e.unwrap();
    let (q, v, l) = (0.7, -1.3, 2.5);
    let d = e.value(&[
        Dual2_64::new(q, 1.0, 0.0),
        Dual2_64::new(v, 2.0, 0.0),
        Dual2_64::new(l, 0.0, 0.0),
    ]);
    close(d.re, l * q.sin() + v * v / 2.0, "value");
    close(d.v1, l * q.cos() + 2.0 * v, "first");
    close(d.v2, -l * q.sin() + 4.0, "second");
}

/// num-dual's powf is NaN at a zero base; the evaluator gives the exact 0 value and first
/// derivatives there (Example 3.1's (p^2 + q^2)^(3/2) at p = q = 0).
#[test]
fn real_power_at_zero_base_has_finite_derivatives() {
    use num_dual::Dual64;
    let mut t = SymbolTable::new();
    t.insert("p");
    t.insert("q");
    let e = Expr::compile("(p^2 + q^2)^1.5", &t).unwrap();
    let d = e.eval(
        &[Dual64::new(0.0, 1.0), Dual64::new(0.0, 0.0)],
        &mut Vec::new(),
    );
    assert_eq!((d.re, d.eps), (0.0, 0.0));
    let d = e.eval(
        &[Dual64::new(0.3, 1.0), Dual64::new(0.4, 0.0)],
        &mut Vec::new(),
    );
    assert!((d.eps - 1.5 * 0.25f64.sqrt() * 0.6).abs() < 1e-15);
}

/// Repeated subexpressions are computed once (cse.rs) and give the plain code's values bit for
/// bit, over f64 and over second-order duals, on random expressions built to repeat subtrees.
#[test]
fn stored_subexpressions_give_the_plain_values_bit_for_bit() {
    let t = table();
    let mut rng = Rng(0x05ee_dc5e);
    let same = |a: f64, b: f64| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
    let mut stored = 0;
    for case in 0..400 {
        let a = gen_expr(&mut rng, 3);
        let b = gen_expr(&mut rng, 2);
        let src = match case % 4 {
            0 => format!("({a})*sin({a}) + ({b})/({a})"),
            1 => format!("sqrt(({a})^2 + ({b})^2) - ({a})^2"),
            2 => format!("({b}) - ({a}) + exp(-({a}))*({b})"),
            _ => format!("atan2({a}, {b}) + atan2({a}, {b})^2"),
        };
        let (Ok(e), Ok(p)) = (
            Expr::compile_with(&src, &t, true),
            Expr::compile_with(&src, &t, false),
        ) else {
            continue; // a constant operand that overflows, say: both refuse alike
        };
        if e.code().iter().any(|o| matches!(o, Op::Get(_))) {
            stored += 1;
            assert!(e.len() < p.len() + 2, "{src}: stored code is not shorter");
        }
        let slots: Vec<f64> = (0..t.len()).map(|k| 0.3 + 0.37 * k as f64).collect();
        assert!(same(e.value(&slots), p.value(&slots)), "{src}");
        let dslots: Vec<Dual2_64> = slots
            .iter()
            .enumerate()
            .map(|(k, &x)| Dual2_64::new(x, 0.1 * k as f64 - 0.2, 0.0))
            .collect();
        let (x, y) = (e.value(&dslots), p.value(&dslots));
        assert!(
            same(x.re, y.re) && same(x.v1, y.v1) && same(x.v2, y.v2),
            "{src}: {x:?} vs {y:?}"
        );
    }
    assert!(
        stored > 250,
        "only {stored} of 400 cases stored a subexpression"
    ); // the rest repeat a leaf
}

#[test]
fn a_repeated_call_is_computed_once() {
    let t = table();
    let e = Expr::compile("sin(x*t)*y + sin(x*t)^2 - sqrt(1 - sin(x*t)^2)", &t).unwrap();
    let sines = e.code().iter().filter(|o| matches!(o, Op::Sin)).count();
    assert_eq!(sines, 1, "{:?}", e.code());
    let p =
        Expr::compile_with("sin(x*t)*y + sin(x*t)^2 - sqrt(1 - sin(x*t)^2)", &t, false).unwrap();
    assert_eq!(p.code().iter().filter(|o| matches!(o, Op::Sin)).count(), 3);
    let slots: [f64; 9] = [0.7, -0.2, 1.3, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert_eq!(e.value(&slots).to_bits(), p.value(&slots).to_bits());
}

/// The reverse sweep (`tape.rs`) against one `Dual` pass per slot: every instruction kind (fused
/// constant and slot operands, stored subexpressions, each function); values bit for bit.
#[test]
fn gradient_matches_one_dual_pass_per_slot() {
    let t = table();
    let srcs = [
        "x*y + 3*x - y/x + 2/y - x/2 + (x - 1)*(y + 2) - (5 - x) + y - x",
        "sin(x)*cos(y) + tan(x/3) + asin(x/4) + acos(y/5) + atan(x*y) + atan2(y, x) + atan2(x, -y)",
        "exp(x/2) + log(y) + sqrt(x*y) + abs(x - y) + sinh(x) + cosh(y) + tanh(x*y)",
        "x^2 + x^3 + y^-2 + x^1.5 + y^x + x^y + (-x)^3 + 2^x",
        "sqrt((x - cos(t))^2 + y^2)*(x - cos(t))/(1 + sqrt((x - cos(t))^2 + y^2)) - -x",
        "r/theta + theta/r + r*theta + r - theta + theta - r + tip.x*tip.vel.y",
        "x",
        "2*t",
    ];
    let base = [0.7, 1.3, 0.4, -0.8, 1.9, 0.5, -0.2, 0.3, 1.1];
    for src in srcs {
        let e = Expr::compile(src, &t).unwrap_or_else(|err| panic!("{src}: {err}"));
        let mut work = Vec::with_capacity(e.gradient_work());
        let cap = work.capacity();
        let mut grad = vec![f64::NAN; base.len()];
        let v = e.gradient(&base, &mut work, &mut grad);
        assert_eq!(v.to_bits(), e.value(&base).to_bits(), "{src}: value");
        for &s in e.slots() {
            let d: Vec<Dual64> = (0..base.len())
                .map(|k| Dual64::new(base[k], if k == s { 1.0 } else { 0.0 }))
                .collect();
            let want = e.value(&d).eps;
            assert!(
                rel(grad[s], want) <= 64.0 * f64::EPSILON,
                "{src}: d/d{} = {} against {want}",
                t.name(s).unwrap(),
                grad[s]
            );
        }
        // unread slots untouched
        for k in 0..base.len() {
            if !e.uses(k) {
                assert!(grad[k].is_nan(), "{src}: slot {k} written");
            }
        }
        assert_eq!(work.capacity(), cap, "{src}: allocated");
    }
    // over duals (a derivative of the gradient): the dual parts agree too
    let e = Expr::compile("sin(x)*y^3 + atan2(y, x)*exp(x*y)", &t).unwrap();
    let d: Vec<Dual64> = base.iter().map(|&b| Dual64::new(b, 0.5)).collect();
    let mut grad = vec![Dual64::from(0.0); base.len()];
    e.gradient(&d, &mut Vec::new(), &mut grad);
    for &s in e.slots() {
        let dd: Vec<Dual<Dual64>> = (0..base.len())
            .map(|k| Dual::new(d[k], Dual64::from(if k == s { 1.0 } else { 0.0 })))
            .collect();
        let want = e.value(&dd).eps;
        assert!(rel(grad[s].re, want.re) <= 64.0 * f64::EPSILON);
        assert!(rel(grad[s].eps, want.eps) <= 64.0 * f64::EPSILON);
    }
}

/// `Expr::affine`: linear slots x, y, tip.x (0, 1, 7), free slot t (2). Each affine answer is
/// checked against the tape's gradient at three states (the coefficients, and the value equals
/// sum c x + F with F = E at zero linear slots); the nonlinear forms (products of linear slots, a
/// linear slot times or under a function of t, division by a linear slot, a slot that is neither)
/// must be refused.
#[test]
fn affine_forms_are_recognised_and_nonlinear_ones_refused() {
    let t = table();
    let linear = |s: usize| [0, 1, 7].contains(&s);
    let free = |s: usize| s == 2;
    let affine = [
        ("x", vec![(0, 1.0)], false),
        (
            "tip.x - (0.3 - 0.1 + 0.1*cos(2*pi*(t/4 - sin(2*pi*t/4)/(2*pi))))",
            vec![(7, 1.0)],
            true,
        ),
        ("2*x - 3*y/4 + 1", vec![(0, 2.0), (1, -0.75)], false),
        (
            "-(x - y)*0.5 - (1 - tip.x)",
            vec![(0, -0.5), (1, 0.5), (7, 1.0)],
            false,
        ),
        ("(x + sin(t))*2 + (x + sin(t)) - 3*x", vec![(0, 0.0)], true),
        (
            "(0.6)*(x) + (-0.8)*(y) - t^2/exp(t)",
            vec![(0, 0.6), (1, -0.8)],
            true,
        ),
    ];
    let states = [
        [0.7, 1.3, 0.4, -0.8, 1.9, 0.5, -0.2, 0.3, 1.1],
        [-1.1, 0.2, 2.5, 0.1, 0.4, -0.3, 0.9, -1.7, 0.6],
        [0.05, -2.0, -0.6, 0.3, 0.2, 0.1, 0.0, 4.0, -0.4],
    ];
    for (src, terms, reads_free) in &affine {
        let e = Expr::compile(src, &t).unwrap_or_else(|err| panic!("{src}: {err}"));
        let a = e
            .affine(linear, free)
            .unwrap_or_else(|| panic!("{src}: not affine"));
        assert_eq!(a.reads_free, *reads_free, "{src}");
        assert_eq!(a.terms.len(), terms.len(), "{src}: {a:?}");
        for ((s, c), (ws, wc)) in a.terms.iter().zip(terms) {
            assert!(
                s == ws && (c - wc).abs() <= 4.0 * f64::EPSILON,
                "{src}: {a:?}"
            );
        }
        for base in &states {
            let mut grad = vec![0.0; base.len()];
            let v = e.gradient(base, &mut Vec::new(), &mut grad);
            for &(s, c) in &a.terms {
                assert!((grad[s] - c).abs() <= 4.0 * f64::EPSILON, "{src}: d/d{s}");
            }
            let mut zeroed = *base;
            for &(s, _) in &a.terms {
                zeroed[s] = 0.0;
            }
            let f = e.value(&zeroed);
            let sum: f64 = a.terms.iter().map(|&(s, c)| c * base[s]).sum::<f64>() + f;
            assert!(
                (sum - v).abs() <= 1e2 * f64::EPSILON * (1.0 + v.abs()),
                "{src}: value"
            );
        }
    }
    for src in [
        "x*x",
        "x^2 - 1",
        "t*x",
        "x/t",
        "sin(x)",
        "x*y",
        "1/x",
        "y/x",
        "x - theta",
        "sqrt(tip.x^2)",
        "atan2(x, 1)",
        "2^x",
        "abs(x)",
        "x*(t - t)",
        "x/2 - y*t/t*0 + 5",
    ] {
        let e = Expr::compile(src, &t).unwrap();
        assert_eq!(e.affine(linear, free), None, "{src}");
    }
    // with no slot linear, a function of t alone is affine with no terms
    let e = Expr::compile("3*t - sin(t)", &t).unwrap();
    let a = e.affine(|_| false, free).unwrap();
    assert!(a.terms.is_empty() && a.reads_free);
}
