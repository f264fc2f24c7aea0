//! The scene file's JSON Schema, generated from the types of [`super::file`] (their doc comments
//! are the descriptions). The committed copy is `scene.schema.json` beside this file; regenerate
//! it with `PROGMO_BLESS=1 cargo test --test integration schema::` (the test fails while the copy differs).

use super::file::{
    SceneFile, CLOSURE_KINDS, JOINTS_WITH_AXIS, JOINT_TYPES, LAGRANGIAN_ONLY, MODEL_KINDS,
    ROOT_JOINTS, SIMULATORS, TARGET_KINDS, TREE_ONLY, URDF_ONLY,
};
use schemars::transform::{RecursiveTransform, RestrictFormats};
use schemars::{json_schema, JsonSchema, Schema, SchemaGenerator};
use serde_json::{json, Value};

/// `$id` of the schema (a name, not a place to fetch it from).
pub const SCHEMA_ID: &str = "https://progmo.invalid/scene.schema.json";

/// Names of coordinates, joints' sites, rows and parameters (the loader's `is_identifier`).
pub const IDENTIFIER_PATTERN: &str = "^[A-Za-z_][A-Za-z0-9_]*$";

/// An expression over t, q, v (x'), accelerations (x''), site signals and parameters; grammar in
/// src/expr/mod.rs.
#[derive(JsonSchema)]
#[schemars(rename = "expression")]
pub struct Expression(#[schemars(length(min = 1))] pub String);

/// An identifier: [A-Za-z_][A-Za-z0-9_]*.
#[derive(JsonSchema)]
#[schemars(rename = "identifier")]
pub struct Identifier(#[schemars(regex(pattern = IDENTIFIER_PATTERN))] pub String);

/// The schema of a scene file, as committed in `scene.schema.json`.
pub fn json_schema() -> Value {
    let generator = schemars::generate::SchemaSettings::draft2020_12()
        .with_transform(RecursiveTransform(tidy))
        .with_transform(RestrictFormats::default())
        .into_generator();
    let mut schema = generator.into_root_schema_for::<SceneFile>();
    schema.insert("$id".into(), SCHEMA_ID.into());
    schema.to_value()
}

/// TOML has no null: an optional key is absent, never null. Drops the null alternative and the
/// null default schemars gives `Option<T>`; joins the lines of doc comments.
fn tidy(s: &mut Schema) {
    let Some(obj) = s.as_object_mut() else {
        return;
    };
    if obj.get("default").is_some_and(Value::is_null) {
        obj.remove("default");
    }
    if let Some(Value::String(d)) = obj.get_mut("description") {
        *d = d.replace('\n', " ");
    }
    if let Some(Value::Array(types)) = obj.get_mut("type") {
        types.retain(|t| t != "null");
        if types.len() == 1 {
            let t = types.remove(0);
            obj.insert("type".into(), t);
        }
    }
    if let Some(Value::Array(alts)) = obj.get_mut("anyOf") {
        alts.retain(|a| a.get("type").is_none_or(|t| t != "null"));
        if alts.len() == 1 {
            let Some(Value::Object(only)) = obj.remove("anyOf").map(|mut a| a[0].take()) else {
                unreachable!("anyOf alternatives are schemas");
            };
            obj.extend(only);
        }
    }
}

/// `[model] ignore`: keys from the closed vocabulary of unmodelled kinds, non-empty reasons.
pub(super) fn ignore_kinds(_: &mut SchemaGenerator) -> Schema {
    let kinds: Vec<&str> = crate::import::unmodelled::KINDS
        .iter()
        .map(|k| k.0)
        .collect();
    json_schema!({
        "type": "object",
        "propertyNames": { "enum": kinds },
        "additionalProperties": { "type": "string", "minLength": 1, "pattern": "\\S" },
        "default": {}
    })
}

fn string_enum(names: &[&str]) -> Schema {
    json_schema!({ "type": "string", "enum": names })
}

/// `kind` of a closure.
pub(super) fn closure_kind(_: &mut SchemaGenerator) -> Schema {
    string_enum(&CLOSURE_KINDS)
}

/// `model.kind`.
pub(super) fn model_kind(_: &mut SchemaGenerator) -> Schema {
    string_enum(&MODEL_KINDS)
}

/// `type` of a joint.
/// `root_joint` of a urdf model.
pub(super) fn root_joint(_: &mut SchemaGenerator) -> Schema {
    string_enum(&ROOT_JOINTS)
}

/// `type` of a joint.
pub(super) fn joint_type(_: &mut SchemaGenerator) -> Schema {
    string_enum(&JOINT_TYPES)
}

/// `kind` of a view target.
pub(super) fn target_kind(_: &mut SchemaGenerator) -> Schema {
    string_enum(&TARGET_KINDS)
}

/// `[solver]`: the settings of [`crate::solve::Overrides`] whose table is `solver` (their names,
/// types, ranges, defaults and doc comments: the one definition of the settings).
pub struct SolverTable;

impl JsonSchema for SolverTable {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "solver".into()
    }

    fn json_schema(_: &mut SchemaGenerator) -> Schema {
        let full = schemars::SchemaGenerator::default()
            .into_root_schema_for::<crate::solve::Overrides>()
            .to_value();
        let mut props = serde_json::Map::new();
        for (name, p) in full["properties"].as_object().into_iter().flatten() {
            if p["x-table"] == "solver" {
                let mut p = p.clone();
                if let Some(o) = p.as_object_mut() {
                    o.remove("x-table");
                }
                props.insert(name.clone(), p);
            }
        }
        json_schema!({
            "type": "object",
            "description": "Solver settings; every key optional, defaults those of `Settings::default()`.",
            "properties": props,
            "additionalProperties": false,
        })
    }
}

/// `[parameters]` keys: identifiers other than `t` and `pi`.
pub(super) fn parameter_names(s: &mut Schema) {
    s.insert(
        "propertyNames".into(),
        json!({ "pattern": IDENTIFIER_PATTERN, "not": { "enum": ["t", "pi"] } }),
    );
}

/// `[checks] not_checked`: keys are simulators, values non-empty reasons.
pub(super) fn simulator_names(s: &mut Schema) {
    s.insert("propertyNames".into(), json!({ "enum": SIMULATORS }));
    s.insert(
        "additionalProperties".into(),
        json!({ "type": "string", "minLength": 1 }),
    );
}

/// `[tolerances]`: the check's budgets and options (`crate::check::tolerance_keys`).
pub(super) fn tolerance_names(s: &mut Schema) {
    s.insert(
        "propertyNames".into(),
        json!({ "enum": crate::check::tolerance_keys() }),
    );
}

/// `inertia`: 3 principal moments or 6 entries.
pub(super) fn inertia_lengths(s: &mut Schema) {
    s.insert(
        "oneOf".into(),
        json!([{ "minItems": 3, "maxItems": 3 }, { "minItems": 6, "maxItems": 6 }]),
    );
}

/// Keys named by a rule must be properties of the table (a misspelt rule would constrain
/// nothing).
fn assert_properties(s: &Schema, keys: &[&str]) {
    for k in keys {
        assert!(
            s.get("properties").and_then(|p| p.get(k)).is_some(),
            "schema rule names `{k}`, not a property"
        );
    }
}

fn required_any(keys: &[&str]) -> Value {
    json!({ "anyOf": keys.iter().map(|k| json!({ "required": [k] })).collect::<Vec<_>>() })
}

/// `[model]`: a lagrangian model has coordinates and one of mass_matrix / mass_diagonal and none
/// of the tree keys; a tree model has bodies and none of the lagrangian keys (the loader's
/// checks, `load.rs`).
pub(super) fn model_kind_rules(s: &mut Schema) {
    assert_properties(s, &LAGRANGIAN_ONLY);
    assert_properties(s, &TREE_ONLY);
    assert_properties(s, &URDF_ONLY);
    let [lagrangian, tree, urdf, mjcf] = MODEL_KINDS;
    s.insert(
        "allOf".into(),
        json!([
            {
                "if": { "properties": { "kind": { "const": lagrangian } } },
                "then": {
                    "required": ["coordinates"],
                    "oneOf": [{ "required": ["mass_matrix"] }, { "required": ["mass_diagonal"] }],
                    "not": required_any(&[&TREE_ONLY[..], &URDF_ONLY[..]].concat()),
                }
            },
            {
                "if": { "properties": { "kind": { "const": tree } } },
                "then": {
                    "required": ["bodies"],
                    "not": required_any(&[&LAGRANGIAN_ONLY[..], &URDF_ONLY[..]].concat())
                }
            },
            {
                "if": { "properties": { "kind": { "const": urdf } } },
                "then": {
                    "required": ["file"],
                    "not": required_any(&[&LAGRANGIAN_ONLY[..], &["bodies"][..]].concat())
                }
            },
            {
                "if": { "properties": { "kind": { "const": mjcf } } },
                "then": {
                    "required": ["file"],
                    "not": required_any(&[&LAGRANGIAN_ONLY[..], &["bodies", "root_joint"][..]].concat())
                }
            }
        ]),
    );
}

/// A joint: hinge and slide joints need an axis.
pub(super) fn joint_axis_rule(s: &mut Schema) {
    assert_properties(s, &["type", "axis"]);
    s.insert(
        "allOf".into(),
        json!([{
            "if": { "properties": { "type": { "enum": JOINTS_WITH_AXIS } } },
            "then": { "required": ["axis"] }
        }]),
    );
}
