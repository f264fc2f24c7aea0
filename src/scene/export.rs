//! A scene's simulator model: the tree export of `crate::export` plus the scene's own elements
//! (expression forces), or a refusal naming what no simulator document can carry. Every door
//! (`progmo export`, the binding, the check) goes through [`Scene::export`], so a check can never
//! replay a model that silently lost a force or a constraint.

use super::{Scene, SceneSystem};
use crate::export::{
    self, ClosureExport, ExportError, ExportOptions, ExportReport, Format, HarnessForce,
};
use crate::programme::Role;

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
        let closures = self.closure_exports();
        let closure_rows: Vec<&String> = closures.iter().flat_map(|c| &c.rows).collect();
        let system: Vec<String> = self
            .rows()
            .into_iter()
            .filter(|r| r.role == Role::System && !closure_rows.contains(&&r.name))
            .map(|r| r.name)
            .collect();
        if !system.is_empty() {
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
