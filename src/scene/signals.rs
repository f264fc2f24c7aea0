//! Body-point signals of tree scenes: the expressions' view of named sites.
//!
//! A site `tip` (a point fixed in a body) offers `tip.x`, `tip.y`, `tip.z` (world position), their
//! time derivatives `tip.x'` (velocity) and `tip.x''` (acceleration), the body orientation
//! `tip.qw`, `tip.qx`, `tip.qy`, `tip.qz` (unit quaternion, body to world) and the world angular
//! velocity `tip.wx`, `tip.wy`, `tip.wz` with derivative `tip.wx'`. Only the signals a scene uses
//! are computed, by the tree's forward kinematics over the same scalar type as everything else
//! (so their derivatives are exact).

use crate::programme::Level;
use crate::scalar::Scalar;
use crate::tree::{self, TreeData};
use nalgebra::Vector3;
use std::sync::Arc;

/// What a signal measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quantity {
    /// World position component (0..3) and its time derivatives (order 0, 1, 2).
    Position { axis: usize, order: u8 },
    /// Body orientation quaternion component (w, x, y, z).
    Orientation { k: usize },
    /// World angular velocity component (order 0) or angular acceleration (order 1).
    Angular { axis: usize, order: u8 },
}

impl Quantity {
    /// Level of a row that reads this signal.
    pub fn level(&self) -> Level {
        let o = match *self {
            Quantity::Position { order, .. } => order,
            Quantity::Orientation { .. } => 0,
            Quantity::Angular { order, .. } => order + 1,
        };
        match o {
            0 => Level::Position,
            1 => Level::Velocity,
            _ => Level::Acceleration,
        }
    }

    /// Parse the part of a signal name after `site.`: `x`, `y'`, `qw`, `wz'`...
    pub fn parse(component: &str) -> Option<Quantity> {
        let order = component.bytes().rev().take_while(|&b| b == b'\'').count() as u8;
        let base = component.trim_end_matches('\'');
        let axis = |c: &str| match c {
            "x" => Some(0),
            "y" => Some(1),
            "z" => Some(2),
            _ => None,
        };
        if let Some(a) = axis(base) {
            return (order <= 2).then_some(Quantity::Position { axis: a, order });
        }
        if let Some(rest) = base.strip_prefix('w') {
            if let Some(a) = axis(rest) {
                return (order <= 1).then_some(Quantity::Angular { axis: a, order });
            }
        }
        if order == 0 {
            return match base {
                "qw" => Some(Quantity::Orientation { k: 0 }),
                "qx" => Some(Quantity::Orientation { k: 1 }),
                "qy" => Some(Quantity::Orientation { k: 2 }),
                "qz" => Some(Quantity::Orientation { k: 3 }),
                _ => None,
            };
        }
        None
    }
}

/// A named site: a point fixed in a body.
#[derive(Clone, Debug, PartialEq)]
pub struct Site {
    pub name: String,
    pub body: usize,
    pub pos: [f64; 3],
}

/// The signals a scene's expressions read, in slot order.
#[derive(Clone, Debug, Default)]
pub struct Signals {
    tree: Option<Arc<tree::Model>>,
    sites: Vec<Site>,
    /// (site index, quantity) per signal slot.
    list: Vec<(usize, Quantity)>,
}

/// Scratch for computing signals.
pub struct SignalWork<S: Scalar> {
    data: Option<TreeData<S>>,
}

impl Signals {
    /// No signals (Lagrangian scenes).
    pub fn none() -> Self {
        Signals::default()
    }

    /// Signals on `sites` of `tree`; add them with [`Signals::push`].
    pub fn new(tree: Arc<tree::Model>, sites: Vec<Site>) -> Self {
        Signals {
            tree: Some(tree),
            sites,
            list: vec![],
        }
    }

    /// The sites.
    pub fn sites(&self) -> &[Site] {
        &self.sites
    }

    /// Resolve a name `site.component`; returns its quantity if it names a signal.
    pub fn resolve(&self, name: &str) -> Option<(usize, Quantity)> {
        let (site, comp) = name.split_once('.')?;
        let i = self.sites.iter().position(|s| s.name == site)?;
        Quantity::parse(comp).map(|q| (i, q))
    }

    /// Add a signal; returns its index among the signals.
    pub fn push(&mut self, site: usize, q: Quantity) -> usize {
        self.list.push((site, q));
        self.list.len() - 1
    }

    /// Quantity of signal `k`.
    pub fn quantity(&self, k: usize) -> Quantity {
        self.list[k].1
    }

    /// Number of signal slots.
    pub fn len(&self) -> usize {
        self.list.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    /// Allocate scratch.
    pub fn work<S: Scalar>(&self) -> SignalWork<S> {
        SignalWork {
            data: self.tree.as_ref().map(|t| t.data::<S>()),
        }
    }

    /// Compute all signals at (q, v, a) into `out`.
    pub fn fill<S: Scalar>(&self, w: &mut SignalWork<S>, q: &[S], v: &[S], a: &[S], out: &mut [S]) {
        let (Some(tree), Some(data)) = (&self.tree, &mut w.data) else {
            return;
        };
        for (k, &(si, quantity)) in self.list.iter().enumerate() {
            let site = &self.sites[si];
            let p = Vector3::new(
                S::from(site.pos[0]),
                S::from(site.pos[1]),
                S::from(site.pos[2]),
            );
            out[k] = match quantity {
                Quantity::Position { axis, order: 0 } => {
                    tree::point_position(tree, data, q, site.body, &p)[axis]
                }
                Quantity::Position { axis, order: 1 } => {
                    tree::point_velocity(tree, data, q, v, site.body, &p)[axis]
                }
                Quantity::Position { axis, .. } => {
                    tree::point_acceleration(tree, data, q, v, a, site.body, &p).0[axis]
                }
                Quantity::Orientation { k } => tree::body_quaternion(tree, data, q, site.body)[k],
                Quantity::Angular { axis, order: 0 } => {
                    tree::body_angular_velocity(tree, data, q, v, site.body)[axis]
                }
                Quantity::Angular { axis, .. } => {
                    tree::point_acceleration(tree, data, q, v, a, site.body, &p).1[axis]
                }
            };
        }
    }
}
