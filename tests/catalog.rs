//! The catalog (`references/scenes/`) and the format's machine-readable description
//! (`src/scene/scene.schema.json`):
//! - the schema allows every key (and value type / enumerated value) every bundled scene uses;
//! - the schema and the loader's serde structs list the same fields, table by table: maximal
//!   example scenes use every schema property and load, and probing each closed table with an
//!   unknown key makes the loader list its accepted fields, which must equal the schema's;
//! - the new catalog scenes reproduce what their `purpose` claims (exact solutions, invariants).

use progmo::scene::Scene;
use serde_json::Value as Json;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use toml::Value as Toml;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn schema() -> Json {
    let text = std::fs::read_to_string(root().join("src/scene/scene.schema.json")).unwrap();
    serde_json::from_str(&text).expect("scene.schema.json is JSON")
}

fn catalog() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(root().join("references/scenes"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    v.sort();
    v
}

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

fn type_ok(ty: &str, v: &Toml) -> bool {
    match ty {
        "object" => v.is_table(),
        "array" => v.is_array(),
        "string" => v.is_str(),
        "number" => v.is_float() || v.is_integer(),
        "integer" => v.is_integer(),
        "boolean" => v.is_bool(),
        _ => false,
    }
}

/// Check a TOML value against a schema node: keys (properties / additionalProperties), types,
/// enums, array items, and `oneOf` alternatives. Errors are pushed with their path.
fn check(root: &Json, node: &Json, v: &Toml, path: &str, errors: &mut Vec<String>) {
    let node = resolve(root, node);
    if let Some(alts) = node.get("oneOf").and_then(|a| a.as_array()) {
        if node.get("type").is_none() && node.get("properties").is_none() {
            let ok = alts.iter().any(|a| {
                let mut e = vec![];
                check(root, a, v, path, &mut e);
                e.is_empty()
            });
            if !ok {
                errors.push(format!("{path}: matches none of the alternatives"));
            }
            return;
        }
    }
    match node.get("type") {
        Some(Json::String(t)) if !type_ok(t, v) => {
            errors.push(format!("{path}: expected {t}, got {}", v.type_str()));
            return;
        }
        Some(Json::Array(ts)) if !ts.iter().any(|t| type_ok(t.as_str().unwrap(), v)) => {
            errors.push(format!(
                "{path}: expected one of {ts:?}, got {}",
                v.type_str()
            ));
            return;
        }
        _ => {}
    }
    if let (Some(Json::Array(allowed)), Some(s)) = (node.get("enum"), v.as_str()) {
        if !allowed.iter().any(|a| a.as_str() == Some(s)) {
            errors.push(format!("{path}: `{s}` is not one of {allowed:?}"));
        }
    }
    match v {
        Toml::Table(t) => {
            let props = node.get("properties").and_then(|p| p.as_object());
            for (k, x) in t {
                let sub = format!("{path}.{k}");
                match (
                    props.and_then(|p| p.get(k)),
                    node.get("additionalProperties"),
                ) {
                    (Some(s), _) => check(root, s, x, &sub, errors),
                    (None, Some(Json::Bool(false))) => {
                        errors.push(format!("{sub}: key not allowed by the schema"))
                    }
                    (None, Some(s)) if s.is_object() => check(root, s, x, &sub, errors),
                    (None, _) => {}
                }
            }
            if let Some(Json::Array(req)) = node.get("required") {
                for r in req {
                    if !t.contains_key(r.as_str().unwrap()) {
                        errors.push(format!("{path}: required key `{r}` missing"));
                    }
                }
            }
        }
        Toml::Array(a) => {
            if let Some(items) = node.get("items") {
                for (i, x) in a.iter().enumerate() {
                    check(root, items, x, &format!("{path}[{i}]"), errors);
                }
            }
        }
        _ => {}
    }
}

#[test]
fn the_schema_allows_every_bundled_scene() {
    let s = schema();
    assert_eq!(
        s["$schema"], "https://json-schema.org/draft/2020-12/schema",
        "draft 2020-12"
    );
    let mut errors = vec![];
    for f in catalog() {
        let v: Toml = toml::from_str(&std::fs::read_to_string(&f).unwrap()).unwrap();
        let name = f.file_name().unwrap().to_string_lossy().to_string();
        check(&s, &s, &v, &name, &mut errors);
    }
    assert!(errors.is_empty(), "\n{}", errors.join("\n"));
}

/// The checker itself must be able to fail.
#[test]
fn the_schema_check_rejects_unknown_keys_and_bad_values() {
    let s = schema();
    let mut v: Toml = toml::from_str(MAXIMAL_TREE).unwrap();
    let mut errors = vec![];
    check(&s, &s, &v, "maximal_tree", &mut errors);
    assert!(errors.is_empty(), "{errors:?}");
    v["model"]["bodies"][0]
        .as_table_mut()
        .unwrap()
        .insert("colour".into(), Toml::String("red".into()));
    v["solver"]
        .as_table_mut()
        .unwrap()
        .insert("integrator".into(), Toml::String("euler".into()));
    check(&s, &s, &v, "maximal_tree", &mut errors);
    assert_eq!(errors.len(), 2, "{errors:?}");
}

/// Tables the schema closes (additionalProperties: false), as TOML paths into a scene: a
/// segment `[]` means "every element", `*` "every value of a map". With their properties.
fn closed_tables(root: &Json) -> BTreeMap<String, BTreeSet<String>> {
    fn walk(root: &Json, node: &Json, path: &str, out: &mut BTreeMap<String, BTreeSet<String>>) {
        let node = resolve(root, node);
        if let Some(items) = node.get("items") {
            walk(root, items, &format!("{path}[]"), out);
        }
        if let Some(Json::Object(p)) = node.get("properties") {
            if node.get("additionalProperties") == Some(&Json::Bool(false)) {
                out.insert(path.to_string(), p.keys().cloned().collect());
            }
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
    walk(root, root, "", &mut out);
    out
}

/// The sub-tables of `v` at a closed-table path (first element of arrays, first map entry).
fn tables_at<'a>(v: &'a mut Toml, path: &str) -> Option<&'a mut toml::Table> {
    let mut cur = v;
    if !path.is_empty() {
        for seg in path.split('.') {
            let (key, arrays) = (seg.trim_end_matches("[]"), seg.matches("[]").count());
            cur = if key == "*" {
                cur.as_table_mut()?.iter_mut().next()?.1
            } else {
                cur.as_table_mut()?.get_mut(key)?
            };
            for _ in 0..arrays {
                cur = cur.as_array_mut()?.first_mut()?;
            }
        }
    }
    cur.as_table_mut()
}

/// Field names the loader lists when it meets an unknown key (serde's `deny_unknown_fields`).
fn loader_fields(message: &str) -> BTreeSet<String> {
    let list = message
        .split_once("expected")
        .unwrap_or_else(|| panic!("no field list in `{message}`"))
        .1;
    list.split('`')
        .skip(1)
        .step_by(2)
        .map(|s| s.to_string())
        .collect()
}

#[test]
fn schema_properties_and_loader_fields_agree_table_by_table() {
    let s = schema();
    let closed = closed_tables(&s);
    for must in [
        "",
        "model",
        "model.bodies[]",
        "model.bodies[].joints[]",
        "model.sites[]",
        "model.point_forces[]",
        "model.attractors[]",
        "programme[]",
        "constraints[]",
        "initial",
        "time",
        "solver",
        "tolerances.*",
        "checks",
    ] {
        assert!(closed.contains_key(must), "schema does not close `{must}`");
    }
    let examples = [
        ("maximal_tree", MAXIMAL_TREE),
        ("maximal_lagrangian", MAXIMAL_LAGRANGIAN),
        ("maximal_lagrangian_diagonal", MAXIMAL_LAGRANGIAN_DIAGONAL),
    ];
    // 1. The maximal examples load (the loader accepts every field they use) ...
    for (name, text) in examples {
        Scene::from_text(Path::new(name), text).unwrap_or_else(|e| panic!("{e}"));
    }
    // ... and together use every property of every closed table of the schema.
    let mut unused = vec![];
    for (path, props) in &closed {
        for p in props {
            let used = examples.iter().any(|(_, text)| {
                let mut v: Toml = toml::from_str(text).unwrap();
                tables_at(&mut v, path).is_some_and(|t| t.contains_key(p))
            });
            if !used {
                unused.push(format!("{path}.{p}"));
            }
        }
    }
    assert!(
        unused.is_empty(),
        "schema properties no maximal example uses: {unused:?}"
    );
    // 2. Probing each closed table with an unknown key: the loader's field list is the schema's.
    let mut mismatches = vec![];
    for (path, props) in &closed {
        let mut probed = false;
        for (name, text) in examples {
            let mut v: Toml = toml::from_str(text).unwrap();
            let Some(t) = tables_at(&mut v, path) else {
                continue;
            };
            t.insert("zz_probe".into(), Toml::Integer(1));
            let probe_text = toml::to_string(&v).unwrap();
            let e = match Scene::from_text(Path::new(name), &probe_text) {
                Ok(_) => panic!("{name}: `{path}.zz_probe` accepted by the loader"),
                Err(e) => e,
            };
            assert!(
                e.message.contains("unknown field `zz_probe`"),
                "{name} {path}: {e}"
            );
            let fields = loader_fields(&e.message);
            if &fields != props {
                mismatches.push(format!("`{path}`: loader {fields:?}, schema {props:?}"));
            }
            probed = true;
            break;
        }
        assert!(probed, "no maximal example has `{path}`");
    }
    assert!(mismatches.is_empty(), "\n{}", mismatches.join("\n"));
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
joints = [{ name = "q1", type = "hinge", axis = [0.0, 1.0, 0.0], anchor = [0.0, 0.0, 0.0], stiffness = 1.0, spring_ref = 0.1, damping = 0.05 }]

[[model.bodies]]
name = "lower"
parent = "upper"
pos = [0.0, 0.0, -1.0]
mass = 1.0
com = [0.0, 0.0, -0.5]
inertia = [0.01, 0.01, 0.01]
joints = [{ name = "j", type = "ball" }]

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

[tolerances]
programme_residual = { value = 1e-6, reason = "Baumgarte keeps the drift small, not zero" }

[checks]
not_checked = { pinocchio = "an example of a declared not_checked" }
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

// ---------------------------------------------------------------------------------------------
// What the new catalog scenes claim.

fn load(name: &str) -> Scene {
    Scene::load(root().join(format!("references/scenes/{name}.toml")))
        .unwrap_or_else(|e| panic!("{e}"))
}

fn param(s: &Scene, name: &str) -> f64 {
    s.parameters.iter().find(|p| p.0 == name).unwrap().1
}

#[test]
fn every_catalog_scene_says_what_it_checks() {
    for f in catalog() {
        let s = Scene::load(&f).unwrap_or_else(|e| panic!("{e}"));
        assert!(!s.description.trim().is_empty(), "{}: description", s.name);
        assert!(!s.purpose.trim().is_empty(), "{}: purpose", s.name);
        assert_eq!(
            Some(s.name.as_str()),
            f.file_stem().and_then(|x| x.to_str()),
            "scene name = file name"
        );
        let t = s.tolerances.iter().find(|t| t.name == "programme_residual");
        assert!(t.is_some_and(|t| !t.reason.trim().is_empty()), "{}", s.name);
    }
}

/// Knife edge (Chaplygin sleigh with prescribed heading): theta = omega t, forward speed
/// v = V + b omega^2 t, lateral force F = m v omega, steering torque tau = b m v omega, and the
/// contact point on the closed-form spiral of the scene's purpose.
#[test]
fn knife_edge_matches_the_closed_form() {
    let s = load("knife_edge");
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let (v0, w, m, b) = (
        param(&s, "V"),
        param(&s, "omega"),
        param(&s, "m"),
        param(&s, "b"),
    );
    let tr = &sol.trajectory;
    let mut worst: f64 = 0.0;
    for k in 0..tr.len() {
        let t = tr.t[k];
        let (q, v, u) = (tr.q_at(k), tr.v_at(k), tr.u_at(k));
        let (c, sn) = ((w * t).cos(), (w * t).sin());
        let speed = v0 + b * w * w * t;
        let x = v0 * sn / w + b * (w * t * sn + c - 1.0);
        let y = v0 * (1.0 - c) / w + b * (sn - w * t * c);
        let f = m * speed * w;
        worst = worst
            .max((q[0] - x).abs())
            .max((q[1] - y).abs())
            .max((q[2] - w * t).abs())
            .max((v[0].hypot(v[1]) - speed).abs())
            .max((u[0] + f * sn).abs())
            .max((u[1] - f * c).abs())
            .max((u[2] - b * f).abs());
    }
    assert!(worst < 1e-7, "knife edge off the closed form by {worst:e}");
}

/// Appell-Hamel: fixed horizontal direction, s(t) = s0 - g a t / (1 + a^2), z' = a s.
#[test]
fn appell_hamel_matches_the_closed_form() {
    let s = load("appell_hamel");
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let (a, vx0, vy0) = (param(&s, "a"), param(&s, "vx0"), param(&s, "vy0"));
    let (s0, g) = (vx0.hypot(vy0), 9.81);
    let tr = &sol.trajectory;
    let mut worst: f64 = 0.0;
    for k in 0..tr.len() {
        let t = tr.t[k];
        let v = tr.v_at(k);
        let sh = s0 - g * a * t / (1.0 + a * a);
        worst = worst
            .max((v[0].hypot(v[1]) - sh).abs())
            .max((v[0] * vy0 - v[1] * vx0).abs())
            .max((v[2] - a * sh).abs());
    }
    assert!(
        worst < 1e-8,
        "Appell-Hamel off the closed form by {worst:e}"
    );
}

/// Slider crank: phi1 = Omega t, the loop stays closed, and the slider position follows from the
/// closure, x3 = L1 cos(phi1) + sqrt(L2^2 - L1^2 sin^2(phi1)).
#[test]
fn slider_crank_follows_its_kinematics() {
    let s = load("slider_crank");
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let (l1, l2, om) = (param(&s, "L1"), param(&s, "L2"), param(&s, "Omega"));
    let tr = &sol.trajectory;
    let mut worst: f64 = 0.0;
    for k in 0..tr.len() {
        let q = tr.q_at(k);
        let p1 = om * tr.t[k];
        let x3 = l1 * p1.cos() + (l2 * l2 - (l1 * p1.sin()).powi(2)).sqrt();
        worst = worst.max((q[0] - p1).abs()).max((q[2] - x3).abs());
    }
    assert!(worst < 1e-9, "slider crank kinematics off by {worst:e}");
    assert_eq!(tr.t.last().copied(), Some(0.1));
    // Power balance: the closure reactions do no work, so the drive's control force alone
    // changes the kinetic energy: u . v = dT/dt = v^T A a + 1/2 v^T (dA/dt) v.
    let (m2, m3, j1, j2) = (
        param(&s, "M2"),
        param(&s, "M3"),
        param(&s, "J1"),
        param(&s, "J2"),
    );
    let c = 0.5 * l1 * l2 * m2;
    let (mut worst, mut scale): (f64, f64) = (0.0, 0.0);
    for k in 0..tr.len() {
        let (q, v, a, u) = (tr.q_at(k), tr.v_at(k), tr.a_at(k), tr.u_at(k));
        let d = q[0] - q[1];
        let am = [
            [j1 + m2 * l1 * l1, c * d.cos(), 0.0],
            [c * d.cos(), j2, 0.0],
            [0.0, 0.0, m3],
        ];
        let mut va = 0.0;
        for i in 0..3 {
            for j in 0..3 {
                va += v[i] * am[i][j] * a[j];
            }
        }
        let adot12 = -c * d.sin() * (v[0] - v[1]);
        let dt = va + adot12 * v[0] * v[1];
        let power: f64 = u.iter().zip(v).map(|(x, y)| x * y).sum();
        let reaction_power: f64 = tr.reactions_at(k).iter().zip(v).map(|(x, y)| x * y).sum();
        worst = worst.max((power - dt).abs()).max(reaction_power.abs());
        scale = scale.max(dt.abs());
    }
    assert!(scale > 1.0, "the drive does work");
    assert!(
        worst < 1e-8 * scale,
        "power balance off by {worst:e} (scale {scale:e})"
    );
}

/// Planar arm: the tip stays on its line and moves at speed V; the self-motion is free.
#[test]
fn planar_arm_tip_moves_along_its_line() {
    let s = load("planar_arm_line");
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let (l, v0, z0) = (param(&s, "l"), param(&s, "V"), param(&s, "z0"));
    let tr = &sol.trajectory;
    let tip = |q: &[f64]| {
        let (mut x, mut z, mut a) = (0.0, 0.0, 0.0);
        for qi in q {
            a += qi;
            x += l * f64::cos(a);
            z += l * f64::sin(a);
        }
        (x, z)
    };
    let x0 = tip(tr.q_at(0)).0;
    let mut worst: f64 = 0.0;
    for k in 0..tr.len() {
        let (x, z) = tip(tr.q_at(k));
        worst = worst.max((z - z0).abs()).max((x - x0 - v0 * tr.t[k]).abs());
    }
    assert!(worst < 1e-9, "tip off its line by {worst:e}");
}

/// The annotated example of FORMAT.md loads and solves within its tolerance (the page cannot
/// drift from the loader unnoticed).
#[test]
fn the_annotated_example_of_format_md_solves() {
    let page = std::fs::read_to_string(root().join("src/scene/FORMAT.md")).unwrap();
    let section = page
        .split_once("## A complete annotated example")
        .expect("section")
        .1;
    let block = section
        .split_once("```toml\n")
        .unwrap()
        .1
        .split_once("```")
        .unwrap()
        .0;
    let s = Scene::from_text(Path::new("FORMAT.md"), block).unwrap_or_else(|e| panic!("{e}"));
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let worst = sol.max_residual.iter().cloned().fold(0.0, f64::max);
    assert!(worst <= s.tolerance("programme_residual").unwrap());
    let mut errors = vec![];
    let sch = schema();
    check(
        &sch,
        &sch,
        &toml::from_str(block).unwrap(),
        "FORMAT.md",
        &mut errors,
    );
    assert!(errors.is_empty(), "{errors:?}");
}
