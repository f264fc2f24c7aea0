//! The scene file as written (TOML), before validation. The reference page is `FORMAT.md` beside
//! this file and the JSON Schema is `scene.schema.json`; a test keeps the three in step.

use serde::de::{self, Deserializer, SeqAccess, Visitor};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::fmt;
use toml::Spanned;

/// A number or an expression in the parameters (`"2*pi"`, `"sqrt(mu/r0)"`).
#[derive(Clone, Debug)]
pub enum Number {
    Value(f64),
    Expr(String),
}

/// One joint coordinate's initial value: a number/expression, or several for ball and free joints.
#[derive(Clone, Debug)]
pub enum Initial {
    One(Number),
    Many(Vec<Number>),
}

// By hand rather than `#[serde(untagged)]`, so that a wrong type (`q1 = true`) says what was
// expected instead of "did not match any variant".
struct NumberVisitor;

impl<'de> Visitor<'de> for NumberVisitor {
    type Value = Number;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a number or an expression string")
    }
    fn visit_f64<E: de::Error>(self, x: f64) -> Result<Number, E> {
        Ok(Number::Value(x))
    }
    fn visit_i64<E: de::Error>(self, x: i64) -> Result<Number, E> {
        Ok(Number::Value(x as f64))
    }
    fn visit_u64<E: de::Error>(self, x: u64) -> Result<Number, E> {
        Ok(Number::Value(x as f64))
    }
    fn visit_str<E: de::Error>(self, s: &str) -> Result<Number, E> {
        Ok(Number::Expr(s.to_string()))
    }
}

impl<'de> Deserialize<'de> for Number {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(NumberVisitor)
    }
}

struct InitialVisitor;

impl<'de> Visitor<'de> for InitialVisitor {
    type Value = Initial;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a number, an expression string, or an array of them")
    }
    fn visit_f64<E: de::Error>(self, x: f64) -> Result<Initial, E> {
        Ok(Initial::One(Number::Value(x)))
    }
    fn visit_i64<E: de::Error>(self, x: i64) -> Result<Initial, E> {
        Ok(Initial::One(Number::Value(x as f64)))
    }
    fn visit_u64<E: de::Error>(self, x: u64) -> Result<Initial, E> {
        Ok(Initial::One(Number::Value(x as f64)))
    }
    fn visit_str<E: de::Error>(self, s: &str) -> Result<Initial, E> {
        Ok(Initial::One(Number::Expr(s.to_string())))
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Initial, A::Error> {
        let mut v = Vec::new();
        while let Some(n) = seq.next_element::<Number>()? {
            v.push(n);
        }
        Ok(Initial::Many(v))
    }
}

impl<'de> Deserialize<'de> for Initial {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(InitialVisitor)
    }
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// Why this scene is in the catalog (what it tests).
    #[serde(default)]
    pub purpose: String,
    #[serde(default)]
    pub parameters: BTreeMap<String, Spanned<Number>>,
    pub model: Spanned<ModelFile>,
    #[serde(default)]
    pub constraints: Vec<RowFile>,
    #[serde(default)]
    pub programme: Vec<RowFile>,
    pub initial: Spanned<InitialFile>,
    pub time: Spanned<TimeFile>,
    #[serde(default)]
    pub solver: SolverFile,
    #[serde(default)]
    pub tolerances: BTreeMap<String, Spanned<ToleranceFile>>,
    #[serde(default)]
    pub checks: ChecksFile,
}

/// How the cross-simulator check treats the scene.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChecksFile {
    /// Simulators the scene is declared not to be checked in (`mujoco`, `pinocchio`), each with the
    /// reason: an expected `not_checked` does not fail a run.
    #[serde(default)]
    pub not_checked: BTreeMap<String, Spanned<String>>,
}

