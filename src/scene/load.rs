//! From the TOML file to a validated [`Scene`].

use super::closures::{Closure, ClosureRows, SetAside};
use super::error::{SceneError, Source};
use super::file::*;
use super::lagrangian::LagrangianModel;
use super::layout::Layout;
use super::rows::ExprConstraints;
use super::signals::{Signals, Site};
use super::tree_model::{PointForce, TreeSceneModel};
use super::{Scene, SceneSystem, Tolerance};
use crate::check;
use crate::expr::{self, Expr, SymbolTable};
use crate::model::Model;
use crate::programme::{Constraints, Level, Role, RowSpec};
use crate::solve::{OverrideError, Overrides, Problem, Settings};
use crate::tree::{self, BodySpec, Fields, JointSpec, ModelError};
use std::collections::BTreeMap;
use std::ops::Range;
use std::sync::Arc;
use toml::Spanned;

type R<T> = Result<T, SceneError>;

/// Symbols of a scene: the slot layout, parameters as constants, signals discovered on demand.
struct Symbols {
    table: SymbolTable,
    layout: Layout,
    signals: Signals,
    /// Level of each signal slot (index k = slot - layout.signals).
    signal_levels: Vec<Level>,
    /// Why a name is no symbol (a locked joint, a link named like a joint): (name, reason), told
    /// when an expression uses it or one of its signals.
    hints: Vec<(String, String)>,
}

impl Symbols {
    /// Compile a spanned expression, creating body-point signals it names.
    fn compile(&mut self, src: &Source, s: &Spanned<String>, field: &str) -> R<Expr> {
        let text = s.get_ref();
        if let Ok(names) = expr::referenced_names(text) {
            for n in names {
                if self.table.get(&n).is_none() && self.table.constant(&n).is_none() {
                    if let Some((site, q)) = self.signals.resolve(&n) {
                        let slot = self.table.insert(n.clone());
                        let k = self.signals.push(site, q);
                        debug_assert_eq!(slot, self.layout.signals + k);
                        self.signal_levels.push(q.level());
                    }
                }
            }
        }
        Expr::compile(text, &self.table).map_err(|e| {
            let mut se = src.expr_error(s.span(), field, &e);
            if let expr::ExprErrorKind::UnknownSymbol { name, .. } = &e.kind {
                let base = name.split(['.', '\'']).next().unwrap_or("");
                if let Some((_, why)) = self.hints.iter().find(|h| h.0 == base) {
                    se.message = format!("unknown symbol `{name}`: {why}");
                }
            }
            se
        })
    }

    /// Level of the highest-level slot an expression reads (None if it reads no slot).
    fn level(&self, e: &Expr) -> Option<Level> {
        e.slots()
            .iter()
            .map(|&s| match self.layout.level(s) {
                Some(l) => l,
                None => self.signal_levels[s - self.layout.signals],
            })
            .max_by_key(|l| *l as u8)
    }

    /// First slot an expression reads outside `allowed`, by name.
    fn outside(&self, e: &Expr, allowed: &[Range<usize>]) -> Option<String> {
        e.slots()
            .iter()
            .find(|s| !allowed.iter().any(|r| r.contains(s)))
            .map(|&s| self.table.name(s).unwrap_or("?").to_string())
    }

    fn total_slots(&self) -> usize {
        self.table.len()
    }
}

pub(super) fn load(src: Source) -> R<Scene> {
    let file: SceneFile = toml::from_str(&src.text).map_err(|e| src.toml_error(&e))?;
    if file.name.trim().is_empty() {
        let message = "the scene needs a non-empty name";
        return Err(match src.key_value_span(0, "name") {
            Some(span) => src.error(span, "name", message),
            None => src.general("name", message),
        });
    }
    let settings = solver(&src, &file)?;
    validate_settings(&src, &file, &settings)?;
    let params = parameters(&src, &file.parameters)?;
    let model = file.model.get_ref();
    let kind = model.kind.get_ref().as_str();
    let (system, spans, import_notes, robot, extra) = match kind {
        "lagrangian" => {
            let (system, spans) = lagrangian_system(&src, &file, &params)?;
            (system, spans, vec![], None, (vec![], None))
        }
        "tree" | "urdf" | "mjcf" => {
            let t = tree_system(&src, &file, &params, &settings)?;
            (t.system, t.spans, t.import_notes, t.robot, t.extra)
        }
        other => {
            return Err(src.error(
                model.kind.span(),
                "model.kind",
                format!(
                    "unknown model kind `{other}`: expected `lagrangian`, `tree`, `urdf` or `mjcf`"
                ),
            ))
        }
    };
    let n_system = file.constraints.len();
    crate::with_problem!(&system, p => check_acceleration_rows(&src, p, &spans, n_system)?);
    let view = super::view::view(&src, &file, &params, &system)?;
    let tolerances = tolerances(&src, &file)?;
    let replay_step = replay_step(&src, &file)?;
    let expected_not_checked = expected_not_checked(&src, &file)?;
    let references = {
        let (q_names, v_names) =
            crate::with_problem!(&system, p => (p.model.q_names(), p.model.v_names()));
        let (t0, t1) = span(&file);
        super::reference::references(&src, &file, &params, &q_names, &v_names, (t0, t1))?
    };
    Ok(Scene {
        name: file.name.clone(),
        description: file.description.clone(),
        purpose: file.purpose.clone(),
        path: src.file.clone(),
        parameters: params,
        system,
        settings,
        tolerances,
        replay_step,
        expected_not_checked,
        references,
        source: src,
        row_spans: spans,
        closures: extra.0,
        set_aside: extra.1,
        view: Arc::new(view),
        import_notes,
        robot,
    })
}

/// The system of a `lagrangian` scene (no actuators: it realizes its programme ideally) and its
/// rows' spans.
fn lagrangian_system(
    src: &Source,
    file: &SceneFile,
    params: &[(String, f64)],
) -> R<(SceneSystem, Vec<Range<usize>>)> {
    let model = file.model.get_ref();
    if let Some(a) = file.actuators.first() {
        let (span, field) = match &a.get_ref().joint {
            Some(j) => (j.span(), "actuators[0].joint"),
            None => (a.span(), "actuators[0]"),
        };
        return Err(src.error(
            span,
            field,
            "actuators need a tree or urdf model (they act on its joints); a lagrangian \
             scene realizes its programme ideally",
        ));
    }
    let (m, mut sym) = lagrangian(src, model, params)?;
    let (c, spans) = rows(src, file, &mut sym, &[])?;
    if let Some(k) = &file.initial.get_ref().keyframe {
        return Err(src.error(k.span(), "initial.keyframe", NO_KEYFRAME));
    }
    let v_start = vec![0.0; m.v_names().len()];
    let (q0, v0) = initial(
        src,
        file,
        params,
        &m.q_names(),
        (&m.v_names(), &v_start),
        None,
    )?;
    let (t0, t1) = span(file);
    let p = Problem {
        model: m,
        constraints: c,
        t0,
        t1,
        q0,
        v0,
    };
    check_mass(src, file, &p)?;
    check_finite_at_start(src, file, &p)?;
    Ok((SceneSystem::Lagrangian(p), spans))
}

/// A tree (`tree`, `urdf`, `mjcf`) scene's system with what comes with it.
struct TreeSystem {
    system: SceneSystem,
    spans: Vec<Range<usize>>,
    import_notes: Vec<String>,
    robot: Option<super::RobotFile>,
    extra: (Vec<Closure>, SetAsideRows),
}

/// The system of a tree scene: the tree, its closures (dependent rows set aside) and actuators.
fn tree_system(
    src: &Source,
    file: &SceneFile,
    params: &[(String, f64)],
    settings: &Settings,
) -> R<TreeSystem> {
    let model = file.model.get_ref();
    let (m, mut sym, (notes, rf), (closures, closure_rows)) = tree_scene(src, model, params)?;
    let (c, mut spans) = rows(src, file, &mut sym, &closure_rows)?;
    let (start, v_start) = keyframe(src, file, m.tree(), rf.as_ref())?;
    let (q0, v0) = initial(
        src,
        file,
        params,
        &m.q_names(),
        (&m.v_names(), &v_start),
        Some((m.tree(), start.as_slice())),
    )?;
    let (t0, t1) = span(file);
    let mut p = Problem {
        model: m,
        constraints: c,
        t0,
        t1,
        q0,
        v0,
    };
    check_mass(src, file, &p)?;
    check_finite_at_start(src, file, &p)?;
    let set_aside = closure_rows_kept(src, file, &mut p, &mut spans, closure_rows.len(), settings)?;
    super::actuators::load(src, file, params, &mut p, !closures.is_empty())?;
    Ok(TreeSystem {
        system: SceneSystem::Tree(p),
        spans,
        import_notes: notes,
        robot: rf,
        extra: (closures, set_aside),
    })
}

type SetAsideRows = Option<(Vec<SetAside>, ExprConstraints)>;

/// Set aside the closure rows dependent at t0 ([`super::closures::set_aside_dependent`]), then
/// check the number of rows left. The set-aside rows must hold at t0 too; they stay available
/// (as constraints of their own) for monitoring.
fn closure_rows_kept<M: Model>(
    src: &Source,
    file: &SceneFile,
    p: &mut Problem<M, ExprConstraints>,
    spans: &mut Vec<Range<usize>>,
    n_closure: usize,
    settings: &Settings,
) -> R<SetAsideRows> {
    if n_closure == 0 {
        return Ok(None);
    }
    let nc = file.constraints.len();
    let aside = super::closures::set_aside_dependent(p, nc..nc + n_closure, &settings.rank());
    let s = p.constraints.rows().len();
    let drop: Vec<usize> = aside.iter().map(|(i, _)| *i).collect();
    let keep: Vec<usize> = (0..s).filter(|i| !drop.contains(i)).collect();
    let (kept, removed) = p.constraints.split(&keep, &drop);
    // The set-aside rows must hold at the initial state like every other row.
    let mut ws = removed.workspace::<f64>();
    let mut g = vec![0.0; drop.len()];
    let zero = vec![0.0; p.v0.len()];
    removed.eval(&mut ws, p.t0, &p.q0, &p.v0, &zero, &mut g);
    for (k, &i) in drop.iter().enumerate() {
        if !(g[k].abs() <= settings.consistency_tol) {
            return Err(src.error(
                spans[i].clone(),
                &format!("row {}", removed.rows()[k].name),
                format!(
                    "closure row `{}` is set aside as dependent at t0 but the initial state                      violates it by {:.3e}: the loop is not assembled",
                    removed.rows()[k].name,
                    g[k]
                ),
            ));
        }
    }
    let nv = p.model.nv();
    if keep.len() > nv {
        let first = keep[nv];
        return Err(src.error(
            spans[first].clone(),
            &format!("row {}", p.constraints.rows()[first].name),
            format!(
                "too many independent rows: {} (constraints, closures and programme) for {nv}                  degrees of freedom",
                keep.len()
            ),
        ));
    }
    let report = aside
        .into_iter()
        .map(|(i, reason)| SetAside {
            row: p.constraints.rows()[i].name.clone(),
            reason,
        })
        .collect();
    *spans = keep.iter().map(|&i| spans[i].clone()).collect();
    p.constraints = kept;
    Ok(Some((report, removed)))
}

