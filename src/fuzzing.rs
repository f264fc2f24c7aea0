//! Bodies of the fuzz targets (`fuzz/`, cargo-fuzz on nightly) and of the stable property test
//! (`tests/fuzz_props.rs`): one function per target, so both exercise the same code.
//!
//! Each takes arbitrary bytes and must return without panicking; the invariants it checks are
//! asserted (an assertion failure is a crash the fuzzer reports).

use crate::expr::{Expr, SymbolTable};
use crate::scene::Scene;
use num_dual::{Dual2_64, Dual64};
use std::path::Path;

/// Scene text -> load. A load error must be located inside the text and render without panicking;
/// a loaded scene's settings must pass [`crate::solve::validate`].
pub fn scene(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match Scene::from_text(Path::new("fuzz.toml"), text) {
        Ok(scene) => {
            let span = scene.span();
            if let Err(e) = crate::solve::validate(span, &scene.settings) {
                panic!("a loaded scene fails validation: {e}");
            }
        }
        Err(e) => {
            let lines = text.lines().count().max(1);
            assert!(e.line <= lines + 1, "line {} of {lines}", e.line);
            let _ = e.to_string();
        }
    }
}

/// Expression text -> compile -> evaluate over f64, first- and second-order dual numbers.
pub fn expr(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let mut table: SymbolTable = ["t", "x", "y", "x'", "tip.x", "r''"].into_iter().collect();
    table.define("m", 1.5);
    table.define("L", 0.25);
    let e = match Expr::compile(text, &table) {
        Ok(e) => e,
        Err(err) => {
            let _ = err.render("fuzz.toml", 1, 1);
            return;
        }
    };
    let _ = (e.slots(), e.time_order(), e.constant(), e.max_stack());
    for x in [[0.3, -1.25, 2.0, 0.7, -0.4, 1e-3], [0.0; 6]] {
        let _: f64 = e.value(&x);
        let _: Dual64 = e.value(&x.map(|s| Dual64::new(s, 1.0)));
        let _: Dual2_64 = e.value(&x.map(|s| Dual2_64::new(s, 1.0, 0.0)));
    }
}
