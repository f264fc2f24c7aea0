//! Stable, bounded version of the fuzz targets (`fuzz/`, nightly): mutated scene files and
//! generated expressions go through the same bodies (`progmo::fuzzing`), which must not panic.
//! A few thousand cases, a few seconds in release; the long coverage-guided runs are `fuzz/run.sh`.

mod common;

use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};

/// The seed scenes: catalog, test-only scenes and the bad-input set.
fn seeds() -> Vec<Vec<u8>> {
    let mut out = vec![];
    for dir in ["references/scenes", "tests/scenes", "tests/bad_scenes"] {
        let files = common::toml_files(dir);
        out.extend(files.iter().map(|p| std::fs::read(p).unwrap()));
    }
    out
}

/// Fragments worth splicing into scene text: numbers at the edges, structure, names.
const TOKENS: &[&str] = &[
    "nan",
    "inf",
    "-inf",
    "1e308",
    "1e-300",
    "5e-324",
    "0",
    "-1",
    "0.0",
    "[",
    "]",
    "[[",
    "]]",
    "{",
    "}",
    "\"",
    "=",
    "\n",
    ".",
    "'",
    "''",
    "(",
    ")",
    "^",
    "*",
    "+",
    "-",
    "/",
    "t",
    "pi",
    "sin(",
    "atan2(",
    "tip.x",
    "q1",
    "world",
    "\u{200b}",
    "\u{202e}",
    "\r",
    "\0",
    "[time]\n",
    "[solver]\n",
    "integrator = \"rk4\"\nstep = 1e-300\n",
    "output_dt = 1e-300\n",
    "max_samples = 2\n",
    "[[model.bodies]]\n",
    "[[model.sites]]\nname = \"s\"\nbody = \"link\"\n",
    "parent = \"world\"\n",
];

#[derive(Clone, Debug)]
enum Edit {
    Delete(usize, usize),
    Insert(usize, usize),
    Byte(usize, u8),
    Duplicate(usize, usize),
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<usize>(), 1usize..40).prop_map(|(a, n)| Edit::Delete(a, n)),
        (any::<usize>(), 0..TOKENS.len()).prop_map(|(a, k)| Edit::Insert(a, k)),
        (any::<usize>(), any::<u8>()).prop_map(|(a, b)| Edit::Byte(a, b)),
        (any::<usize>(), 1usize..200).prop_map(|(a, n)| Edit::Duplicate(a, n)),
    ]
}

fn apply(mut text: Vec<u8>, edits: &[Edit]) -> Vec<u8> {
    for e in edits {
        let len = text.len().max(1);
        match *e {
            Edit::Delete(a, n) => {
                let a = a % len;
                let b = (a + n).min(text.len());
                if a < b {
                    text.drain(a..b);
                }
            }
            Edit::Insert(a, k) => {
                let a = (a % len).min(text.len());
                text.splice(a..a, TOKENS[k].bytes());
            }
            Edit::Byte(a, b) => {
                if !text.is_empty() {
                    text[a % len] = b;
                }
            }
            Edit::Duplicate(a, n) => {
                let a = (a % len).min(text.len());
                let b = (a + n).min(text.len());
                let piece = text[a..b].to_vec();
                text.splice(b..b, piece);
            }
        }
    }
    text
}

#[test]
fn mutated_scenes_load_or_fail_cleanly() {
    let seeds = seeds();
    let mut runner = TestRunner::new(Config {
        cases: 3000,
        failure_persistence: None,
        ..Config::default()
    });
    let strategy = (0..seeds.len(), prop::collection::vec(edit(), 1..6));
    runner
        .run(&strategy, |(k, edits)| {
            progmo::fuzzing::scene(&apply(seeds[k].clone(), &edits));
            Ok(())
        })
        .unwrap();
}

/// Expressions from a small grammar (so most compile), plus raw strings.
fn expression() -> impl Strategy<Value = String> {
    let leaf = prop_oneof![
        Just("x".to_string()),
        Just("y".to_string()),
        Just("t".to_string()),
        Just("x'".to_string()),
        Just("tip.x".to_string()),
        Just("m".to_string()),
        Just("pi".to_string()),
        prop_oneof![
            Just(0.0),
            Just(-0.0),
            Just(1e308),
            Just(1e-308),
            Just(2.0),
            -10.0..10.0f64
        ]
        .prop_map(|v| format!("{v:e}")),
    ];
    leaf.prop_recursive(6, 64, 4, |inner| {
        prop_oneof![
            (inner.clone(), "[-+*/^]", inner.clone()).prop_map(|(a, o, b)| format!("{a} {o} {b}")),
            (
                "(sin|cos|tan|asin|acos|atan|exp|log|sqrt|abs|sinh|cosh|tanh)",
                inner.clone()
            )
                .prop_map(|(f, a)| format!("{f}({a})")),
            (inner.clone(), inner.clone()).prop_map(|(a, b)| format!("atan2({a}, {b})")),
            inner.clone().prop_map(|a| format!("-({a})")),
            inner.prop_map(|a| format!("({a})")),
        ]
    })
}

#[test]
fn generated_expressions_compile_and_evaluate_or_fail_cleanly() {
    let mut runner = TestRunner::new(Config {
        cases: 3000,
        failure_persistence: None,
        ..Config::default()
    });
    let strategy = prop_oneof![
        3 => expression(),
        1 => ".{0,40}",
    ];
    runner
        .run(&strategy, |text| {
            progmo::fuzzing::expr(text.as_bytes());
            Ok(())
        })
        .unwrap();
}