/// Evaluate parameters (numbers or expressions of other parameters) in dependency order.
fn parameters(src: &Source, p: &BTreeMap<String, Spanned<Number>>) -> R<Vec<(String, f64)>> {
    let mut done: Vec<(String, f64)> = vec![];
    let mut table = SymbolTable::new();
    for name in p.keys() {
        if !is_identifier(name) || name == "t" || name == "pi" {
            let s = &p[name];
            return Err(src.error(
                s.span(),
                &format!("parameters.{name}"),
                "a parameter name must be an identifier other than `t` and `pi`",
            ));
        }
    }
    let mut pending: Vec<&String> = p.keys().collect();
    while !pending.is_empty() {
        let mut progress = false;
        let mut still = vec![];
        for name in pending {
            let s = &p[name];
            let value = match s.get_ref() {
                Number::Value(x) => Some(*x),
                Number::Expr(text) => match Expr::compile(text, &table) {
                    Ok(e) => Some(e.value::<f64>(&[])),
                    Err(_) => None,
                },
            };
            match value {
                Some(x) => {
                    if !x.is_finite() {
                        return Err(src.error(
                            s.span(),
                            &format!("parameters.{name}"),
                            format!("evaluates to {x}"),
                        ));
                    }
                    table.define(name.clone(), x);
                    done.push((name.clone(), x));
                    progress = true;
                }
                None => still.push(name),
            }
        }
        if !progress {
            // A parameter that fails on its own (not waiting for a pending one) reports its error;
            // if every pending one waits for another, they form a cycle.
            let waits = |name: &String| -> Vec<&String> {
                match p[name].get_ref() {
                    Number::Expr(text) => expr::referenced_names(text)
                        .unwrap_or_default()
                        .into_iter()
                        .filter_map(|n| still.iter().find(|s| ***s == n).copied())
                        .collect(),
                    Number::Value(_) => vec![],
                }
            };
            let name = *still
                .iter()
                .find(|n| waits(n).is_empty())
                .unwrap_or(&still[0]);
            let s = &p[name];
            if waits(name).is_empty() {
                if let Number::Expr(text) = s.get_ref() {
                    if let Err(e) = Expr::compile(text, &table) {
                        let spanned = Spanned::new(s.span(), text.clone());
                        return Err(src.expr_error(
                            spanned.span(),
                            &format!("parameters.{name}"),
                            &e,
                        ));
                    }
                }
                return Err(src.error(
                    s.span(),
                    &format!("parameters.{name}"),
                    "cannot be evaluated",
                ));
            }
            // Follow the first pending dependency until a parameter repeats.
            let mut path: Vec<&String> = vec![name];
            loop {
                let next = waits(path[path.len() - 1])[0];
                if let Some(i) = path.iter().position(|n| *n == next) {
                    let mut cycle: Vec<&str> = path[i..].iter().map(|n| n.as_str()).collect();
                    cycle.push(next);
                    let first = &p[path[i]];
                    return Err(src.error(
                        first.span(),
                        &format!("parameters.{}", path[i]),
                        format!("parameters form a cycle: {}", cycle.join(" -> ")),
                    ));
                }
                path.push(next);
            }
        }
        pending = still;
    }
    Ok(done)
}

/// Bodies reordered so that every parent precedes its children (the file may list them in any
/// order); stable otherwise. Bodies whose parent never appears stay at the end, for the tree to
/// report.
fn parents_first(specs: Vec<BodySpec>) -> Vec<BodySpec> {
    let mut placed: Vec<BodySpec> = Vec::with_capacity(specs.len());
    let mut names = std::collections::HashSet::new();
    let mut rest = specs;
    loop {
        let before = rest.len();
        let mut still = vec![];
        for b in rest {
            if b.parent == tree::WORLD || names.contains(&b.parent) {
                names.insert(b.name.clone());
                placed.push(b);
            } else {
                still.push(b);
            }
        }
        rest = still;
        if rest.is_empty() || rest.len() == before {
            placed.extend(rest);
            return placed;
        }
    }
}

/// "a, b and c".
pub(super) fn and_list(names: &[&str]) -> String {
    match names.split_last() {
        Some((last, rest)) if !rest.is_empty() => format!("{} and {last}", rest.join(", ")),
        _ => names.join(""),
    }
}

pub(super) fn is_identifier(s: &str) -> bool {
    let mut c = s.chars();
    matches!(c.next(), Some(ch) if ch.is_ascii_alphabetic() || ch == '_')
        && c.all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
}

fn symbols(q: &[String], v: &[String], params: &[(String, f64)], signals: Signals) -> Symbols {
    let mut table = SymbolTable::new();
    let layout = Layout::build(&mut table, q, v);
    for (n, x) in params {
        table.define(n.clone(), *x);
    }
    Symbols {
        table,
        layout,
        signals,
        signal_levels: vec![],
        hints: vec![],
    }
}

fn lagrangian(
    src: &Source,
    m: &ModelFile,
    params: &[(String, f64)],
) -> R<(LagrangianModel, Symbols)> {
    lagrangian_keys(src, m)?;
    let names = coordinate_names(src, m, params)?;
    let n = names.len();
    let mut sym = symbols(&names, &names, params, Signals::none());
    let mass = mass_entries(src, m, &mut sym, n)?;
    let potential = potential(src, m, &mut sym, n)?;
    let forces = lagrangian_forces(src, m, &mut sym, &names)?;
    let model = LagrangianModel::new(names, sym.layout.clone(), mass, potential, forces);
    Ok((model, sym))
}

/// A lagrangian model takes none of the tree or robot file keys, and some coordinates.
fn lagrangian_keys(src: &Source, m: &ModelFile) -> R<()> {
    if !m.bodies.is_empty()
        || !m.sites.is_empty()
        || m.gravity.is_some()
        || !m.point_forces.is_empty()
        || !m.attractors.is_empty()
        || !m.closures.is_empty()
    {
        return Err(src.error(
            m.kind.span(),
            "model",
            format!("{} belong to `tree` models", and_list(&TREE_ONLY)),
        ));
    }
    if let Some((_, r)) = m.ignore.iter().next() {
        return Err(src.error(
            r.span(),
            "model.ignore",
            "`ignore` belongs to `urdf` and `mjcf` models (it declares what of the robot file is \
             not modelled)",
        ));
    }
    if m.coordinates.is_empty() {
        return Err(src.error(
            m.kind.span(),
            "model.coordinates",
            "a lagrangian model needs coordinates",
        ));
    }
    if let Some(c) = m.coordinates.get(crate::input::MAX_COORDINATES) {
        return Err(src.error(
            c.span(),
            "model.coordinates",
            format!(
                "more than {} coordinates (the limit of coordinates of a model)",
                crate::input::MAX_COORDINATES
            ),
        ));
    }
    Ok(())
}

/// The coordinates' names: identifiers, not `t`, `pi` or a parameter, each once.
fn coordinate_names(src: &Source, m: &ModelFile, params: &[(String, f64)]) -> R<Vec<String>> {
    let mut names: Vec<String> = vec![];
    let mut seen = std::collections::HashSet::new();
    for c in &m.coordinates {
        let n = c.get_ref();
        if !is_identifier(n) || n == "t" || n == "pi" || params.iter().any(|p| &p.0 == n) {
            return Err(src.error(
                c.span(),
                "model.coordinates",
                format!("`{n}` is not a valid coordinate name (an identifier, not `t`, `pi` or a parameter)"),
            ));
        }
        if !seen.insert(n) {
            return Err(src.error(
                c.span(),
                "model.coordinates",
                format!("`{n}` appears twice"),
            ));
        }
        names.push(n.clone());
    }
    Ok(names)
}

/// The mass matrix's upper triangle (i <= j, constant-zero entries left out), from exactly one of
/// `mass_matrix` and `mass_diagonal`; its entries read the coordinates only.
fn mass_entries(
    src: &Source,
    m: &ModelFile,
    sym: &mut Symbols,
    n: usize,
) -> R<Vec<(usize, usize, Expr)>> {
    match (&m.mass_matrix, &m.mass_diagonal) {
        (Some(_), Some(_)) | (None, None) => {
            let span = m
                .mass_diagonal
                .as_ref()
                .map(|d| d.span())
                .unwrap_or(m.kind.span());
            Err(src.error(
                span,
                "model",
                "give exactly one of `mass_matrix` (n x n) and `mass_diagonal` (n entries)",
            ))
        }
        (None, Some(diag)) => mass_diagonal(src, diag, sym, n),
        (Some(full), None) => mass_matrix(src, full, sym, n),
    }
}

/// `mass_diagonal`: n entries.
fn mass_diagonal(
    src: &Source,
    diag: &Spanned<Vec<Spanned<String>>>,
    sym: &mut Symbols,
    n: usize,
) -> R<Vec<(usize, usize, Expr)>> {
    #[allow(clippy::single_range_in_vec_init)] // a list of allowed slot ranges, here one
    let q_only = [sym.layout.q..sym.layout.q + n];
    let mut mass = vec![];
    if diag.get_ref().len() != n {
        return Err(src.error(
            diag.span(),
            "model.mass_diagonal",
            format!("has {} entries for {n} coordinates", diag.get_ref().len()),
        ));
    }
    for (i, s) in diag.get_ref().iter().enumerate() {
        let field = format!("model.mass_diagonal[{i}]");
        let e = sym.compile(src, s, &field)?;
        if let Some(bad) = sym.outside(&e, &q_only) {
            return Err(src.error(
                s.span(),
                &field,
                format!("the mass matrix may depend on the coordinates only, not on `{bad}`"),
            ));
        }
        mass.push((i, i, e));
    }
    Ok(mass)
}

