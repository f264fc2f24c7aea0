//! The scene format is kept once, in the serde types of `src/scene/file.rs`:
//! - `src/scene/scene.schema.json` is generated from them (`progmo::scene::schema::json_schema`)
//!   and must equal the committed file; regenerate it with
//!   `PROGMO_BLESS=1 cargo test --release --test integration schema::`;
//! - every bundled scene (catalog, Test Set, test scenes) validates against it (a JSON Schema
//!   validator, draft 2020-12), and the maximal example scenes, which load, use every key it has;
//! - `FORMAT.md` documents exactly its keys: each key table of the page is marked with the
//!   table it documents (`<!-- keys: model.bodies[] -->` on the line before the table; the
//!   keys are the backticked names in the first column), and per table the page's keys equal
//!   the schema's properties.

use crate::common;

use progmo::scene::schema::json_schema;
use progmo::scene::Scene;
use serde_json::Value as Json;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

const SCHEMA_FILE: &str = "src/scene/scene.schema.json";

/// The generated schema as committed: pretty JSON, two-space indent, final newline.
fn schema_text() -> String {
    serde_json::to_string_pretty(&json_schema()).unwrap() + "\n"
}

#[test]
fn the_committed_schema_is_the_generated_one() {
    let path = root().join(SCHEMA_FILE);
    let generated = schema_text();
    if std::env::var_os("PROGMO_BLESS").is_some() {
        std::fs::write(&path, &generated).unwrap();
        return;
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "{SCHEMA_FILE} differs from the schema generated from src/scene/file.rs; regenerate it \
         with `PROGMO_BLESS=1 cargo test --release --test integration schema::` and commit it"
    );
}

fn validator() -> jsonschema::Validator {
    jsonschema::draft202012::new(&json_schema()).expect("the generated schema is valid")
}

/// Schema errors of a TOML scene text (converted to JSON), one line each.
fn errors(v: &jsonschema::Validator, text: &str) -> Vec<String> {
    let toml: toml::Value = toml::from_str(text).expect("TOML");
    let json = serde_json::to_value(toml).unwrap();
    v.iter_errors(&json)
        .map(|e| format!("{}: {e}", e.instance_path()))
        .collect()
}

#[test]
fn every_bundled_scene_matches_the_schema() {
    let v = validator();
    let mut bad = vec![];
    let mut n = 0;
    for dir in ["references/scenes", "references/testset", "tests/scenes"] {
        for f in common::toml_files(dir) {
            n += 1;
            for e in errors(&v, &std::fs::read_to_string(&f).unwrap()) {
                bad.push(format!("{}: {e}", f.display()));
            }
        }
    }
    assert!(n >= 15, "only {n} bundled scenes found");
    assert!(bad.is_empty(), "\n{}", bad.join("\n"));
}

/// The annotated example of FORMAT.md matches the schema, loads and solves within its tolerance
/// (the page cannot drift from the loader unnoticed).
#[test]
fn the_annotated_example_of_format_md_matches_the_schema_and_solves() {
    let page = std::fs::read_to_string(root().join("src/scene/FORMAT.md")).unwrap();
    let section = page
        .split_once("## A complete annotated example")
        .expect("section")
        .1;
    let block = section.split_once("```toml\n").unwrap().1;
    let block = block.split_once("```").unwrap().0;
    let e = errors(&validator(), block);
    assert!(e.is_empty(), "{e:?}");
    let s = Scene::from_text(Path::new("FORMAT.md"), block).unwrap_or_else(|e| panic!("{e}"));
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let worst = sol.max_residual.iter().cloned().fold(0.0, f64::max);
    assert!(worst <= s.tolerance("programme_residual").unwrap());
}