/// One row of a full mass matrix as written: expressions with their places.
pub type SpannedRow = Spanned<Vec<Spanned<String>>>;

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelFile {
    /// "lagrangian" or "tree".
    pub kind: Spanned<String>,
    // lagrangian
    #[serde(default)]
    pub coordinates: Vec<Spanned<String>>,
    #[serde(default)]
    pub mass_matrix: Option<Spanned<Vec<SpannedRow>>>,
    #[serde(default)]
    pub mass_diagonal: Option<Spanned<Vec<Spanned<String>>>>,
    #[serde(default)]
    pub potential: Option<Spanned<String>>,
    #[serde(default)]
    pub forces: BTreeMap<String, Spanned<String>>,
    // tree
    #[serde(default)]
    pub gravity: Option<[f64; 3]>,
    #[serde(default)]
    pub bodies: Vec<Spanned<BodyFile>>,
    #[serde(default)]
    pub sites: Vec<Spanned<SiteFile>>,
    #[serde(default)]
    pub attractors: Vec<Spanned<AttractorFile>>,
    #[serde(default)]
    pub point_forces: Vec<Spanned<PointForceFile>>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodyFile {
    pub name: String,
    #[serde(default = "world")]
    pub parent: String,
    /// Placement in the parent frame (default 0); spanned so that a bad value is located at itself.
    #[serde(default)]
    pub pos: Option<Spanned<[f64; 3]>>,
    /// Orientation (w, x, y, z) in the parent frame (default identity).
    #[serde(default)]
    pub quat: Option<Spanned<[f64; 4]>>,
    pub mass: Spanned<f64>,
    #[serde(default)]
    pub com: [f64; 3],
    /// Principal moments [ixx, iyy, izz] or the full [ixx, iyy, izz, ixy, ixz, iyz] about the CoM.
    #[serde(default)]
    pub inertia: Option<Spanned<Vec<f64>>>,
    #[serde(default)]
    pub joints: Vec<Spanned<JointFile>>,
}

fn world() -> String {
    "world".to_string()
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointFile {
    pub name: String,
    /// "hinge", "slide", "ball" or "free".
    #[serde(rename = "type")]
    pub kind: Spanned<String>,
    #[serde(default)]
    pub axis: Option<Spanned<[f64; 3]>>,
    #[serde(default)]
    pub anchor: [f64; 3],
    #[serde(default)]
    pub stiffness: f64,
    #[serde(default)]
    pub spring_ref: f64,
    #[serde(default)]
    pub damping: f64,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SiteFile {
    pub name: String,
    pub body: String,
    #[serde(default)]
    pub pos: [f64; 3],
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AttractorFile {
    #[serde(default)]
    pub point: [f64; 3],
    pub mu: f64,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointForceFile {
    pub body: String,
    #[serde(default)]
    pub point: [f64; 3],
    /// World-frame force components as expressions.
    pub force: [Spanned<String>; 3],
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RowFile {
    pub name: Spanned<String>,
    pub expr: Spanned<String>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InitialFile {
    #[serde(default)]
    pub q: BTreeMap<String, Spanned<Initial>>,
    #[serde(default)]
    pub v: BTreeMap<String, Spanned<Initial>>,
    /// Project an inconsistent initial state onto the constraints instead of refusing it.
    #[serde(default)]
    pub assemble: bool,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeFile {
    #[serde(default)]
    pub t0: Option<Spanned<f64>>,
    pub t1: Spanned<f64>,
    /// Output sample spacing; absent: one sample per accepted step.
    #[serde(default)]
    pub output_dt: Option<Spanned<f64>>,
    /// Most output samples a run may write (default `solve::DEFAULT_MAX_SAMPLES`).
    #[serde(default)]
    pub max_samples: Option<Spanned<i64>>,
}

#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolverFile {
    pub formulation: Option<Spanned<String>>,
    pub integrator: Option<Spanned<String>>,
    /// Fixed step of rk4.
    pub step: Option<Spanned<f64>>,
    pub rtol: Option<Spanned<f64>>,
    pub atol: Option<Spanned<f64>>,
    pub max_step: Option<Spanned<f64>>,
    /// "projection", "baumgarte" or "none".
    pub drift: Option<Spanned<String>>,
    pub projection_tol: Option<Spanned<f64>>,
    pub baumgarte_alpha: Option<Spanned<f64>>,
    pub baumgarte_beta: Option<Spanned<f64>>,
    pub max_drift: Option<Spanned<f64>>,
    /// Stop at the first conditioning warning.
    pub strict: Option<bool>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ToleranceFile {
    pub value: f64,
    pub reason: String,
}