/// `mass_matrix`: n x n, symmetric; its upper triangle.
fn mass_matrix(
    src: &Source,
    full: &Spanned<Vec<SpannedRow>>,
    sym: &mut Symbols,
    n: usize,
) -> R<Vec<(usize, usize, Expr)>> {
    #[allow(clippy::single_range_in_vec_init)] // a list of allowed slot ranges, here one
    let q_only = [sym.layout.q..sym.layout.q + n];
    let mut mass = vec![];
    let rows = full.get_ref();
    if rows.len() != n || rows.iter().any(|r| r.get_ref().len() != n) {
        return Err(src.error(
            full.span(),
            "model.mass_matrix",
            format!("must be {n} x {n} (one row per coordinate)"),
        ));
    }
    for i in 0..n {
        for j in i..n {
            let s = &rows[i].get_ref()[j];
            let field = format!("model.mass_matrix[{i}][{j}]");
            let e = sym.compile(src, s, &field)?;
            if let Some(bad) = sym.outside(&e, &q_only) {
                return Err(src.error(
                    s.span(),
                    &field,
                    format!("the mass matrix may depend on the coordinates only, not on `{bad}`"),
                ));
            }
            // The lower triangle must be the same expression text, or agree in value at
            // a few probe points (two different texts used to pass unchecked unless both
            // were constants).
            let sl = &rows[j].get_ref()[i];
            let fl = format!("model.mass_matrix[{j}][{i}]");
            let el = sym.compile(src, sl, &fl)?;
            if el.source().trim() != e.source().trim() {
                symmetric(src, sym, (&e, &el), sl, &fl, (i, j))?;
            }
            if e.constant() != Some(0.0) {
                mass.push((i, j, e));
            }
        }
    }
    Ok(mass)
}

/// Entries [i][j] (`e`) and [j][i] (`el`, at `sl`) of two different texts agree at a few probe
/// points.
fn symmetric(
    src: &Source,
    sym: &Symbols,
    (e, el): (&Expr, &Expr),
    sl: &Spanned<String>,
    fl: &str,
    (i, j): (usize, usize),
) -> R<()> {
    for p in 0..3 {
        let probe: Vec<f64> = (0..sym.total_slots())
            .map(|k| 0.3 + 0.1 * k as f64 + 0.37 * (p * (k % 3)) as f64)
            .collect();
        let (x, y) = (e.value(&probe), el.value(&probe));
        let close = (x - y).abs() <= 1e-12 * x.abs().max(1.0); // false for NaN
        if !close {
            return Err(src.error(
                sl.span(),
                fl,
                format!("the mass matrix must be symmetric: differs from entry [{i}][{j}]"),
            ));
        }
    }
    Ok(())
}

/// `potential`: an expression of t and the coordinates.
fn potential(src: &Source, m: &ModelFile, sym: &mut Symbols, n: usize) -> R<Option<Expr>> {
    let potential = match &m.potential {
        Some(s) => {
            let e = sym.compile(src, s, "model.potential")?;
            let allowed = [
                sym.layout.t..sym.layout.t + 1,
                sym.layout.q..sym.layout.q + n,
            ];
            if let Some(bad) = sym.outside(&e, &allowed) {
                return Err(src.error(
                    s.span(),
                    "model.potential",
                    format!(
                        "the potential may depend on t and the coordinates only, not on `{bad}`"
                    ),
                ));
            }
            Some(e)
        }
        None => None,
    };
    Ok(potential)
}

/// `forces` of a lagrangian model: per coordinate, an expression of t, q and v.
fn lagrangian_forces(
    src: &Source,
    m: &ModelFile,
    sym: &mut Symbols,
    names: &[String],
) -> R<Vec<(usize, Expr)>> {
    let mut forces = vec![];
    for (name, s) in &m.forces {
        let field = format!("model.forces.{name}");
        let i = names.iter().position(|x| x == name).ok_or_else(|| {
            src.error(
                s.span(),
                &field,
                format!(
                    "`{name}` is not a coordinate{} (coordinates: {})",
                    check::did_you_mean(name, names.iter().map(String::as_str)),
                    names.join(", ")
                ),
            )
        })?;
        let e = sym.compile(src, s, &field)?;
        #[allow(clippy::single_range_in_vec_init)] // a list of allowed slot ranges, here one
        let allowed = [sym.layout.t..sym.layout.a];
        if let Some(bad) = sym.outside(&e, &allowed) {
            return Err(src.error(
                s.span(),
                &field,
                format!("a force may depend on t, q and v only, not on `{bad}`"),
            ));
        }
        forces.push((i, e));
    }
    Ok(forces)
}

/// Notes of an imported robot file and its [`RobotFile`] (None for a `tree` model).
type ImportInfo = (Vec<String>, Option<super::RobotFile>);

fn tree_scene(
    src: &Source,
    m: &ModelFile,
    params: &[(String, f64)],
) -> R<(TreeSceneModel, Symbols, ImportInfo, ClosureRows)> {
    let imported = matches!(m.kind.get_ref().as_str(), "urdf" | "mjcf");
    let (specs, joint_names, link_sites, notes, mut hints) = if imported {
        import_specs(src, m, params)?
    } else {
        let (specs, joint_names) = tree_specs(src, m, params)?;
        (specs, joint_names, vec![], (vec![], None), vec![])
    };
    let joint_names: Vec<&str> = joint_names.iter().map(|s| s.as_str()).collect();
    let joint_set: std::collections::HashSet<&str> = joint_names.iter().copied().collect();
    let body_at = notes.1.as_ref().map_or(&[][..], |r| r.body_at.as_slice());
    let tree = Arc::new(build_tree(src, m, specs, body_at)?);
    let mut sites = link_sites_of(&tree, &link_sites, &joint_set, &mut hints);
    scene_sites(src, m, &tree, &joint_set, &mut sites)?;
    let mut closures = super::closures::load(src, m, &tree, &joint_names, &mut sites)?;
    closures.1.extend(mimic_rows(m, notes.1.as_ref())); // generated system rows, like a closure's
    let q_names = tree.q_names().to_vec();
    let v_names = tree.v_names().to_vec();
    let mut sym = symbols(
        &q_names,
        &v_names,
        params,
        Signals::new(tree.clone(), sites),
    );
    sym.hints = hints;
    let point_forces = point_forces(src, m, &tree, &mut sym)?;
    let coordinate_forces = coordinate_forces(src, m, &v_names, &mut sym)?;
    let model = TreeSceneModel::new(tree, sym.layout.clone(), point_forces, coordinate_forces);
    Ok((model, sym, notes, closures))
}

/// The kinematic tree of the bodies (sorted parents first) in the model's fields, within the
/// limit of coordinates.
/// `body_at`: where a robot file writes each body's mass properties (errors of a body are
/// reported there; empty for a tree scene).
fn build_tree(
    src: &Source,
    m: &ModelFile,
    specs: Vec<BodySpec>,
    body_at: &[(String, SceneError)],
) -> R<tree::Model> {
    let fields = Fields {
        gravity: m.gravity.unwrap_or([0.0; 3]),
        attractors: m
            .attractors
            .iter()
            .map(|a| tree::Attractor {
                point: a.get_ref().point,
                mu: a.get_ref().mu,
            })
            .collect(),
    };
    let specs = parents_first(specs);
    let tree = tree::Model::new(&specs, fields).map_err(|e| match &e {
        ModelError::Body { body, msg } => match body_at.iter().find(|b| &b.0 == body) {
            Some((_, at)) => SceneError {
                message: format!("body '{body}': {msg}"),
                ..at.clone()
            },
            None => located_model_error(src, m, e),
        },
        _ => located_model_error(src, m, e),
    })?;
    if tree.nv() > crate::input::MAX_COORDINATES {
        let limit = crate::input::MAX_COORDINATES;
        let message = format!(
            "{} velocity coordinates, more than {limit} (the limit of coordinates of a model)",
            tree.nv()
        );
        // the body whose joints pass the limit (a tree scene), else the robot file
        let mut nv = 0;
        let over = m.bodies.iter().position(|b| {
            nv += b
                .get_ref()
                .joints
                .iter()
                .map(|j| match j.get_ref().kind.get_ref().as_str() {
                    "ball" => 3,
                    "free" => 6,
                    _ => 1,
                })
                .sum::<usize>();
            nv > limit
        });
        return Err(match (over, &m.file) {
            (Some(i), _) => src.error(m.bodies[i].span(), &format!("model.bodies[{i}]"), message),
            (None, Some(f)) => src.error(f.span(), "model.file", message),
            (None, None) => src.error(m.kind.span(), "model", message),
        });
    }
    Ok(tree)
}

/// A [`ModelError`] of the tree located in the scene: at the joint, the inertia, the parent or
/// name of the body it names, else the body, else the model.
fn located_model_error(src: &Source, m: &ModelFile, e: ModelError) -> SceneError {
    let (body, msg) = match &e {
        ModelError::Body { body, .. } | ModelError::Joint { body, .. } => {
            (Some(body.clone()), e.to_string())
        }
        _ => (None, e.to_string()),
    };
    let mut idx = body
        .as_ref()
        .and_then(|b| m.bodies.iter().position(|x| &x.get_ref().name == b));
    if msg.contains("duplicate body name") {
        // the second body of that name is the duplicate
        idx = body.as_ref().and_then(|b| {
            let mut same = m
                .bodies
                .iter()
                .enumerate()
                .filter(|x| &x.1.get_ref().name == b);
            same.nth(1).map(|x| x.0)
        });
    }
    // Bodies are sorted parents first here, so an unplaced parent is missing or in a cycle.
    let msg = match idx.map(|i| &m.bodies[i].get_ref().parent) {
        Some(parent) if msg.contains("unknown parent") => {
            if m.bodies.iter().any(|b| &b.get_ref().name == parent) {
                format!(
                    "the parents of body '{}' form a cycle through '{parent}'",
                    m.bodies[idx.unwrap_or(0)].get_ref().name
                )
            } else {
                format!(
                    "body '{}': unknown parent '{parent}'",
                    m.bodies[idx.unwrap_or(0)].get_ref().name
                )
            }
        }
        _ => msg,
    };
    let joint = match &e {
        ModelError::Joint { joint, .. } => idx.and_then(|i| {
            let js = &m.bodies[i].get_ref().joints;
            js.iter()
                .position(|j| &j.get_ref().name == joint)
                .map(|k| (i, k, js[k].span()))
        }),
        _ => None,
    };
    // a name or parent on a line of its own: the caret on its value
    let key = |i: usize, key: &str| src.key_value_span(m.bodies[i].span().start, key);
    match idx {
        _ if joint.is_some() => {
            let (i, k, span) = joint.expect("some");
            src.error(span, &format!("model.bodies[{i}].joints[{k}]"), msg)
        }
        // Inertia problems point at the inertia itself.
        Some(i) if msg.contains("inertia") && m.bodies[i].get_ref().inertia.is_some() => {
            let span = m.bodies[i].get_ref().inertia.as_ref().unwrap().span();
            src.error(span, &format!("model.bodies[{i}].inertia"), msg)
        }
        Some(i) if msg.contains("parent") && key(i, "parent").is_some() => src.error(
            key(i, "parent").expect("some"),
            &format!("model.bodies[{i}].parent"),
            msg,
        ),
        Some(i) if msg.contains("duplicate body name") && key(i, "name").is_some() => src.error(
            key(i, "name").expect("some"),
            &format!("model.bodies[{i}].name"),
            msg,
        ),
        Some(i) => src.error(m.bodies[i].span(), &format!("model.bodies[{i}]"), msg),
        None => src.error(m.kind.span(), "model", msg),
    }
}