/// Negative controls: each change of a maximal example is refused by the schema and by the loader.
#[test]
fn the_schema_rejects_unknown_keys_bad_values_and_mixed_model_kinds() {
    let v = validator();
    let tree: [(&str, &str); 8] = [
        ("mass = 1.0\n", "mass = 1.0\ncolour = \"red\"\n"),
        ("integrator = \"rk4\"", "integrator = \"euler\""),
        ("strict = false", "strict = false\nfoo = 1"),
        ("type = \"ball\"", "type = \"hinge\""), // a hinge needs an axis
        ("kind = \"tree\"", "kind = \"tree\"\npotential = \"0\""),
        ("inertia = [0.01, 0.01, 0.01]", "inertia = [0.01, 0.01]"),
        ("b = \"2*a\"", "pi = \"2*a\""),
        ("\"Baumgarte keeps the drift small, not zero\"", "\" \""),
    ];
    let lagrangian: [(&str, &str); 2] = [
        ("potential", "gravity = [0.0, 0.0, 1.0]\npotential"),
        ("potential", "mass_diagonal = [\"1\", \"1\"]\npotential"),
    ];
    let cases = tree
        .iter()
        .map(|c| (MAXIMAL_TREE, c))
        .chain(lagrangian.iter().map(|c| (MAXIMAL_LAGRANGIAN, c)));
    for (example, (from, to)) in cases {
        assert_eq!(errors(&v, example), Vec::<String>::new());
        assert!(example.contains(from), "{from}");
        let text = example.replacen(from, to, 1);
        let e = errors(&v, &text);
        assert!(e.len() == 1, "`{to}` for `{from}`: schema errors {e:?}");
        assert!(
            Scene::from_text(Path::new("probe"), &text).is_err(),
            "the loader accepts `{to}` for `{from}`"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Tables of the schema.

/// Follow `$ref` (local `#/$defs/...` only).
fn resolve<'a>(root: &'a Json, node: &'a Json) -> &'a Json {
    match node.get("$ref").and_then(|r| r.as_str()) {
        Some(r) => {
            let name = r.strip_prefix("#/$defs/").expect("local $ref");
            resolve(root, &root["$defs"][name])
        }
        None => node,
    }
}

/// Name of the top-level table.
const TOP: &str = "(top level)";

/// The schema's tables with fixed keys, as TOML paths into a scene (`[]`: every element of an
/// array, `*`: every value of a map; the scene itself is [`TOP`]), with their keys.
fn tables(schema: &Json) -> BTreeMap<String, BTreeSet<String>> {
    fn walk(root: &Json, node: &Json, path: &str, out: &mut BTreeMap<String, BTreeSet<String>>) {
        let node = resolve(root, node);
        if let Some(items) = node.get("items") {
            walk(root, items, &format!("{path}[]"), out);
        }
        if let Some(Json::Object(p)) = node.get("properties") {
            let name = if path.is_empty() { TOP } else { path };
            out.insert(name.to_string(), p.keys().cloned().collect());
            for (k, s) in p {
                let sub = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                walk(root, s, &sub, out);
            }
        }
        if let Some(ap) = node.get("additionalProperties").filter(|a| a.is_object()) {
            walk(root, ap, &format!("{path}.*"), out);
        }
    }
    let mut out = BTreeMap::new();
    walk(schema, schema, "", &mut out);
    out
}

/// The sub-tables of `v` at a table path (every element of arrays: a shape or a view target
/// takes one of several key sets; the first map entry of `*`).
fn tables_at<'a>(v: &'a toml::Value, path: &str) -> Vec<&'a toml::Table> {
    let mut cur = vec![v];
    for seg in path.split('.').filter(|&s| s != TOP) {
        let (key, arrays) = (seg.trim_end_matches("[]"), seg.matches("[]").count());
        cur = cur
            .into_iter()
            .filter_map(|c| {
                let t = c.as_table()?;
                if key == "*" {
                    t.values().next()
                } else {
                    t.get(key)
                }
            })
            .collect();
        for _ in 0..arrays {
            cur = cur
                .into_iter()
                .filter_map(|c| c.as_array())
                .flatten()
                .collect();
        }
    }
    cur.into_iter().filter_map(|c| c.as_table()).collect()
}

/// A two-link planar chain with one closure (closures of different kinds use different keys).
fn maximal_closure(closure: &str) -> String {
    format!(
        r#"
name = "maximal_closure"
[model]
kind = "tree"
[[model.bodies]]
name = "l1"
mass = 1.0
com = [0.5, 0.0, 0.0]
inertia = [0.01, 0.1, 0.1]
joints = [{{ name = "q1", type = "hinge", axis = [0.0, 0.0, 1.0] }}]
[[model.bodies]]
name = "l2"
parent = "l1"
pos = [1.0, 0.0, 0.0]
mass = 1.0
com = [0.5, 0.0, 0.0]
inertia = [0.01, 0.1, 0.1]
joints = [{{ name = "q2", type = "hinge", axis = [0.0, 0.0, 1.0] }}]
{closure}
[initial]
[time]
t1 = 1.0
"#
    )
}

const WELD: &str = r#"[[model.closures]]
name = "w"
kind = "weld"
body_a = "l2"
point_a = [0.0, 0.0, 0.0]
quat_a = [1.0, 0.0, 0.0, 0.0]
body_b = "world"
point_b = [1.0, 0.0, 0.0]
quat_b = [1.0, 0.0, 0.0, 0.0]"#;

const DISTANCE: &str = r#"[[model.closures]]
name = "rope"
kind = "distance"
body_a = "l2"
point_a = [1.0, 0.0, 0.0]
body_b = "l1"
point_b = [0.0, 1.0, 0.0]
distance = 2.23606797749979"#;

const LINE: &str = r#"[[model.closures]]
name = "guide"
kind = "line"
body_a = "l2"
point_a = [1.0, 0.0, 0.0]
body_b = "world"
point_b = [0.0, 0.0, 0.0]
axis = [1.0, 0.0, 0.0]"#;

#[test]
fn the_maximal_examples_load_match_the_schema_and_use_every_key() {
    let s = json_schema();
    let v = validator();
    let examples = [
        MAXIMAL_TREE,
        MAXIMAL_LAGRANGIAN,
        MAXIMAL_LAGRANGIAN_DIAGONAL,
        MAXIMAL_URDF,
        MAXIMAL_MJCF,
        &maximal_closure(WELD),
        &maximal_closure(DISTANCE),
        &maximal_closure(LINE),
        // `[[actuators]]` with every key (servo-constraints): a joint, a direction.
        include_str!("../references/scenes/two_car_chain.toml"),
        include_str!("../references/scenes/thruster_cars.toml"),
        // a `rolling` closure (radius, normal, a disk's axis)
        include_str!("../references/scenes/rolling_disk.toml"),
    ];
    for text in examples {
        Scene::from_text(Path::new("maximal"), text).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(errors(&v, text), Vec::<String>::new());
    }
    let parsed: Vec<toml::Value> = examples
        .iter()
        .map(|t| toml::from_str(t).unwrap())
        .collect();
    let mut unused = vec![];
    for (path, keys) in tables(&s) {
        for k in keys {
            if !parsed
                .iter()
                .any(|v| tables_at(v, &path).iter().any(|t| t.contains_key(&k)))
            {
                unused.push(format!("{path}.{k}"));
            }
        }
    }
    assert!(
        unused.is_empty(),
        "keys no maximal example uses: {unused:?}"
    );
}

// ---------------------------------------------------------------------------------------------
// FORMAT.md against the schema.

/// The key tables of FORMAT.md: for each `<!-- keys: PATH... -->` marker, the backticked names
/// in the first column of the table that follows it (blank lines and a generated-table marker
/// between allowed), for each
/// path the marker names (union over the markers of one path).
fn format_md_tables(page: &str) -> BTreeMap<String, BTreeSet<String>> {
    let mut out: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut lines = page.lines().peekable();
    while let Some(line) = lines.next() {
        let Some(paths) = line
            .trim()
            .strip_prefix("<!-- keys:")
            .and_then(|r| r.strip_suffix("-->"))
        else {
            continue;
        };
        let paths = match paths.trim() {
            TOP => vec![TOP],
            p => p.split_whitespace().collect(),
        };
        // blank lines, and a `<!-- generated: ... -->` marker, between
        while lines
            .next_if(|l| l.trim().is_empty() || l.starts_with("<!-- generated:"))
            .is_some()
        {}
        let mut keys = BTreeSet::new();
        let mut rows = 0;
        while let Some(row) = lines.next_if(|l| l.starts_with('|')) {
            rows += 1;
            let first = row.split('|').nth(1).unwrap_or("").trim();
            if rows <= 2 {
                continue; // header and separator
            }
            let key = first.trim_matches('`');
            assert!(
                first.starts_with('`') && first.ends_with('`') && !key.contains('`'),
                "FORMAT.md, table {paths:?}: first column `{first}` is not one backticked key"
            );
            keys.insert(key.to_string());
        }
        assert!(
            rows > 2,
            "FORMAT.md: no table after the marker of {paths:?}"
        );
        for p in paths {
            out.entry(p.to_string())
                .or_default()
                .extend(keys.iter().cloned());
        }
    }
    out
}

#[test]
fn format_md_documents_exactly_the_schema_keys() {
    let page = std::fs::read_to_string(root().join("src/scene/FORMAT.md")).unwrap();
    let documented = format_md_tables(&page);
    let schema = tables(&json_schema());
    let mut problems = vec![];
    for (path, keys) in &schema {
        match documented.get(path) {
            None => problems.push(format!("table `{path}` has no key table in FORMAT.md")),
            Some(doc) => {
                for k in keys.difference(doc) {
                    problems.push(format!(
                        "`{path}`: `{k}` is in the schema, not in FORMAT.md"
                    ));
                }
                for k in doc.difference(keys) {
                    problems.push(format!(
                        "`{path}`: `{k}` is in FORMAT.md, not in the schema"
                    ));
                }
            }
        }
    }
    for path in documented.keys().filter(|p| !schema.contains_key(*p)) {
        problems.push(format!(
            "FORMAT.md documents table `{path}`, which the schema lacks"
        ));
    }
    assert!(problems.is_empty(), "\n{}", problems.join("\n"));
}

/// The FORMAT.md check can fail: a key the page leaves out and a key the schema lacks are found.
#[test]
fn the_format_md_check_finds_missing_and_extra_keys() {
    let page =
        "<!-- keys: time -->\n| key | meaning |\n|--|--|\n| `t1` | end |\n| `t2` | no such key |\n";
    let doc = format_md_tables(page);
    let schema = &tables(&json_schema())["time"];
    assert_eq!(
        schema.difference(&doc["time"]).cloned().collect::<Vec<_>>(),
        ["max_samples", "output_dt", "t0"]
    );
    assert_eq!(
        doc["time"].difference(schema).cloned().collect::<Vec<_>>(),
        ["t2"]
    );
}

/// Uses every field a tree scene can have (it loads; it is not meant to be solved).
const MAXIMAL_TREE: &str = r#"
name = "maximal_tree"
description = "Every field of a tree scene."
purpose = "Keeps the schema and the loader in step."

[parameters]
a = 0.5
b = "2*a"

[model]
kind = "tree"
gravity = [0.0, 0.0, -9.81]
forces = { q1 = "-0.1*q1'" }
attractors = [{ point = [0.0, 0.0, -10.0], mu = 1.0 }]
point_forces = [{ body = "upper", point = [0.0, 0.0, -0.5], force = ["0", "0", "-0.1*t"] }]

[[model.bodies]]
name = "upper"
parent = "world"
pos = [0.0, 0.0, 0.0]
quat = [1.0, 0.0, 0.0, 0.0]
mass = 1.0
com = [0.0, 0.0, -0.5]
inertia = [0.01, 0.01, 0.01, 0.0, 0.0, 0.0]
joints = [{ name = "q1", type = "hinge", axis = [0.0, 1.0, 0.0], anchor = [0.0, 0.0, 0.0], stiffness = 1.0, spring_ref = 0.1, damping = 0.05, armature = 0.01 }]
gravcomp = 0.5
shape = { capsule = [0.05, 1.0], pos = [0.0, 0.0, -0.5], quat = [1.0, 0.0, 0.0, 0.0], color = [0.2, 0.2, 0.8, 1.0] }

[[model.bodies]]
name = "lower"
parent = "upper"
pos = [0.0, 0.0, -1.0]
mass = 1.0
com = [0.0, 0.0, -0.5]
inertia = [0.01, 0.01, 0.01]
joints = [{ name = "j", type = "ball" }]
shape = { cylinder = [0.05, 1.0] }

[[model.bodies]]
name = "bob"
parent = "lower"
pos = [0.0, 0.0, -1.0]
mass = 0.1
shape = { sphere = 0.05 }

[[model.bodies]]
name = "plate"
parent = "lower"
pos = [0.0, 0.0, -1.0]
mass = 0.1
inertia = [0.001, 0.001, 0.001]
shape = { box = [0.1, 0.1, 0.01] }

[[model.sites]]
name = "tip"
body = "lower"
pos = [0.0, 0.0, -1.0]

[[constraints]]
name = "no_spin"
expr = "j.wz"

[[programme]]
name = "reach"
expr = "tip.x - a*sin(t)"

[initial]
q = { q1 = 0.1, j = [1.0, 0.0, 0.0, 0.0] }
v = { q1 = 0.0, j = [0.0, 0.0, 0.0] }
assemble = true

[time]
t0 = 0.0
t1 = 1.0
output_dt = 0.1
max_samples = 1000

[solver]
formulation = "kkt"
integrator = "rk4"
step = 0.01
rtol = 1e-8
atol = 1e-10
max_step = 0.1
drift = "baumgarte"
projection_tol = 1e-12
baumgarte_alpha = 2.0
baumgarte_beta = 1.0
max_drift = 1e-3
strict = false
richardson = false
max_steps = 1000000

[tolerances]
programme_residual = { value = 1e-6, reason = "Baumgarte keeps the drift small, not zero" }

[checks]
not_checked = { pinocchio = "an example of a declared not_checked" }

[[view.targets]]
name = "reach"
kind = "path"
path = ["a*sin(t)", "0", "-2"]
samples = 50
color = [1.0, 0.0, 1.0, 0.8]

[[view.targets]]
kind = "line"
point = [0.0, 0.0, "-b"]
direction = [1.0, 0.0, 0.0]
size = 2.0

[[view.targets]]
kind = "plane"
point = [0.0, 0.0, -2.5]
normal = [0.0, 0.0, 1.0]

[[view.targets]]
kind = "circle"
point = [0.0, 0.0, -2.0]
normal = [0.0, 0.0, 1.0]
radius = "a"

[[view.targets]]
kind = "point"
point = [0.5, 0.0, -2.0]
"#;

/// Every field of a lagrangian scene with a full mass matrix.
const MAXIMAL_LAGRANGIAN: &str = r#"
name = "maximal_lagrangian"
description = "Every field of a lagrangian scene."
purpose = "Keeps the schema and the loader in step."

[parameters]
m = 1.0

[model]
kind = "lagrangian"
coordinates = ["x", "y"]
mass_matrix = [["m", "0"], ["0", "m*(1 + x^2)"]]
potential = "0.5*(x^2 + y^2)"
forces = { x = "-0.1*x'" }

[[constraints]]
name = "c"
expr = "y' - 0.1"

[[programme]]
name = "p"
expr = "x - 0.1*sin(t)"

[initial]
q = { x = 0.0, y = 0.0 }
v = { x = 0.1, y = 0.1 }

[time]
t1 = 1.0

[[reference]]
t = "0.5*m"
source = "the programme and the constraint solved by hand"
q = { x = "0.1*sin(t)", y = 0.05 }
v = { y = 0.1 }
u = { y = 0.0 }
"#;

/// A lagrangian scene with a diagonal mass matrix.
const MAXIMAL_LAGRANGIAN_DIAGONAL: &str = r#"
name = "maximal_lagrangian_diagonal"

[model]
kind = "lagrangian"
coordinates = ["x", "y"]
mass_diagonal = ["1", "2"]

[[programme]]
name = "p"
expr = "x - 0.1*sin(t)"

[initial]
q = { x = 0.0, y = 0.0 }

[time]
t1 = 1.0
"#;

/// Every key of a urdf scene (the robot of tests/urdf_import.rs; paths relative to the crate).
const MAXIMAL_URDF: &str = r#"
name = "maximal_urdf"
description = "Every key of a urdf model."

[model]
kind = "urdf"
file = "tests/robots/two_link.urdf"
root_joint = "free"
locked_joints = ["slide"]
gravity = [0.0, 0.0, -9.81]
ignore = { joint_limit = "the motion stays inside the ranges", effort_limit = "u is compared with the file's limits by hand", mimic = "the slide, which follows the elbow, is welded alone" }

[[model.frames]]
name = "tip"
parent = "tool"
pos = [0.0, 0.0, 0.1]
quat = [1.0, 0.0, 0.0, 0.0]

[initial]

[time]
t1 = 1.0
"#;

/// What only an `mjcf` model takes: `[initial] keyframe`.
const MAXIMAL_MJCF: &str = r#"
name = "maximal_mjcf"
description = "An mjcf model started from a keyframe of its file."

[model]
kind = "mjcf"
file = "tests/robots/mjcf/two_link.xml"
gravity = [0.0, 0.0, -9.81]

[initial]
keyframe = "home"
q = { slide = 0.0 }

[time]
t1 = 1.0
"#;

// ---------------------------------------------------------------------------------------------
// FORMAT.md's "Default budgets" table against the check's vocabulary (`progmo::check`).

const BUDGETS_MARKER: &str = "<!-- generated: progmo::check::default_budget_table -->";

/// FORMAT.md with the table after `BUDGETS_MARKER` replaced by `table` (None: no marker).
fn with_budget_table(page: &str, table: &str) -> Option<String> {
    with_table_after(page, BUDGETS_MARKER, table)
}

/// `page` with the Markdown table right after the line `marker` replaced by `table`.
fn with_table_after(page: &str, marker: &str, table: &str) -> Option<String> {
    let at = page.find(marker)? + marker.len() + 1;
    let rest = &page[at..];
    let len: usize = rest
        .split_inclusive('\n')
        .take_while(|l| l.starts_with('|'))
        .map(str::len)
        .sum();
    Some(format!("{}{table}{}", &page[..at], &rest[len..]))
}

/// FORMAT.md with the table after `marker` as `generated` (written with PROGMO_BLESS, else
/// compared); returns the page as read. `source` names what the table is generated from.
fn format_md_table_is_generated(marker: &str, generated: &str, source: &str) -> String {
    let path = root().join("src/scene/FORMAT.md");
    let page = std::fs::read_to_string(&path).unwrap();
    let want = with_table_after(&page, marker, generated)
        .unwrap_or_else(|| panic!("FORMAT.md lacks the marker {marker}"));
    if std::env::var_os("PROGMO_BLESS").is_some() {
        std::fs::write(&path, &want).unwrap();
        return want;
    }
    assert!(
        page == want,
        "FORMAT.md's table after {marker} differs from {source}; regenerate it with \
         `PROGMO_BLESS=1 cargo test --release --test integration schema::` and commit it"
    );
    page
}

#[test]
fn format_md_default_budgets_are_the_cores() {
    let generated = progmo::check::default_budget_table();
    let page = format_md_table_is_generated(BUDGETS_MARKER, &generated, "progmo::check::METRICS");
    // Every metric is in the table, and the table holds nothing else (a negative control of the
    // comparison: a table missing a row is not the generated one).
    for m in &progmo::check::METRICS {
        assert!(generated.contains(&format!("| `{}`", m.name)), "{}", m.name);
    }
    let short = generated.lines().take(3).collect::<Vec<_>>().join("\n") + "\n";
    assert_ne!(with_budget_table(&page, &short).unwrap(), page);
}

const SETTINGS_MARKER: &str = "<!-- generated: progmo::solve::settings_table(\"solver\") -->";

/// FORMAT.md's `[solver]` key table is generated from the one definition of the settings
/// (`progmo::solve::Overrides`' fields and doc comments).
#[test]
fn format_md_solver_keys_are_the_settings() {
    let generated = progmo::solve::settings_table("solver");
    format_md_table_is_generated(SETTINGS_MARKER, &generated, "progmo::solve::Overrides");
}

/// One name per setting at every door: the settings of the one definition
/// (`progmo::solve::settings`) are exactly the scene file's keys that set them (`[solver]`, `[time]`
/// but its origin t0, `[initial] assemble`) and `progmo solve`'s setting flags; the Python keyword
/// arguments are checked against the same list by tests/python/test_settings.py.
#[test]
fn every_door_takes_the_same_setting_names() {
    let names: BTreeSet<String> = progmo::solve::settings()
        .iter()
        .map(|s| s.name.clone())
        .collect();
    let s = json_schema();
    let keys = |def: &str| -> BTreeSet<String> {
        s["$defs"][def]["properties"]
            .as_object()
            .unwrap()
            .keys()
            .cloned()
            .collect()
    };
    let mut file: BTreeSet<String> = keys("solver");
    file.extend(keys("time").into_iter().filter(|k| k != "t0"));
    file.extend(keys("initial").into_iter().filter(|k| k == "assemble"));
    assert_eq!(file, names, "scene file keys vs progmo::solve::settings()");
    // the run's own options (where to write, what to print) are not settings
    let own = ["out", "no-mcap", "quiet", "json", "help"];
    let flags: BTreeSet<String> = progmo::cli::solve_flags()
        .into_iter()
        .filter(|f| !own.contains(&f.as_str()))
        .map(|f| f.replace('-', "_"))
        .collect();
    assert_eq!(
        flags, names,
        "progmo solve flags vs progmo::solve::settings()"
    );
    // the numeric [solver] settings a sweep may vary are the schema's numeric [solver] keys
    let numeric: BTreeSet<&str> = s["$defs"]["solver"]["properties"]
        .as_object()
        .unwrap()
        .iter()
        .filter(|(_, v)| v["type"] == "number")
        .map(|(k, _)| k.as_str())
        .collect();
    assert!(
        numeric.contains("rtol") && numeric.contains("max_step"),
        "{numeric:?}"
    );
}

/// The rows of the table after `marker` in FORMAT.md: (first cell, second cell).
fn table_after(page: &str, marker: &str) -> Vec<(String, String)> {
    let mut lines = page
        .lines()
        .skip_while(|l| l.trim() != marker)
        .skip(1)
        .skip_while(|l| l.trim().is_empty());
    let mut rows = vec![];
    for (k, row) in lines
        .by_ref()
        .take_while(|l| l.starts_with('|'))
        .enumerate()
    {
        if k < 2 {
            continue; // header and separator
        }
        let cells: Vec<&str> = row.split('|').map(str::trim).collect();
        rows.push((cells[1].to_string(), cells[2].to_string()));
    }
    assert!(!rows.is_empty(), "FORMAT.md: no table after `{marker}`");
    rows
}

/// FORMAT.md's robot-file tables and the closed vocabulary of unmodelled kinds
/// (`progmo::import::unmodelled::KINDS`) are in step: the kinds table lists exactly its kinds;
/// the URDF and MJCF tables give every row one of the four statuses, name only kinds of the
/// vocabulary, and together use every kind. Negative control: a page missing a kind is caught.
#[test]
fn format_md_robot_tables_use_the_closed_vocabulary() {
    use progmo::import::unmodelled::KINDS;
    let page = std::fs::read_to_string(root().join("src/scene/FORMAT.md")).unwrap();
    let check = |page: &str| -> Result<(), String> {
        let vocab: BTreeSet<&str> = KINDS.iter().map(|k| k.0).collect();
        let listed: BTreeSet<String> = table_after(page, "<!-- unmodelled kinds -->")
            .into_iter()
            .map(|(k, _)| k.trim_matches('`').to_string())
            .collect();
        let listed: BTreeSet<&str> = listed.iter().map(|s| s.as_str()).collect();
        if listed != vocab {
            return Err(format!("kinds table {listed:?} vs KINDS {vocab:?}"));
        }
        let mut used = BTreeSet::new();
        for fmt in ["urdf", "mjcf"] {
            for (what, status) in table_after(page, &format!("<!-- robot elements: {fmt} -->")) {
                if let Some(rest) = status.strip_prefix("ignorable (`") {
                    let kind = rest.trim_end_matches("`)");
                    if !vocab.contains(kind) {
                        return Err(format!("{fmt}: {what}: `{kind}` is not a kind"));
                    }
                    used.insert(kind.to_string());
                } else if !["modelled", "refused", "not read"]
                    .iter()
                    .any(|s| status.starts_with(s))
                {
                    return Err(format!("{fmt}: {what}: status `{status}`"));
                }
            }
        }
        let unused: Vec<_> = vocab.iter().filter(|k| !used.contains(**k)).collect();
        if !unused.is_empty() {
            return Err(format!("kinds no element table uses: {unused:?}"));
        }
        Ok(())
    };
    check(&page).unwrap_or_else(|e| panic!("FORMAT.md: {e}"));
    let without = page.replace(
        "| `mimic` | URDF `<mimic>`: a joint that follows another (modelled as a system row unless declared ignored: the joints are then independent). |\n",
        "",
    );
    assert!(check(&without).is_err(), "a missing kind went unnoticed");
    let wrong = page.replace("ignorable (`mimic`)", "ignorable (`mimics`)");
    assert!(check(&wrong).is_err(), "an unknown kind went unnoticed");
}
