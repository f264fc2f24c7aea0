//! What the 3D view of a tree scene draws besides the mechanism (drawn by
//! [`crate::output::Bodies`]): bodies' `shape`, `[[view.targets]]` and the sites the programme
//! rows read (their realized traces).

use super::error::{SceneError, Source};
use super::file::{Number, SceneFile, ShapeFile, TargetFile, TARGET_KINDS};
use super::load::{number, span};
use super::signals::Quantity;
use super::SceneSystem;
use crate::expr::{self, Expr, SymbolTable};
use crate::output::{
    Geometry, Shape, Target, TracedSite, View, ViewTarget, SHAPE_COLOR, TARGET_COLOR,
};
use std::ops::Range;
use toml::Spanned;

type R<T> = Result<T, SceneError>;

/// The view of a loaded scene (lagrangian scenes have none: targets there are refused).
pub(super) fn view(
    src: &Source,
    file: &SceneFile,
    params: &[(String, f64)],
    system: &SceneSystem,
) -> R<View> {
    let tree = match system {
        SceneSystem::Tree(p) => p.model.tree(),
        SceneSystem::Lagrangian(_) => {
            return match file.view.targets.first() {
                Some(t) => Err(src.error(
                    t.span(),
                    "view.targets[0]",
                    "view targets are drawn with a tree model's bodies; a lagrangian model has none",
                )),
                None => Ok(View::default()),
            };
        }
    };
    let mut consts = SymbolTable::new();
    for (n, x) in params {
        consts.define(n.clone(), *x);
    }
    let model = file.model.get_ref();
    let mut shapes = vec![None; tree.bodies().len()];
    for (bi, b) in model.bodies.iter().enumerate() {
        let bf = b.get_ref();
        if let (Some(s), Some(i)) = (&bf.shape, tree.body_id(&bf.name)) {
            let com = tree.bodies()[i].com;
            shapes[i] = Some(shape(
                src,
                s,
                &format!("model.bodies[{bi}].shape"),
                [com[0], com[1], com[2]],
            )?);
        }
    }
    let mut targets = vec![];
    for (k, t) in file.view.targets.iter().enumerate() {
        let field = format!("view.targets[{k}]");
        let name = t
            .get_ref()
            .name
            .clone()
            .unwrap_or_else(|| format!("target{k}"));
        if targets.iter().any(|x: &ViewTarget| x.name == name) {
            return Err(src.error(
                t.span(),
                &format!("{field}.name"),
                format!("target name `{name}` is used twice"),
            ));
        }
        targets.push(target(src, t, &field, name, &consts, span(file))?);
    }
    // Sites the programme rows read (`site.component` signals), in order of first use.
    let mut traced: Vec<TracedSite> = vec![];
    for row in &file.programme {
        for n in expr::referenced_names(row.expr.get_ref()).unwrap_or_default() {
            let Some((site, comp)) = n.rsplit_once('.') else {
                continue;
            };
            if Quantity::parse(comp).is_none() || traced.iter().any(|s| s.name == site) {
                continue;
            }
            let sf = model
                .sites
                .iter()
                .map(|s| s.get_ref())
                .find(|s| s.name == site);
            if let Some((sf, body)) = sf.and_then(|s| tree.body_id(&s.body).map(|b| (s, b))) {
                traced.push(TracedSite {
                    name: sf.name.clone(),
                    body,
                    pos: sf.pos,
                });
            }
        }
    }
    Ok(View {
        shapes,
        targets,
        traced,
    })
}

fn positive(src: &Source, span: Range<usize>, field: &str, what: &str, x: f64) -> R<f64> {
    if x > 0.0 && x.is_finite() {
        Ok(x)
    } else {
        Err(src.error(span, field, format!("{what} must be positive, got {x}")))
    }
}