/// The sites of an imported robot's links and frames; a link named like a joint is no site
/// (`hints` says why).
fn link_sites_of(
    tree: &tree::Model,
    link_sites: &[String],
    joint_set: &std::collections::HashSet<&str>,
    hints: &mut Vec<(String, String)>,
) -> Vec<Site> {
    // Imported robots: every link and frame is a site at its origin (its orientation signals are
    // the body's own), unless a joint has its name.
    for n in link_sites.iter().filter(|n| joint_set.contains(n.as_str())) {
        hints.push((
            n.clone(),
            format!(
                "link `{n}` has the name of a joint, so it is not a site (its signals would read \
                 as the joint's): add a `[[model.frames]]` of another name with parent = \"{n}\""
            ),
        ));
    }
    link_sites
        .iter()
        .filter(|n| !joint_set.contains(n.as_str()))
        .map(|n| Site {
            name: n.clone(),
            body: tree.body_id(n).expect("imported body"),
            pos: [0.0; 3],
        })
        .collect()
}

/// `[[model.sites]]` appended to `sites`: on a known body, an identifier, unique, not a joint's.
fn scene_sites(
    src: &Source,
    m: &ModelFile,
    tree: &tree::Model,
    joint_set: &std::collections::HashSet<&str>,
    sites: &mut Vec<Site>,
) -> R<()> {
    for (si, s) in m.sites.iter().enumerate() {
        let sf = s.get_ref();
        let body = tree.body_id(&sf.body).ok_or_else(|| {
            src.error(
                s.span(),
                &format!("model.sites[{si}].body"),
                format!("unknown body `{}`", sf.body),
            )
        })?;
        if !is_identifier(&sf.name) {
            return Err(src.error(
                s.span(),
                &format!("model.sites[{si}].name"),
                "a site name must be an identifier",
            ));
        }
        if sites.iter().any(|x: &Site| x.name == sf.name) {
            return Err(src.error(
                s.span(),
                &format!("model.sites[{si}].name"),
                format!("site name `{}` is used twice", sf.name),
            ));
        }
        // `j.qw` would name both the site's orientation and ball joint j's coordinate.
        if joint_set.contains(sf.name.as_str()) {
            return Err(src.error(
                s.span(),
                &format!("model.sites[{si}].name"),
                format!("site name `{}` is also a joint name: its signals would collide with the joint's coordinates", sf.name),
            ));
        }
        sites.push(Site {
            name: sf.name.clone(),
            body,
            pos: sf.pos,
        });
    }
    Ok(())
}

/// `[[model.point_forces]]`: a force (expressions of t, q and v) at a point of a body.
fn point_forces(
    src: &Source,
    m: &ModelFile,
    tree: &tree::Model,
    sym: &mut Symbols,
) -> R<Vec<PointForce>> {
    #[allow(clippy::single_range_in_vec_init)] // a list of allowed slot ranges, here one
    let state = [sym.layout.t..sym.layout.a];
    let mut point_forces = vec![];
    for (fi, f) in m.point_forces.iter().enumerate() {
        let pf = f.get_ref();
        let field = format!("model.point_forces[{fi}]");
        let body = tree.body_id(&pf.body).ok_or_else(|| {
            src.error(
                f.span(),
                &format!("{field}.body"),
                format!("unknown body `{}`", pf.body),
            )
        })?;
        let mut exprs = vec![];
        for (k, s) in pf.force.iter().enumerate() {
            let e = sym.compile(src, s, &format!("{field}.force[{k}]"))?;
            if let Some(bad) = sym.outside(&e, &state) {
                return Err(src.error(
                    s.span(),
                    &format!("{field}.force[{k}]"),
                    format!("a force may depend on t, q and v only, not on `{bad}`"),
                ));
            }
            exprs.push(e);
        }
        let [a, b, c]: [Expr; 3] = exprs.try_into().expect("three components");
        point_forces.push(PointForce {
            body,
            point: pf.point,
            force: [a, b, c],
        });
    }
    Ok(point_forces)
}

/// `forces` of a tree model: per velocity coordinate, an expression of t, q and v.
fn coordinate_forces(
    src: &Source,
    m: &ModelFile,
    v_names: &[String],
    sym: &mut Symbols,
) -> R<Vec<(usize, Expr)>> {
    #[allow(clippy::single_range_in_vec_init)] // a list of allowed slot ranges, here one
    let state = [sym.layout.t..sym.layout.a];
    let mut coordinate_forces = vec![];
    for (name, s) in &m.forces {
        let field = format!("model.forces.{name}");
        let i = v_names.iter().position(|x| x == name).ok_or_else(|| {
            src.error(
                s.span(),
                &field,
                format!(
                    "`{name}` is not a velocity coordinate{} (have: {})",
                    check::did_you_mean(name, v_names.iter().map(String::as_str)),
                    v_names.join(", ")
                ),
            )
        })?;
        let e = sym.compile(src, s, &field)?;
        if let Some(bad) = sym.outside(&e, &state) {
            return Err(src.error(
                s.span(),
                &field,
                format!("a force may depend on t, q and v only, not on `{bad}`"),
            ));
        }
        coordinate_forces.push((i, e));
    }
    Ok(coordinate_forces)
}

/// Bodies, joint names, link and frame names (sites), notes and robot file of a `urdf` or `mjcf`
/// model, and why names are no symbols (locked joints).
type Imported = (
    Vec<BodySpec>,
    Vec<String>,
    Vec<String>,
    ImportInfo,
    Vec<(String, String)>,
);

/// The bodies of a `urdf` or `mjcf` model: the file's links or bodies ([`crate::import::urdf`],
/// [`crate::import::mjcf`]) plus `frames` as massless welded bodies.
fn import_specs(src: &Source, m: &ModelFile, params: &[(String, f64)]) -> R<Imported> {
    let kind = m.kind.get_ref().as_str();
    let present: Vec<&str> = [
        ("coordinates", !m.coordinates.is_empty()),
        ("mass_matrix", m.mass_matrix.is_some()),
        ("mass_diagonal", m.mass_diagonal.is_some()),
        ("potential", m.potential.is_some()),
        ("bodies", !m.bodies.is_empty()),
    ]
    .iter()
    .filter(|x| x.1)
    .map(|x| x.0)
    .collect();
    if !present.is_empty() {
        return Err(src.error(
            m.kind.span(),
            "model",
            format!(
                "a `{kind}` model takes its bodies from the file: remove {}",
                and_list(&present)
            ),
        ));
    }
    let Some(file) = &m.file else {
        return Err(src.error(
            m.kind.span(),
            "model.file",
            format!("a `{kind}` model needs `file` (a path relative to the scene, or package://PKG/...)"),
        ));
    };
    let (path, text) = read_robot(src, file)?;
    let root = root_joint(src, m, kind)?;
    let locked: Vec<String> = m
        .locked_joints
        .iter()
        .map(|l| l.get_ref().clone())
        .collect();
    let usrc_path = path.clone();
    let usrc = Source::new(path, text);
    let robot = import_robot(src, m, kind, &usrc, root, &locked)?;
    let mut specs = robot.bodies;
    let mut sites: Vec<String> = specs
        .iter()
        .map(|b| b.name.clone())
        .filter(|n| !n.contains(['`', '\'']))
        .collect();
    frames(src, m, &robot.joints, &mut specs, &mut sites)?;
    site_frames(src, &robot.sites, &robot.joints, &mut specs, &mut sites)?;
    // a static body's mass progmo does not compute: refused where the scene needs it (`com.`)
    if let Some(e) = robot.mass_unknown.first() {
        if !sites.iter().any(|s| s == "com") && dotted_words(&src.text).contains("com") {
            return Err(e.clone());
        }
    }
    let hints = locked_hints(src, m, &robot.locked);
    for j in &robot.joints {
        if params.iter().any(|p| &p.0 == j) {
            return Err(src.error(
                file.span(),
                "model.file",
                format!("joint `{j}` of the file has the name of a parameter"),
            ));
        }
    }
    let (mimics, records) = mimic_rows_of(
        m,
        robot.mimics,
        &robot.locked,
        &robot.joints,
        robot.unmodelled,
    )?;
    let unmodelled = declared(src, m, &records)?;
    let info = super::RobotFile {
        kind: kind.to_string(),
        path: std::path::absolute(&usrc_path).unwrap_or(usrc_path),
        locked: robot.locked,
        ranges: robot.ranges,
        unmodelled,
        keyframes: robot.keyframes,
        body_at: robot.body_at,
        mimics,
    };
    Ok((specs, robot.joints, sites, (robot.notes, Some(info)), hints))
}

/// The URDF's `<mimic>` couplings the scene models (all, unless `[model] ignore` declares
/// `mimic`: then none, and their records stay) and the records left: a coupling of two moving
/// joints is a system row; of two locked joints, nothing (both welded); of a locked and a moving
/// one, or with a leader the file lacks, an error at the `<mimic>`.
fn mimic_rows_of(
    m: &ModelFile,
    mimics: Vec<crate::import::urdf::Mimic>,
    locked: &[(String, f64)],
    joints: &[String],
    mut records: Vec<crate::import::unmodelled::Unmodelled>,
) -> R<(
    Vec<crate::import::urdf::Mimic>,
    Vec<crate::import::unmodelled::Unmodelled>,
)> {
    if m.ignore.contains_key("mimic") || mimics.is_empty() {
        return Ok((vec![], records));
    }
    records.retain(|r| r.kind != "mimic");
    let is_locked = |j: &str| locked.iter().any(|(l, _)| l == j);
    let mut out = vec![];
    for mm in mimics {
        let leader_locked = is_locked(&mm.leader);
        let problem = if !leader_locked && !joints.contains(&mm.leader) {
            Some(format!(
                "joint `{}` follows `{}`, which is not a joint of the file (declare `mimic` ignored to read the joints as independent)",
                mm.joint, mm.leader
            ))
        } else if mm.locked != leader_locked {
            let (l, f) = if mm.locked {
                (&mm.joint, &mm.leader)
            } else {
                (&mm.leader, &mm.joint)
            };
            Some(format!("`{l}` is locked and `{f}`, coupled to it by this <mimic>, moves: lock both or neither (or declare `mimic` ignored: the joints are then independent)"))
        } else {
            None
        };
        if let Some(msg) = problem {
            let mut e = mm.at.clone();
            e.message = msg;
            return Err(e);
        }
        if !mm.locked {
            out.push(mm);
        }
    }
    Ok((out, records))
}

