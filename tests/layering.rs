//! The crate's top-level modules (ARCHITECTURE.md's rooms) form no circle: every `crate::x` path
//! in module `y`'s non-test code is an arrow y -> x, and the arrows must be acyclic, so each room
//! can be read (and tested) knowing only the rooms below it. A circle fails with the files and
//! lines of its arrows.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

type Arrows = BTreeMap<String, BTreeMap<String, Vec<String>>>;

/// Every `.rs` file under `dir`.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// Names of the modules declared `#[cfg(test)] mod name;` anywhere (their files are test code).
fn test_modules(files: &[PathBuf]) -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    for f in files {
        let text = std::fs::read_to_string(f).unwrap();
        let mut lines = text.lines().map(str::trim);
        while let Some(l) = lines.next() {
            if l == "#[cfg(test)]" {
                if let Some(decl) = lines.next().and_then(|n| n.strip_prefix("mod ")) {
                    if let Some(name) = decl.strip_suffix(';') {
                        names.insert(name.to_string());
                    }
                }
            }
        }
    }
    names
}

/// The arrows between the top-level modules of `src`, each with where it is written.
fn arrows(src: &Path) -> Arrows {
    let mut files = vec![];
    rust_files(src, &mut files);
    let tests = test_modules(&files);
    let room = |f: &Path| -> Option<String> {
        let rel = f.strip_prefix(src).unwrap();
        let first = rel.components().next()?.as_os_str().to_str()?.to_string();
        let name = first.strip_suffix(".rs").unwrap_or(&first).to_string();
        (name != "lib" && name != "main").then_some(name)
    };
    let rooms: BTreeSet<String> = files.iter().filter_map(|f| room(f)).collect();
    let mut out = Arrows::new();
    for f in &files {
        let Some(from) = room(f) else { continue };
        let stem = f.file_stem().unwrap().to_str().unwrap();
        if stem == "tests" || tests.contains(stem) {
            continue;
        }
        let text = std::fs::read_to_string(f).unwrap();
        let code = text.split("#[cfg(test)]\nmod tests").next().unwrap();
        for (k, line) in code.lines().enumerate() {
            let line = line.split("//").next().unwrap();
            for piece in line.split("crate::").skip(1) {
                let to: String = piece
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                if to != from && rooms.contains(&to) {
                    let at = format!("{}:{}", f.display(), k + 1);
                    out.entry(from.clone())
                        .or_default()
                        .entry(to)
                        .or_default()
                        .push(at);
                }
            }
        }
    }
    out
}

/// A circle of the arrows, as the rooms in order, or None.
fn circle(arrows: &Arrows) -> Option<Vec<String>> {
    fn visit(
        at: &str,
        arrows: &Arrows,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(i) = path.iter().position(|p| p == at) {
            return Some(path[i..].to_vec());
        }
        if !done.insert(at.to_string()) {
            return None;
        }
        path.push(at.to_string());
        for to in arrows.get(at).into_iter().flat_map(|m| m.keys()) {
            if let Some(c) = visit(to, arrows, path, done) {
                return Some(c);
            }
        }
        path.pop();
        None
    }
    let mut done = BTreeSet::new();
    arrows
        .keys()
        .find_map(|r| visit(r, arrows, &mut vec![], &mut done))
}

#[test]
fn the_top_level_modules_form_no_circle() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let a = arrows(&src);
    assert!(
        a.len() > 10,
        "the scan found the crate's modules: {:?}",
        a.keys()
    );
    assert!(
        a["scene"].contains_key("solve"),
        "the scan sees `crate::` paths"
    );
    if let Some(c) = circle(&a) {
        let mut msg = format!("module circle: {} -> {}\n", c.join(" -> "), c[0]);
        for (i, from) in c.iter().enumerate() {
            let to = &c[(i + 1) % c.len()];
            msg += &format!("  {from} -> {to}: {:?}\n", a[from][to]);
        }
        panic!("{msg}");
    }
}

/// Negative control: a back-arrow written into a copy of two rooms is found.
#[test]
fn a_planted_back_arrow_is_found() {
    let dir = std::env::temp_dir().join(format!("progmo-layering-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("high")).unwrap();
    std::fs::write(dir.join("high/mod.rs"), "use crate::low::f;\n").unwrap();
    std::fs::write(dir.join("low.rs"), "pub fn f() {}\n").unwrap();
    let one_way = arrows(&dir);
    assert_eq!(circle(&one_way), None);
    std::fs::write(dir.join("low.rs"), "pub fn f() { crate::high::g() }\n").unwrap();
    let both = arrows(&dir);
    let c = circle(&both).expect("the back-arrow closes a circle");
    assert_eq!(c.len(), 2, "{c:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}
