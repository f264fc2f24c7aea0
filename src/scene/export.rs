//! A scene's simulator model: the tree export of `crate::export` plus the scene's own elements
//! (expression forces), or a refusal naming what no simulator document can carry. Every door
//! (`progmo export`, the binding, the check) goes through [`Scene::export`], so a check can never
//! replay a model that silently lost a force or a constraint.

use super::{Scene, SceneSystem};
use crate::export::{
    self, ClosureExport, ExportError, ExportOptions, ExportReport, Format, HarnessForce,
};
use crate::programme::Role;

/// Closure kinds the simulators hold (MuJoCo equalities, Pinocchio constraint models); the rows of
/// the others are supplied by [`Scene::export_supplying`].
pub const HELD_CLOSURES: [&str; 2] = ["point", "weld"];

impl Scene {
    /// Export the scene's model to `format`. The report lists, besides the tree's own harness
    /// forces, every expression force of the scene ([`HarnessForce::PointForce`],
    /// [`HarnessForce::CoordinateForce`]). Refused with [`ExportError::Unsupported`] naming the
    /// element: lagrangian models (no bodies to export) and system constraints of tree scenes
    /// other than loop closures (simulators would not enforce them). Loop closures
    /// (`[[model.closures]]`) are exported ([`ClosureExport`]: MuJoCo equalities, Pinocchio
    /// frames the harness joins with constraint models), listed in the report with their rows.
    pub fn export(
        &self,
        format: Format,
        options: &ExportOptions,
    ) -> Result<(String, ExportReport), ExportError> {
        self.export_route(format, options, false)
    }

    /// Export with the reactions of the system rows no simulator holds supplied by progmo: those
    /// rows (expression `[[constraints]]`, nonholonomic or not, and the rows of `distance`,
    /// `line`, `plane` and `rolling` closures) are left out of the document, and the report lists
    /// them as one [`HarnessForce::SuppliedReaction`]: the harness applies their generalized
    /// reaction B_s^T lambda_s from the solver as a coordinate force, so the rest of the model
    /// (inertia, forces, programme, the closures the simulator does hold) is still checked. Without
    /// such rows it is [`Scene::export`]; lagrangian models are refused as there.
    pub fn export_supplying(
        &self,
        format: Format,
        options: &ExportOptions,
    ) -> Result<(String, ExportReport), ExportError> {
        self.export_route(format, options, true)
    }

    fn export_route(
        &self,
        format: Format,
        options: &ExportOptions,
        supply: bool,
    ) -> Result<(String, ExportReport), ExportError> {
        let p = match &self.system {
            SceneSystem::Tree(p) => p,
            SceneSystem::Lagrangian(_) => {
                return Err(ExportError::Unsupported {
                    format,
                    what: "a lagrangian model (a mass matrix and forces given as expressions): \
                           no MJCF/URDF element describes it"
                        .into(),
                })
            }
        };
        let all = self.closure_exports();
        let (closures, left_out): (Vec<ClosureExport>, Vec<ClosureExport>) = if supply {
            all.into_iter()
                .partition(|c| HELD_CLOSURES.contains(&c.kind.as_str()))
        } else {
            (all, vec![])
        };
        let closure_rows: Vec<&String> = closures.iter().flat_map(|c| &c.rows).collect();
        let system: Vec<String> = self
            .rows()
            .into_iter()
            .filter(|r| r.role == Role::System && !closure_rows.contains(&&r.name))
            .map(|r| r.name)
            .collect();
        let supplied = if supply && !system.is_empty() {
            let mut why = vec![];
            let in_closures: Vec<&String> = left_out.iter().flat_map(|c| &c.rows).collect();
            let plain: Vec<String> = system
                .iter()
                .filter(|r| !in_closures.contains(r))
                .cloned()
                .collect();
            if !plain.is_empty() {
                why.push(format!(
                    "system constraints {} (no simulator element holds an expression row)",
                    crate::solve::quoted(&plain)
                ));
            }
            for c in &left_out {
                why.push(format!(
                    "{} closure `{}` ({})",
                    c.kind,
                    c.name,
                    match c.kind.as_str() {
                        "distance" => "MuJoCo's tendon equality leaves out its curvature term;                                        no Pinocchio constraint model",
                        "rolling" => "no rolling contact in MuJoCo or Pinocchio",
                        _ => "no such equality in MuJoCo, no such constraint model in Pinocchio",
                    }
                ));
            }
            Some(HarnessForce::SuppliedReaction {
                rows: system.clone(),
                reason: why.join("; "),
            })
        } else {
            None
        };
        if !system.is_empty() && supplied.is_none() {
            return Err(ExportError::Unsupported {
                format,
                what: format!(
                    "system constraints ({}): the exported model would not enforce them",
                    crate::solve::quoted(&system)
                ),
            });
        }
        let tree = p.model.tree();
        let (doc, mut report) = match format {
            Format::Mjcf => export::mjcf_closed(tree, &closures, options)?,
            Format::Urdf => export::urdf_closed(tree, &closures, options)?,
        };
        let bodies = tree.bodies();
        for (index, pf) in p.model.point_forces().iter().enumerate() {
            report.harness_forces.push(HarnessForce::PointForce {
                index,
                body: bodies[pf.body].name.clone(),
                point: pf.point,
                force: [0, 1, 2].map(|k| pf.force[k].source().to_string()),
            });
        }
        let v_names = tree.v_names();
        for (i, e) in p.model.coordinate_forces() {
            report.harness_forces.push(HarnessForce::CoordinateForce {
                v_name: v_names[*i].clone(),
                expr: e.source().to_string(),
            });
        }
        report.harness_forces.extend(supplied);
        Ok((doc, report))
    }

    /// The scene's loop closures as the exporters take them (site names `NAME__a`, `NAME__b`, the
    /// synthetic sites of the rows; rows set aside at t0 listed).
    pub fn closure_exports(&self) -> Vec<ClosureExport> {
        let aside: Vec<&str> = self
            .set_aside
            .iter()
            .flat_map(|(s, _)| s.iter().map(|a| a.row.as_str()))
            .collect();
        self.closures
            .iter()
            .map(|c| {
                let rows: Vec<String> = c.rows().into_iter().map(|(n, _)| n).collect();
                ClosureExport {
                    name: c.name.clone(),
                    kind: c.kind.name().into(),
                    body_a: c.body_a.clone(),
                    point_a: c.point_a,
                    quat_a: c.quat_a,
                    body_b: c.body_b.clone(),
                    point_b: c.point_b,
                    quat_b: c.quat_b,
                    distance: c.distance,
                    axis: c.axis,
                    site_a: super::closures::site_name(&c.name, 'a'),
                    site_b: super::closures::site_name(&c.name, 'b'),
                    set_aside: rows
                        .iter()
                        .filter(|r| aside.contains(&r.as_str()))
                        .cloned()
                        .collect(),
                    rows,
                }
            })
            .collect()
    }
}