/// The system row of each modelled `<mimic>`: `mimic_JOINT` (`mimic_K`, the K-th, when the joint's
/// name is not an identifier), q_joint - (multiplier q_leader + offset) = 0, spanned at `model.file`.
fn mimic_rows(m: &ModelFile, rf: Option<&super::RobotFile>) -> Vec<(RowFile, String)> {
    let Some((rf, file)) = rf.zip(m.file.as_ref()) else {
        return vec![];
    };
    use crate::expr::written;
    rf.mimics
        .iter()
        .enumerate()
        .map(|(k, mm)| {
            let name = if is_identifier(&mm.joint) {
                format!("mimic_{}", mm.joint)
            } else {
                format!("mimic_{k}")
            };
            let expr = format!(
                "{} - ({:?}*{} + {:?})",
                written(&mm.joint),
                mm.multiplier,
                written(&mm.leader),
                mm.offset
            );
            let row = RowFile {
                name: Spanned::new(file.span(), name),
                expr: Spanned::new(file.span(), expr),
            };
            (row, "model.file".to_string())
        })
        .collect()
}

/// The robot file of `file` (resolved beside the scene or in a package), read as text.
fn read_robot(src: &Source, file: &Spanned<String>) -> R<(std::path::PathBuf, String)> {
    use crate::import;
    let dir = src.file.parent().unwrap_or(std::path::Path::new("."));
    let path = import::resolve(file.get_ref(), dir)
        .map_err(|e| src.error(file.span(), "model.file", e))?;
    let text = crate::input::read(&path, crate::input::ROBOT_LIMIT)
        .map_err(|e| {
            let shown = path.display();
            src.error(
                file.span(),
                "model.file",
                format!("cannot read `{shown}`: {e}"),
            )
        })
        .and_then(|b| crate::input::text(b).map_err(|e| robot_not_text(&path, e)))?;
    Ok((path, text))
}

/// `root_joint` of a `urdf` model (fixed by default); an `mjcf` model takes none.
fn root_joint(src: &Source, m: &ModelFile, kind: &str) -> R<crate::import::urdf::RootJoint> {
    use crate::import::urdf;
    let root = match m.root_joint.as_ref().map(|r| r.get_ref().as_str()) {
        Some(_) if kind == "mjcf" => {
            return Err(src.error(
                m.root_joint.as_ref().expect("given").span(),
                "model.root_joint",
                "an `mjcf` model takes its joints from the file (a free root is a <freejoint/> there): remove root_joint",
            ))
        }
        None | Some("fixed") => urdf::RootJoint::Fixed,
        Some("free") => urdf::RootJoint::Free,
        Some(other) => {
            return Err(src.error(
                m.root_joint.as_ref().expect("given").span(),
                "model.root_joint",
                format!("unknown root joint `{other}`: expected `fixed` or `free`"),
            ))
        }
    };
    Ok(root)
}

/// The robot of the file `usrc` (URDF or MJCF) with its `locked` joints welded; a locked joint the
/// file lacks is located in the scene.
fn import_robot(
    src: &Source,
    m: &ModelFile,
    kind: &str,
    usrc: &Source,
    root: crate::import::urdf::RootJoint,
    locked: &[String],
) -> R<crate::import::urdf::Robot> {
    use crate::import::{mjcf, urdf};
    let robot = if kind == "mjcf" {
        mjcf::import(usrc, locked)
    } else {
        urdf::import(usrc, root, locked)
    }
    .map_err(|mut e| {
        // a locked joint the file lacks is the scene's mistake: locate it there
        if e.field == "locked_joints" {
            let k = locked
                .iter()
                .position(|l| e.message.contains(&format!("`{l}`")));
            let span = k.map_or(m.kind.span(), |k| m.locked_joints[k].span());
            e = src.error(span, "model.locked_joints", e.message);
        }
        e
    })?;
    Ok(robot)
}

/// `[[model.frames]]`: massless bodies welded to a link (or the world), appended to `specs` and,
/// as sites, to `sites`; each named by an identifier no link or joint has.
fn frames(
    src: &Source,
    m: &ModelFile,
    joints: &[String],
    specs: &mut Vec<BodySpec>,
    sites: &mut Vec<String>,
) -> R<()> {
    let mut body_names: std::collections::HashSet<String> =
        specs.iter().map(|b| b.name.clone()).collect();
    let joint_set: std::collections::HashSet<&str> = joints.iter().map(String::as_str).collect();
    for (fi, f) in m.frames.iter().enumerate() {
        let ff = f.get_ref();
        let field = format!("model.frames[{fi}]");
        if specs.len() == crate::input::MAX_BODIES {
            return Err(src.error(
                f.span(),
                &field,
                format!(
                    "more than {} bodies with the file's (the limit of bodies of a model)",
                    crate::input::MAX_BODIES
                ),
            ));
        }
        if joint_set.contains(ff.name.as_str()) {
            return Err(src.error(
                f.span(),
                &format!("{field}.name"),
                format!(
                    "frame name `{}` is also a joint name: its signals would collide with the joint's coordinates",
                    ff.name
                ),
            ));
        }
        if !is_identifier(&ff.name) || body_names.contains(&ff.name) {
            return Err(src.error(
                f.span(),
                &format!("{field}.name"),
                format!(
                    "frame name `{}` must be an identifier and not a link's name",
                    ff.name
                ),
            ));
        }
        if !body_names.contains(&ff.parent) && ff.parent != tree::WORLD {
            return Err(src.error(
                f.span(),
                &format!("{field}.parent"),
                format!("unknown link `{}`", ff.parent),
            ));
        }
        let n = ff.quat.iter().map(|x| x * x).sum::<f64>().sqrt();
        if !(n >= 1e-9 && n.is_finite() && ff.pos.iter().all(|x| x.is_finite())) {
            return Err(src.error(
                f.span(),
                &field,
                "pos must be finite and quat a nonzero (w, x, y, z)",
            ));
        }
        body_names.insert(ff.name.clone());
        push_frame(specs, sites, (&ff.name, &ff.parent), (ff.pos, ff.quat));
    }
    Ok(())
}

/// A frame (a `[[model.frames]]` entry, an MJCF site): a massless body welded to `parent` at
/// `pos`, `quat`, and a signal source of its name.
fn push_frame(
    specs: &mut Vec<BodySpec>,
    sites: &mut Vec<String>,
    (name, parent): (&str, &str),
    (pos, quat): ([f64; 3], [f64; 4]),
) {
    specs.push(BodySpec::massless(name, parent).at(pos).rotated(quat));
    sites.push(name.to_string());
}

/// Every word of `text` that a `.` follows (`NAME.` or `` `NAME`. `` names a signal source).
fn dotted_words(text: &str) -> std::collections::HashSet<&str> {
    let mut named = std::collections::HashSet::new();
    // backquoted names (`` `tip-2`.x ``, the quoting of expr/lexer.rs)
    let mut rest = text;
    while let Some(open) = rest.find('`') {
        let after = &rest[open + 1..];
        let Some(close) = after.find('`') else { break };
        if after[close + 1..].starts_with('.') {
            named.insert(&after[..close]);
        }
        rest = &after[close + 1..];
    }
    let mut start = None;
    for (i, c) in text.char_indices() {
        if c.is_alphanumeric() || c == '_' {
            start.get_or_insert(i);
        } else {
            if let (Some(s), '.') = (start, c) {
                named.insert(&text[s..i]);
            }
            start = None;
        }
    }
    named
}

/// The MJCF file's `<site>`s the scene names (`NAME.` in its text: model only what a scene needs),
/// appended as massless bodies welded where the site is, like `[[model.frames]]`. A site whose
/// name is a link's, a joint's or a `frames` entry's, or cannot be written in a row even
/// backquoted, is not added (that name means the other); one that cannot be read as a frame is
/// refused with its reason, located at the site.
fn site_frames(
    src: &Source,
    file_sites: &[crate::import::mjcf::Site],
    joints: &[String],
    specs: &mut Vec<BodySpec>,
    sites: &mut Vec<String>,
) -> R<()> {
    use std::collections::HashSet;
    let named = dotted_words(&src.text);
    let mut taken: HashSet<String> = specs.iter().map(|b| b.name.clone()).collect();
    taken.extend(joints.iter().cloned());
    for site in file_sites {
        let unused = !named.contains(site.name.as_str());
        let writable =
            is_identifier(&site.name) || crate::import::unusable_name(&site.name).is_none();
        if unused || taken.contains(&site.name) || !writable {
            continue;
        }
        if let Some(e) = &site.problem {
            return Err(e.clone());
        }
        if specs.len() == crate::input::MAX_BODIES {
            return Err(src.general(
                "model.file",
                format!(
                    "more than {} bodies with the file's sites",
                    crate::input::MAX_BODIES
                ),
            ));
        }
        push_frame(
            specs,
            sites,
            (&site.name, &site.parent),
            (site.pos, site.quat),
        );
        taken.insert(site.name.clone());
    }
    Ok(())
}

/// Why a locked joint's name is no symbol: welded at its q, by which `locked_joints` entry.
fn locked_hints(src: &Source, m: &ModelFile, locked: &[(String, f64)]) -> Vec<(String, String)> {
    locked
        .iter()
        .map(|(j, q)| {
            let k = m.locked_joints.iter().position(|l| l.get_ref() == j);
            let at = k.map_or(String::new(), |k| {
                let (line, _) = src.line_col(m.locked_joints[k].span().start);
                format!(" by model.locked_joints[{k}] (line {line})")
            });
            (
                j.clone(),
                format!("`{j}` is a locked joint, welded at q = {q}{at}: it is no coordinate"),
            )
        })
        .collect()
}

/// `[model] ignore` checked against the closed vocabulary and the file's records: each key a
/// kind of [`crate::import::unmodelled::KINDS`] (else a located error naming the nearest), each
/// reason non-empty, each kind present in the file; the records with their declarations.
fn declared(
    src: &Source,
    m: &ModelFile,
    found: &[crate::import::unmodelled::Unmodelled],
) -> R<Vec<super::UnmodelledEntry>> {
    use crate::import::unmodelled::{is_kind, nearest_kind, KINDS};
    for (k, reason) in &m.ignore {
        let field = format!("model.ignore.{k}");
        if !is_kind(k) {
            return Err(src.error(
                reason.span(),
                &field,
                format!(
                    "unknown kind `{k}`: did you mean `{}`? (kinds: {})",
                    nearest_kind(k),
                    KINDS.iter().map(|x| x.0).collect::<Vec<_>>().join(", ")
                ),
            ));
        }
        if reason.get_ref().trim().is_empty() {
            return Err(src.error(
                reason.span(),
                &field,
                format!("ignoring `{k}` needs a reason (a non-empty string)"),
            ));
        }
        if !found.iter().any(|u| u.kind == k) {
            return Err(src.error(
                reason.span(),
                &field,
                format!("the robot file has no element of kind `{k}` (or only on locked joints): remove this declaration"),
            ));
        }
    }
    Ok(found
        .iter()
        .map(|u| super::UnmodelledEntry {
            kind: u.kind.to_string(),
            element: u.element.clone(),
            location: u.location(),
            declared: m.ignore.get(u.kind).map(|r| r.get_ref().clone()),
        })
        .collect())
}

