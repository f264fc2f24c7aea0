//! A scene's simulator model: the tree export of `crate::export` plus the scene's own elements
//! (expression forces), or a refusal naming what no simulator document can carry. Every door
//! (`progmo export`, the binding, the check) goes through [`Scene::export`], so a check can never
//! replay a model that silently lost a force or a constraint.

use super::{Scene, SceneSystem};
use crate::export::{self, ExportError, ExportOptions, ExportReport, Format, HarnessForce};
use crate::programme::Role;

impl Scene {
    /// Export the scene's model to `format`. The report lists, besides the tree's own harness
    /// forces, every expression force of the scene ([`HarnessForce::PointForce`],
    /// [`HarnessForce::CoordinateForce`]). Refused with [`ExportError::Unsupported`] naming the
    /// element: lagrangian models (no bodies to export) and system constraints of tree scenes
    /// (simulators would not enforce them).
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
        let system: Vec<String> = self
            .rows()
            .into_iter()
            .filter(|r| r.role == Role::System)
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
            Format::Mjcf => export::mjcf(tree, options)?,
            Format::Urdf => export::urdf(tree, options)?,
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
}