fn color(
    src: &Source,
    c: &Option<Spanned<[f64; 4]>>,
    field: &str,
    default: [f64; 4],
) -> R<[f64; 4]> {
    match c {
        None => Ok(default),
        Some(c) if c.get_ref().iter().all(|x| (0.0..=1.0).contains(x)) => Ok(*c.get_ref()),
        Some(c) => Err(src.error(
            c.span(),
            &format!("{field}.color"),
            format!(
                "colour components must lie in [0, 1], got {:?}",
                c.get_ref()
            ),
        )),
    }
}

fn shape(src: &Source, s: &Spanned<ShapeFile>, field: &str, com: [f64; 3]) -> R<Shape> {
    let sf = s.get_ref();
    let given = [
        sf.cuboid.is_some(),
        sf.sphere.is_some(),
        sf.cylinder.is_some(),
        sf.capsule.is_some(),
    ];
    if given.iter().filter(|&&g| g).count() != 1 {
        return Err(src.error(
            s.span(),
            field,
            "a shape needs exactly one of box, sphere, cylinder, capsule",
        ));
    }
    let geometry = if let Some(d) = &sf.cuboid {
        for x in d.get_ref() {
            positive(src, d.span(), &format!("{field}.box"), "a box side", *x)?;
        }
        Geometry::Box(*d.get_ref())
    } else if let Some(r) = &sf.sphere {
        Geometry::Sphere(positive(
            src,
            r.span(),
            &format!("{field}.sphere"),
            "the radius",
            *r.get_ref(),
        )?)
    } else {
        let (key, v) = match (&sf.cylinder, &sf.capsule) {
            (Some(v), _) => ("cylinder", v),
            (_, Some(v)) => ("capsule", v),
            _ => unreachable!("one geometry was given"),
        };
        let f = format!("{field}.{key}");
        let [r, l] = *v.get_ref();
        let r = positive(src, v.span(), &f, "the radius", r)?;
        let l = positive(src, v.span(), &f, "the length", l)?;
        if key == "cylinder" {
            Geometry::Cylinder(r, l)
        } else {
            Geometry::Capsule(r, l)
        }
    };
    let quaternion = match &sf.quat {
        None => [1.0, 0.0, 0.0, 0.0],
        Some(q) => {
            let n = q.get_ref().iter().map(|x| x * x).sum::<f64>().sqrt();
            if !(n > 0.0 && n.is_finite()) {
                return Err(src.error(
                    q.span(),
                    &format!("{field}.quat"),
                    "the quaternion must be non-zero",
                ));
            }
            q.get_ref().map(|x| x / n)
        }
    };
    Ok(Shape {
        geometry,
        position: sf.pos.unwrap_or(com),
        quaternion,
        color: color(src, &sf.color, field, SHAPE_COLOR)?,
    })
}