/// A robot file that is not text: located in it, never quoted ([`crate::input::text`]).
fn robot_not_text(path: &std::path::Path, e: crate::input::NotText) -> SceneError {
    SceneError {
        file: path.to_path_buf(),
        line: e.line,
        column: e.column,
        field: "xml".into(),
        message: format!("the robot file {}", e.message),
        excerpt: String::new(),
    }
}

/// The bodies of a `tree` model as written in `[[model.bodies]]`, and its joint names.
fn tree_specs(
    src: &Source,
    m: &ModelFile,
    params: &[(String, f64)],
) -> R<(Vec<BodySpec>, Vec<String>)> {
    tree_keys(src, m)?;
    let mut specs = vec![];
    let mut joint_names: Vec<String> = vec![];
    let mut joint_set = std::collections::HashSet::new();
    for (bi, b) in m.bodies.iter().enumerate() {
        let bf = b.get_ref();
        let field = format!("model.bodies[{bi}]");
        let mass = *bf.mass.get_ref();
        if !(mass >= 0.0) || !mass.is_finite() {
            return Err(src.error(
                bf.mass.span(),
                &format!("{field}.mass"),
                format!("mass must be positive (or 0 for a massless link), got {mass}"),
            ));
        }
        for (ji, j) in bf.joints.iter().enumerate() {
            let n = j.get_ref().name.as_str();
            let jfield = format!("{field}.joints[{ji}].name");
            if !is_identifier(n) || n == "t" || n == "pi" || params.iter().any(|p| p.0 == n) {
                return Err(src.error(
                    j.span(),
                    &jfield,
                    format!("`{n}` is not a valid joint name (an identifier, not `t`, `pi` or a parameter)"),
                ));
            }
            if !joint_set.insert(n.to_string()) {
                return Err(src.error(
                    j.span(),
                    &jfield,
                    format!("joint name `{n}` is used twice"),
                ));
            }
            joint_names.push(n.to_string());
        }
        let mut spec = body_spec(src, b, &field, mass)?;
        for (ji, j) in bf.joints.iter().enumerate() {
            spec = spec.joint(joint_spec(src, j, &format!("{field}.joints[{ji}]"))?);
        }
        specs.push(spec);
    }
    Ok((specs, joint_names))
}

/// A tree model takes none of the robot file or lagrangian keys, and 1 to
/// [`crate::input::MAX_BODIES`] bodies.
fn tree_keys(src: &Source, m: &ModelFile) -> R<()> {
    if let Some(f) = &m.file {
        return Err(src.error(
            f.span(),
            "model.file",
            format!(
                "{} belong to `urdf` and `mjcf` models",
                and_list(&URDF_ONLY)
            ),
        ));
    }
    if m.root_joint.is_some()
        || !m.frames.is_empty()
        || !m.locked_joints.is_empty()
        || !m.ignore.is_empty()
    {
        return Err(src.error(
            m.kind.span(),
            "model",
            format!(
                "{} belong to `urdf` and `mjcf` models",
                and_list(&URDF_ONLY)
            ),
        ));
    }
    if !m.coordinates.is_empty()
        || m.mass_matrix.is_some()
        || m.mass_diagonal.is_some()
        || m.potential.is_some()
    {
        return Err(src.error(
            m.kind.span(),
            "model",
            format!(
                "{} belong to `lagrangian` models",
                and_list(&LAGRANGIAN_ONLY)
            ),
        ));
    }
    if m.bodies.is_empty() {
        return Err(src.error(
            m.kind.span(),
            "model.bodies",
            "a tree model needs at least one body",
        ));
    }
    if let Some(b) = m.bodies.get(crate::input::MAX_BODIES) {
        return Err(src.error(
            b.span(),
            &format!("model.bodies[{}]", crate::input::MAX_BODIES),
            format!(
                "more than {} bodies (the limit of bodies of a model)",
                crate::input::MAX_BODIES
            ),
        ));
    }
    Ok(())
}

/// Body `b` (of a checked `mass`) with its inertia and placement, without its joints.
fn body_spec(src: &Source, b: &Spanned<BodyFile>, field: &str, mass: f64) -> R<BodySpec> {
    let bf = b.get_ref();
    let inertia = body_inertia(src, bf, field)?;
    if mass == 0.0 && inertia != [[0.0; 3]; 3] {
        let span = bf.inertia.as_ref().map_or(b.span(), |i| i.span());
        return Err(src.error(
            span,
            &format!("{field}.inertia"),
            "a body of mass 0 is a massless link and takes no inertia: give a positive `mass` or remove `inertia`",
        ));
    }
    let spec = if mass == 0.0 && inertia == [[0.0; 3]; 3] {
        BodySpec::massless(&bf.name, &bf.parent)
    } else {
        BodySpec::new(&bf.name, &bf.parent, mass, bf.com, inertia)
    };
    // Placement, checked here so that a bad value is located at itself (not at the body).
    let pos = bf.pos.as_ref().map_or([0.0; 3], |p| *p.get_ref());
    let quat = bf
        .quat
        .as_ref()
        .map_or([1.0, 0.0, 0.0, 0.0], |q| *q.get_ref());
    if let Some(p) = bf
        .pos
        .as_ref()
        .filter(|p| !p.get_ref().iter().all(|x| x.is_finite()))
    {
        return Err(src.error(p.span(), &format!("{field}.pos"), "placement is not finite"));
    }
    if let Some(q) = &bf.quat {
        let n = quat.iter().map(|x| x * x).sum::<f64>().sqrt();
        if !n.is_finite() {
            return Err(src.error(
                q.span(),
                &format!("{field}.quat"),
                "placement is not finite",
            ));
        }
        if n < 1e-9 {
            return Err(src.error(
                q.span(),
                &format!("{field}.quat"),
                "placement quaternion is zero: give a unit quaternion (w, x, y, z)",
            ));
        }
    }
    Ok(spec.at(pos).rotated(quat).with_gravcomp(bf.gravcomp))
}

/// A body's inertia tensor: 3 principal moments or 6 entries (none: zero).
fn body_inertia(src: &Source, bf: &BodyFile, field: &str) -> R<[[f64; 3]; 3]> {
    Ok(match &bf.inertia {
        None => [[0.0; 3]; 3],
        Some(i) => {
            let v = i.get_ref();
            match v.len() {
                3 => [[v[0], 0.0, 0.0], [0.0, v[1], 0.0], [0.0, 0.0, v[2]]],
                6 => [[v[0], v[3], v[4]], [v[3], v[1], v[5]], [v[4], v[5], v[2]]],
                k => {
                    return Err(src.error(i.span(), &format!("{field}.inertia"), format!("give 3 principal moments or 6 entries [ixx, iyy, izz, ixy, ixz, iyz], not {k}")))
                }
            }
        }
    })
}

/// Joint `j` of a body, reported under `jfield`.
fn joint_spec(src: &Source, j: &Spanned<JointFile>, jfield: &str) -> R<JointSpec> {
    let jf = j.get_ref();
    let kind = jf.kind.get_ref().as_str();
    let axis = || match &jf.axis {
        None => Err(src.error(
            j.span(),
            &format!("{jfield}.axis"),
            format!("a {kind} joint needs an axis"),
        )),
        Some(a) => {
            let v = *a.get_ref();
            let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if n.is_finite() && n >= 1e-12 {
                Ok(v)
            } else {
                Err(src.error(
                    a.span(),
                    &format!("{jfield}.axis"),
                    format!("axis {v:?} is zero or not finite"),
                ))
            }
        }
    };
    let mut js = match kind {
        "hinge" => JointSpec::hinge(&jf.name, axis()?),
        "slide" => JointSpec::slide(&jf.name, axis()?),
        "ball" => JointSpec::ball(&jf.name),
        "free" => JointSpec::free(&jf.name),
        other => {
            return Err(src.error(
                jf.kind.span(),
                &format!("{jfield}.type"),
                format!("unknown joint type `{other}`: expected hinge, slide, ball or free"),
            ))
        }
    };
    js = js.with_anchor(jf.anchor);
    if jf.stiffness != 0.0 {
        js = js.with_spring(jf.stiffness, jf.spring_ref);
    }
    if jf.damping != 0.0 {
        js = js.with_damping(jf.damping);
    }
    if jf.armature != 0.0 {
        js = js.with_armature(jf.armature);
    }
    Ok(js)
}

/// Constraint rows: the system's own constraints, then the programme.
fn rows(
    src: &Source,
    file: &SceneFile,
    sym: &mut Symbols,
    closure_rows: &[(RowFile, String)],
) -> R<(ExprConstraints, Vec<Range<usize>>)> {
    let mut specs = vec![];
    let mut exprs = vec![];
    let mut spans = vec![];
    let all = file
        .constraints
        .iter()
        .enumerate()
        .map(|(i, r)| (r, Role::System, format!("constraints[{i}]")))
        .chain(
            closure_rows
                .iter()
                .map(|(r, field)| (r, Role::System, field.clone())),
        )
        .chain(
            file.programme
                .iter()
                .enumerate()
                .map(|(i, r)| (r, Role::Programme, format!("programme[{i}]"))),
        )
        .collect::<Vec<_>>();
    for (r, role, field) in all {
        let name = r.name.get_ref();
        if !is_identifier(name) {
            return Err(src.error(
                r.name.span(),
                &format!("{field}.name"),
                "a row name must be an identifier",
            ));
        }
        if specs.iter().any(|s: &RowSpec| &s.name == name) {
            return Err(src.error(
                r.name.span(),
                &format!("{field}.name"),
                format!("row name `{name}` is used twice"),
            ));
        }
        let e = sym.compile(src, &r.expr, &format!("{field}.expr"))?;
        let level = match sym.level(&e) {
            Some(l) => l,
            None => {
                return Err(src.error(
                    r.expr.span(),
                    &format!("{field}.expr"),
                    "the row depends on neither time nor the state",
                ))
            }
        };
        if level == Level::Position && !e.slots().iter().any(|&s| s != sym.layout.t) {
            return Err(src.error(
                r.expr.span(),
                &format!("{field}.expr"),
                "the row depends on time only: it constrains nothing",
            ));
        }
        specs.push(RowSpec::new(name, level, role));
        exprs.push(e);
        spans.push(r.expr.span());
    }
    let nv = sym.layout.nv;
    // Closure rows are counted after the dependent ones are set aside (`closure_rows_kept`).
    if specs.len() - closure_rows.len() > nv {
        // Point at the first row beyond the number of degrees of freedom.
        let nc = file.constraints.len();
        let n_user = specs.len() - closure_rows.len();
        let (row, field) = if nv < nc {
            (&file.constraints[nv], format!("constraints[{nv}]"))
        } else {
            (&file.programme[nv - nc], format!("programme[{}]", nv - nc))
        };
        return Err(src.error(
            row.name.span(),
            &field,
            format!(
                "too many rows: {n_user} (constraints + programme) for {nv} degrees of freedom, at most {nv}"
            ),
        ));
    }
    let signals = std::mem::take(&mut sym.signals);
    Ok((
        ExprConstraints::new(specs, exprs, sym.layout.clone(), signals),
        spans,
    ))
}

/// The initial state: every coordinate by name (tree scenes: missing ones take the neutral value),
/// velocities default to 0.
fn initial(
    src: &Source,
    file: &SceneFile,
    params: &[(String, f64)],
    q_names: &[String],
    (v_names, v_start): (&[String], &[f64]),
    tree: Option<(&Arc<tree::Model>, &[f64])>,
) -> R<(Vec<f64>, Vec<f64>)> {
    let init = file.initial.get_ref();
    let mut consts = SymbolTable::new();
    for (n, x) in params {
        consts.define(n.clone(), *x);
    }
    let value = |n: &Number, span: Range<usize>, field: &str| number(src, &consts, n, span, field);
    let fill = |map: &BTreeMap<String, Spanned<Initial>>,
                names: &[String],
                out: &mut Vec<Option<f64>>,
                what: &str,
                is_q: bool|
     -> R<()> {
        for (key, s) in map {
            let field = format!("initial.{what}.{key}");
            let targets: Vec<usize> = if let Some(i) = names.iter().position(|n| n == key) {
                vec![i]
            } else if let Some((t, _)) = tree {
                match t.joint_id(key) {
                    Some(j) => {
                        let r = if is_q {
                            t.joint_q_range(j)
                        } else {
                            t.joint_v_range(j)
                        };
                        r.collect()
                    }
                    None => vec![],
                }
            } else {
                vec![]
            };
            if targets.is_empty() {
                return Err(src.error(
                    s.span(),
                    &field,
                    format!(
                        "`{key}` is not a coordinate{} (have: {})",
                        check::did_you_mean(key, names.iter().map(String::as_str)),
                        names.join(", ")
                    ),
                ));
            }
            let vals: Vec<f64> = match s.get_ref() {
                Initial::One(n) => vec![value(n, s.span(), &field)?],
                Initial::Many(ns) => ns
                    .iter()
                    .map(|n| value(n, s.span(), &field))
                    .collect::<R<_>>()?,
            };
            if vals.len() != targets.len() {
                return Err(src.error(
                    s.span(),
                    &field,
                    format!("needs {} values, got {}", targets.len(), vals.len()),
                ));
            }
            for (i, x) in targets.into_iter().zip(vals) {
                if !x.is_finite() {
                    return Err(src.error(s.span(), &field, format!("is {x}")));
                }
                out[i] = Some(x);
            }
        }
        Ok(())
    };
    let mut q: Vec<Option<f64>> = vec![None; q_names.len()];
    fill(&init.q, q_names, &mut q, "q", true)?;
    let mut v: Vec<Option<f64>> = vec![None; v_names.len()];
    fill(&init.v, v_names, &mut v, "v", false)?;
    let q: Vec<f64> = match tree {
        Some((_, neutral)) => q
            .iter()
            .zip(neutral)
            .map(|(x, n)| x.unwrap_or(*n))
            .collect(),
        None => {
            let missing: Vec<&str> = q_names
                .iter()
                .zip(&q)
                .filter(|(_, x)| x.is_none())
                .map(|(n, _)| n.as_str())
                .collect();
            if !missing.is_empty() {
                return Err(src.error(
                    file.initial.span(),
                    "initial.q",
                    format!("missing initial values for {}", missing.join(", ")),
                ));
            }
            q.into_iter().map(|x| x.unwrap_or(0.0)).collect()
        }
    };
    let v = v
        .iter()
        .zip(v_start)
        .map(|(x, s)| x.unwrap_or(*s))
        .collect();
    Ok((q, v))
}

const NO_KEYFRAME: &str = "a keyframe is read from an `mjcf` model's file: this model has none";

/// The starting values `[initial]` q and v complete: the tree's neutral configuration and zero
/// velocities, or the MJCF keyframe `[initial] keyframe` names (its joints' qpos and qvel; a locked
/// joint's value must be the one it is welded at).
fn keyframe(
    src: &Source,
    file: &SceneFile,
    t: &Arc<tree::Model>,
    rf: Option<&super::RobotFile>,
) -> R<(Vec<f64>, Vec<f64>)> {
    let mut q: Vec<f64> = tree::neutral(t).iter().copied().collect();
    let mut v = vec![0.0; t.nv()];
    let Some(k) = &file.initial.get_ref().keyframe else {
        return Ok((q, v));
    };
    let at = |m: String| src.error(k.span(), "initial.keyframe", m);
    let keys = rf.map_or(&[][..], |r| r.keyframes.as_slice());
    let Some(key) = keys.iter().find(|x| &x.name == k.get_ref()) else {
        let names: Vec<&str> = keys.iter().map(|x| x.name.as_str()).collect();
        return Err(at(if rf.is_some_and(|r| r.kind == "mjcf") {
            format!(
                "no keyframe `{}` in the file{} (named keys: {})",
                k.get_ref(),
                check::did_you_mean(k.get_ref(), names.iter().copied()),
                if names.is_empty() {
                    "none".into()
                } else {
                    names.join(", ")
                }
            )
        } else {
            NO_KEYFRAME.into()
        }));
    };
    let locked = rf.map_or(&[][..], |r| r.locked.as_slice());
    for (joint, kq, kv) in &key.joints {
        if let Some((_, welded)) = locked.iter().find(|(l, _)| l == joint) {
            if (kq[0] - welded).abs() > 1e-12 * welded.abs().max(1.0) {
                return Err(at(format!(
                    "keyframe `{}` ({}:{}) puts locked joint `{joint}` at {}, but it is welded at {welded}: unlock it or give the keyframe that value",
                    key.name,
                    key.file.display(),
                    key.line,
                    kq[0]
                )));
            }
            continue;
        }
        let j = t.joint_id(joint).expect("a joint of the imported file");
        for (i, x) in t.joint_q_range(j).zip(kq) {
            q[i] = *x;
        }
        for (i, x) in t.joint_v_range(j).zip(kv) {
            v[i] = *x;
        }
    }
    Ok((q, v))
}

/// The time span as written (checked with the settings by [`validate_settings`]).
/// A number or an expression of the constants in `consts`, located at `span` on error.
pub(super) fn number(
    src: &Source,
    consts: &SymbolTable,
    n: &Number,
    span: Range<usize>,
    field: &str,
) -> R<f64> {
    match n {
        Number::Value(x) => Ok(*x),
        Number::Expr(text) => Expr::compile(text, consts)
            .map(|e| e.value::<f64>(&[]))
            .map_err(|e| src.expr_error(span, field, &e)),
    }
}

pub(super) fn span(file: &SceneFile) -> (f64, f64) {
    let t = file.time.get_ref();
    (t.t0.as_ref().map_or(0.0, |x| *x.get_ref()), *t.t1.get_ref())
}

/// [`crate::solve::validate`] on the file's span and settings, the error located at its key.
fn validate_settings(src: &Source, file: &SceneFile, settings: &Settings) -> R<()> {
    use crate::solve::SettingsField as F;
    let Err(e) = crate::solve::validate(span(file), settings) else {
        return Ok(());
    };
    let t = file.time.get_ref();
    let f = &file.solver;
    let at = |x: &Option<Spanned<f64>>| x.as_ref().map(|x| x.span());
    let key = |k: &str| f.get(k).map(|x| x.span());
    let place = match e.field {
        F::T0 => at(&t.t0),
        F::T1 => Some(t.t1.span()),
        F::OutputDt => at(&t.output_dt),
        F::MaxSamples => t.max_samples.as_ref().map(|x| x.span()),
        F::Step => key("step").or(key("integrator")),
        other => other.key().strip_prefix("solver.").and_then(key),
    };
    // A span or rate that is too long is about the time table as a whole when no key is at fault.
    let place = place.or_else(|| (e.field == F::MaxSamples).then(|| file.time.span()));
    Err(match place {
        Some(span) => src.error(span, &e.field.key(), e.message),
        None => src.general(&e.field.key(), e.message),
    })
}

/// The file's settings: the `[solver]` keys, `[time]` output_dt / max_samples and `[initial]`
/// assemble, read through [`Overrides::from_table`] (names, types and ranges of the one definition)
/// and applied to the defaults; an error is located at the value, named by its table and key.
fn solver(src: &Source, file: &SceneFile) -> R<Settings> {
    let time = file.time.get_ref();
    let mut given = toml::Table::new();
    let mut spans: BTreeMap<String, (String, Range<usize>)> = BTreeMap::new();
    for (name, v) in &file.solver {
        let ok = crate::solve::setting(name).is_some_and(|s| s.table == "solver");
        if !ok {
            let names = crate::solve::settings()
                .iter()
                .filter(|s| s.table == "solver")
                .map(|s| s.name.as_str());
            return Err(src.error(
                v.span(),
                &format!("solver.{name}"),
                format!(
                    "unknown key `{name}`{}: [solver] takes {}",
                    check::did_you_mean(name, names.clone()),
                    names.collect::<Vec<_>>().join(", ")
                ),
            ));
        }
        given.insert(name.clone(), v.get_ref().clone());
        spans.insert(name.clone(), (format!("solver.{name}"), v.span()));
    }
    if let Some(x) = &time.output_dt {
        given.insert("output_dt".into(), toml::Value::Float(*x.get_ref()));
        spans.insert("output_dt".into(), ("time.output_dt".into(), x.span()));
    }
    if let Some(n) = &time.max_samples {
        given.insert("max_samples".into(), toml::Value::Integer(*n.get_ref()));
        spans.insert("max_samples".into(), ("time.max_samples".into(), n.span()));
    }
    given.insert(
        "assemble".into(),
        toml::Value::Boolean(file.initial.get_ref().assemble),
    );
    let located = |name: &str, message: String| match spans.get(name) {
        Some((key, span)) => src.error(span.clone(), key, message),
        None => src.general("solver", message),
    };
    let o = Overrides::from_table(&given).map_err(|e| located(&e.name, e.message))?;
    Settings::default().apply(&o).map_err(|e| match e {
        OverrideError::UnknownName(u) => located(
            u.what,
            format!(
                "unknown value `{}`: expected one of {}",
                u.value,
                u.expected.join(", ")
            ),
        ),
        OverrideError::StepRequired => match spans.get("integrator") {
            Some((_, span)) => src.error(
                span.clone(),
                "solver.step",
                "rk4 needs a positive fixed `step`",
            ),
            None => src.general("solver.step", "rk4 needs a positive fixed `step`"),
        },
    })
}