#[allow(clippy::too_many_lines)] // over 100 lines before the lint: to split, not to grow
fn target(
    src: &Source,
    t: &Spanned<TargetFile>,
    field: &str,
    name: String,
    consts: &SymbolTable,
    (t0, t1): (f64, f64),
) -> R<ViewTarget> {
    let tf = t.get_ref();
    let kind = tf.kind.get_ref().as_str();
    if !TARGET_KINDS.contains(&kind) {
        return Err(src.error(
            tf.kind.span(),
            &format!("{field}.kind"),
            format!(
                "unknown target kind `{kind}`: expected one of {}",
                TARGET_KINDS.join(", ")
            ),
        ));
    }
    // Which keys each kind reads; any other given key is refused (it would be silently ignored).
    let (needs, allows): (&[&str], &[&str]) = match kind {
        "point" => (&["point"], &[]),
        "line" => (&["point", "direction"], &["size"]),
        "plane" => (&["point", "normal"], &["size"]),
        "circle" => (&["point", "normal", "radius"], &[]),
        _ => (&["path"], &["samples"]),
    };
    let sp = |x: Option<Range<usize>>| x.unwrap_or_else(|| t.span());
    let present = [
        ("point", tf.point.as_ref().map(|x| x.span())),
        ("direction", tf.direction.as_ref().map(|x| x.span())),
        ("normal", tf.normal.as_ref().map(|x| x.span())),
        ("radius", tf.radius.as_ref().map(|x| x.span())),
        ("size", tf.size.as_ref().map(|x| x.span())),
        ("path", tf.path.as_ref().map(|x| x[0].span())),
        ("samples", tf.samples.as_ref().map(|x| x.span())),
    ];
    for (key, given) in present {
        if given.is_some() && !needs.contains(&key) && !allows.contains(&key) {
            return Err(src.error(
                sp(given),
                &format!("{field}.{key}"),
                format!("a {kind} target has no `{key}`"),
            ));
        }
        if given.is_none() && needs.contains(&key) {
            return Err(src.error(t.span(), field, format!("a {kind} target needs `{key}`")));
        }
    }
    let vec3 = |v: &Option<Spanned<[Number; 3]>>, key: &str| -> R<[f64; 3]> {
        let v = v.as_ref().expect("checked above");
        let f = format!("{field}.{key}");
        let mut out = [0.0; 3];
        for (o, n) in out.iter_mut().zip(v.get_ref()) {
            *o = number(src, consts, n, v.span(), &f)?;
        }
        if key != "point" && out.iter().map(|x| x * x).sum::<f64>() == 0.0 {
            return Err(src.error(v.span(), &f, format!("the {key} must be non-zero")));
        }
        Ok(out)
    };
    let scalar = |v: &Option<Spanned<Number>>, key: &str| -> R<Option<f64>> {
        match v {
            None => Ok(None),
            Some(v) => {
                let f = format!("{field}.{key}");
                let x = number(src, consts, v.get_ref(), v.span(), &f)?;
                positive(src, v.span(), &f, &format!("the {key}"), x).map(Some)
            }
        }
    };
    let target = match kind {
        "point" => Target::Point(vec3(&tf.point, "point")?),
        "line" => Target::Line(
            vec3(&tf.point, "point")?,
            vec3(&tf.direction, "direction")?,
            scalar(&tf.size, "size")?,
        ),
        "plane" => Target::Plane(
            vec3(&tf.point, "point")?,
            vec3(&tf.normal, "normal")?,
            scalar(&tf.size, "size")?,
        ),
        "circle" => Target::Circle(
            vec3(&tf.point, "point")?,
            vec3(&tf.normal, "normal")?,
            scalar(&tf.radius, "radius")?.expect("checked above"),
        ),
        _ => {
            let n = match &tf.samples {
                None => 200,
                Some(s) if *s.get_ref() >= 2 && *s.get_ref() <= 100_000 => *s.get_ref() as usize,
                Some(s) => {
                    return Err(src.error(
                        s.span(),
                        &format!("{field}.samples"),
                        format!("samples must be between 2 and 100000, got {}", s.get_ref()),
                    ))
                }
            };
            let mut table = consts.clone();
            table.insert("t");
            let mut exprs = vec![];
            for (k, e) in tf.path.as_ref().expect("checked above").iter().enumerate() {
                let f = format!("{field}.path[{k}]");
                exprs.push(
                    Expr::compile(e.get_ref(), &table)
                        .map_err(|err| src.expr_error(e.span(), &f, &err))?,
                );
            }
            let mut pts = Vec::with_capacity(n);
            for i in 0..n {
                let t = t0 + (t1 - t0) * i as f64 / (n - 1) as f64;
                let p = [
                    exprs[0].value(&[t]),
                    exprs[1].value(&[t]),
                    exprs[2].value(&[t]),
                ];
                if let Some(k) = p.iter().position(|x| !x.is_finite()) {
                    let e = &tf.path.as_ref().expect("checked above")[k];
                    return Err(src.error(
                        e.span(),
                        &format!("{field}.path[{k}]"),
                        format!("evaluates to {} at t = {t}", p[k]),
                    ));
                }
                pts.push(p);
            }
            Target::Path(pts)
        }
    };
    Ok(ViewTarget {
        name,
        target,
        color: color(src, &tf.color, field, TARGET_COLOR)?,
    })
}