/// Simulators the scene declares it is not checked in, with the reasons.
fn expected_not_checked(src: &Source, file: &SceneFile) -> R<Vec<(String, String)>> {
    let mut out = vec![];
    for (sim, reason) in &file.checks.not_checked {
        let field = format!("checks.not_checked.{sim}");
        if !SIMULATORS.contains(&sim.as_str()) {
            return Err(src.error(
                reason.span(),
                &field,
                format!(
                    "unknown simulator `{sim}`{}: expected one of {}",
                    check::did_you_mean(sim, SIMULATORS.iter().copied()),
                    SIMULATORS.join(", ")
                ),
            ));
        }
        if reason.get_ref().trim().is_empty() {
            return Err(src.error(
                reason.span(),
                &field,
                "a declared not_checked needs a reason",
            ));
        }
        out.push((sim.clone(), reason.get_ref().clone()));
    }
    Ok(out)
}

/// `[tolerances]`: names of the check's vocabulary ([`check::tolerance_keys`]: a misspelt budget
/// would silently leave its metric at the default), positive values, reasons.
fn tolerances(src: &Source, file: &SceneFile) -> R<Vec<Tolerance>> {
    let mut out = vec![];
    let known = check::tolerance_keys();
    for (name, t) in &file.tolerances {
        let field = format!("tolerances.{name}");
        if let Some((_, why)) = check::RETIRED.iter().find(|(r, _)| r == name) {
            return Err(src.error(
                t.span(),
                &field,
                format!("`{name}` is no longer accepted: {why}"),
            ));
        }
        if !known.contains(name) {
            return Err(src.error(
                t.span(),
                &field,
                format!(
                    "unknown tolerance `{name}`{}: the check reads its metrics' budgets (the \
                     metric's name, or with `_mujoco`, `_pinocchio`, `_drake`, `_solver_only` for a checker \
                     that judges it) (FORMAT.md, \"Tolerances\")",
                    check::did_you_mean(name, known.iter().map(|k| k.as_str())),
                ),
            ));
        }
        out.push(tolerance(src, name, &field, t)?);
    }
    Ok(out)
}

/// One `{ value, reason }` entry: a positive finite value and a non-empty reason.
fn tolerance(src: &Source, name: &str, field: &str, t: &Spanned<ToleranceFile>) -> R<Tolerance> {
    let tf = t.get_ref();
    if !(tf.value > 0.0) || !tf.value.is_finite() {
        return Err(src.error(
            t.span(),
            field,
            format!("value must be positive, got {}", tf.value),
        ));
    }
    if tf.reason.trim().is_empty() {
        return Err(src.error(t.span(), field, "every tolerance needs a one-line reason"));
    }
    Ok(Tolerance {
        name: name.to_string(),
        value: tf.value,
        reason: tf.reason.clone(),
    })
}

/// `[checks] replay_step`: the check's fixed replay step, with its reason.
fn replay_step(src: &Source, file: &SceneFile) -> R<Option<Tolerance>> {
    file.checks
        .replay_step
        .as_ref()
        .map(|t| tolerance(src, "replay_step", "checks.replay_step", t))
        .transpose()
}

/// A(q0) must be symmetric positive definite.
fn check_mass<M: Model, C: Constraints>(
    src: &Source,
    file: &SceneFile,
    p: &Problem<M, C>,
) -> R<()> {
    let mut ws = p.model.workspace::<f64>();
    let n = p.model.nv();
    let mut a = nalgebra::DMatrix::zeros(n, n);
    p.model.mass_matrix(&mut ws, &p.q0, &mut a);
    let bad =
        a.iter().any(|x| !x.is_finite()) || crate::linalg::cholesky(&mut a.clone(), n).is_err();
    if bad {
        // Lagrangian models point at the matrix they give; tree models at the model.
        let m = file.model.get_ref();
        let (span, field) = match (&m.mass_matrix, &m.mass_diagonal) {
            (Some(a), _) => (a.span(), "model.mass_matrix"),
            (None, Some(d)) => (d.span(), "model.mass_diagonal"),
            _ => (file.model.span(), "model"),
        };
        let msg = singular_mass(&a, &p.model.v_names()).unwrap_or_else(|| {
            "the mass matrix is not positive definite (or not finite) at the initial configuration"
                .to_string()
        });
        return Err(src.error(span, field, msg));
    }
    Ok(())
}

/// Why A(q0) (symmetric, not positive definite) is singular: its rank and the coordinates whose
/// rows are zero, else those its null space moves; `None` when A is indefinite or not finite.
/// Zero is relative: within [`tree::INERTIA_RTOL`] of the largest eigenvalue.
fn singular_mass(a: &nalgebra::DMatrix<f64>, names: &[String]) -> Option<String> {
    if a.iter().any(|x| !x.is_finite()) {
        return None;
    }
    let n = a.nrows();
    let e = nalgebra::SymmetricEigen::new(0.5 * (a + a.transpose()));
    let hi = e.eigenvalues.max().max(0.0);
    let tol = tree::INERTIA_RTOL * hi;
    if e.eigenvalues.min() < -tol {
        return None;
    }
    let null: Vec<usize> = (0..n).filter(|&k| e.eigenvalues[k] <= tol).collect();
    let list = |ks: &[usize]| {
        ks.iter()
            .map(|&k| format!("`{}`", names[k]))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let zero_rows: Vec<usize> = (0..n)
        .filter(|&i| a.row(i).iter().all(|x| x.abs() <= tol))
        .collect();
    let rank = format!(
        "the mass matrix is singular at the initial configuration (rank {} of {n}): the motion is not determined",
        n - null.len()
    );
    if !zero_rows.is_empty() {
        return Some(format!(
            "{rank}: the rows of {} are zero (no mass moves with them, e.g. a massless link at the end of a chain; give it mass or lock the joint)",
            list(&zero_rows)
        ));
    }
    // the coordinates a null vector moves (components above 1/10 of the unit vector)
    let moved: Vec<usize> = (0..n)
        .filter(|&i| null.iter().any(|&k| e.eigenvectors[(i, k)].abs() > 0.1))
        .collect();
    Some(format!(
        "{rank}: a combination of {} moves no mass",
        list(&moved)
    ))
}

/// The forces G, Q and the rows must be finite at the initial state: a value that overflows there
/// (a velocity of 1e308 squares to inf) is refused at its `initial` entry, not as NaN rows at t0.
fn check_finite_at_start<M: Model, C: Constraints>(
    src: &Source,
    file: &SceneFile,
    p: &Problem<M, C>,
) -> R<()> {
    let (nv, s) = (p.model.nv(), p.constraints.rows().len());
    let mut ws = p.model.workspace::<f64>();
    let (mut g, mut f, mut h) = (vec![0.0; nv], vec![0.0; nv], vec![0.0; s]);
    p.model.velocity_terms(&mut ws, &p.q0, &p.v0, &mut g);
    p.model.applied_forces(&mut ws, p.t0, &p.q0, &p.v0, &mut f);
    let mut cws = p.constraints.workspace::<f64>();
    p.constraints
        .eval(&mut cws, p.t0, &p.q0, &p.v0, &vec![0.0; nv], &mut h);
    if g.iter().chain(&f).chain(&h).all(|x| x.is_finite()) {
        return Ok(());
    }
    // Blame the largest initial value the file gives (velocities first), else the table.
    let init = file.initial.get_ref();
    let largest = |what: &str, map: &BTreeMap<String, Spanned<Initial>>| {
        map.iter()
            .filter_map(|(k, x)| {
                let m = match x.get_ref() {
                    Initial::One(Number::Value(v)) => v.abs(),
                    Initial::Many(vs) => vs
                        .iter()
                        .map(|n| match n {
                            Number::Value(v) => v.abs(),
                            Number::Expr(_) => 0.0,
                        })
                        .fold(0.0, f64::max),
                    _ => 0.0,
                };
                (m > 1e100).then(|| (m, format!("initial.{what}.{k}"), x.span()))
            })
            .max_by(|a, b| a.0.total_cmp(&b.0))
    };
    let message = "the forces or the rows overflow (are not finite) at the initial state";
    Err(
        match largest("v", &init.v).or_else(|| largest("q", &init.q)) {
            Some((m, field, span)) => {
                src.error(span, &field, format!("{m:e} is too large: {message}"))
            }
            None => src.error(file.initial.span(), "initial", message),
        },
    )
}

/// Acceleration-level rows must be linear in dv/dt (checked at the initial state).
fn check_acceleration_rows<M: Model, C: Constraints>(
    src: &Source,
    p: &Problem<M, C>,
    spans: &[Range<usize>],
    n_system: usize,
) -> R<()> {
    let rows = p.constraints.rows();
    if !rows.iter().any(|r| r.level == Level::Acceleration) {
        return Ok(());
    }
    let nv = p.model.nv();
    let mut ws = p.constraints.workspace::<f64>();
    let mut h0 = vec![0.0; rows.len()];
    let mut h1 = vec![0.0; rows.len()];
    let mut h2 = vec![0.0; rows.len()];
    let mut a = vec![0.0; nv];
    p.constraints.eval(&mut ws, p.t0, &p.q0, &p.v0, &a, &mut h0);
    for j in 0..nv {
        a[j] = 1.0;
        p.constraints.eval(&mut ws, p.t0, &p.q0, &p.v0, &a, &mut h1);
        a[j] = 2.0;
        p.constraints.eval(&mut ws, p.t0, &p.q0, &p.v0, &a, &mut h2);
        a[j] = 0.0;
        for (i, r) in rows.iter().enumerate() {
            if r.level != Level::Acceleration {
                continue;
            }
            let scale = h0[i].abs().max(h1[i].abs()).max(h2[i].abs()).max(1.0);
            if (h2[i] - 2.0 * h1[i] + h0[i]).abs() > 1e-9 * scale {
                let field = if i < n_system {
                    format!("constraints[{i}].expr")
                } else {
                    format!("programme[{}].expr", i - n_system)
                };
                return Err(src.error(
                    spans[i].clone(),
                    &field,
                    "an acceleration-level row must be linear in the accelerations",
                ));
            }
        }
    }
    Ok(())
}
