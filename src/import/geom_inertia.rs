//! MuJoCo's mass properties of primitive geoms and of a body from its geoms, as its compiler
//! computes them (`mjCGeom::GetVolume`, `mjCGeom::SetInertia`, `mjCBody::InertiaFromGeom`,
//! the `boundmass` / `boundinertia` clamp of `mjCBody::Compile`). Sizes are MuJoCo's: radii and
//! half-lengths; the geom's own axis is z.

use nalgebra::{Matrix3, SymmetricEigen, UnitQuaternion, Vector3};
use std::f64::consts::PI;

/// MuJoCo's `mjEPS`: geoms of no more mass do not count, volumes of no more are none.
pub(crate) const MJ_EPS: f64 = 1e-14;

/// A primitive geom type with a closed-form volume and inertia.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Shape {
    Sphere,
    Capsule,
    Cylinder,
    Ellipsoid,
    Box,
}

impl Shape {
    pub(crate) fn parse(s: &str) -> Option<Shape> {
        Some(match s {
            "sphere" => Shape::Sphere,
            "capsule" => Shape::Capsule,
            "cylinder" => Shape::Cylinder,
            "ellipsoid" => Shape::Ellipsoid,
            "box" => Shape::Box,
            _ => return None,
        })
    }

    /// How many `size` numbers the shape reads (MuJoCo's `checksize`).
    pub(crate) fn sizes(self) -> usize {
        match self {
            Shape::Sphere => 1,
            Shape::Capsule | Shape::Cylinder => 2,
            Shape::Ellipsoid | Shape::Box => 3,
        }
    }
}

/// The volume of a solid geom, or its surface area for `shell` (`shellinertia="true"`; the
/// ellipsoid's by Knud Thomsen's approximation, p = 1.6075, as MuJoCo).
pub(crate) fn volume(shape: Shape, s: [f64; 3], shell: bool) -> f64 {
    let (r, h) = (s[0], 2.0 * s[1]);
    match (shape, shell) {
        (Shape::Sphere, false) => 4.0 * PI * r * r * r / 3.0,
        (Shape::Sphere, true) => 4.0 * PI * r * r,
        (Shape::Capsule, false) => PI * (r * r * h + 4.0 * r * r * r / 3.0),
        (Shape::Capsule, true) => 4.0 * PI * r * r + 2.0 * PI * r * h,
        (Shape::Cylinder, false) => PI * r * r * h,
        (Shape::Cylinder, true) => 2.0 * PI * r * r + 2.0 * PI * r * h,
        (Shape::Ellipsoid, false) => 4.0 * PI * s[0] * s[1] * s[2] / 3.0,
        (Shape::Ellipsoid, true) => {
            let p = 1.6075;
            let t = (s[0] * s[1]).powf(p) + (s[1] * s[2]).powf(p) + (s[2] * s[0]).powf(p);
            4.0 * PI * (t / 3.0).powf(1.0 / p)
        }
        (Shape::Box, false) => 8.0 * s[0] * s[1] * s[2],
        (Shape::Box, true) => 8.0 * (s[0] * s[1] + s[1] * s[2] + s[2] * s[0]),
    }
}

/// The principal moments about the geom's centre, in its frame, of a geom of mass `m`.
pub(crate) fn principal(shape: Shape, s: [f64; 3], m: f64, shell: bool) -> [f64; 3] {
    let [a2, b2, c2] = s.map(|x| x * x);
    match (shape, shell) {
        (Shape::Sphere, false) => [2.0 * m * a2 / 5.0; 3],
        (Shape::Sphere, true) => [2.0 * m * a2 / 3.0; 3],
        (Shape::Capsule, _) => capsule(s[0], s[1], m, shell),
        (Shape::Cylinder, false) => {
            let (r, h) = (s[0], 2.0 * s[1]);
            let t = m * (3.0 * r * r + h * h) / 12.0;
            [t, t, m * r * r / 2.0]
        }
        (Shape::Cylinder, true) => cylinder_shell(s[0], s[1], m),
        (Shape::Ellipsoid, false) => [
            m * (b2 + c2) / 5.0,
            m * (a2 + c2) / 5.0,
            m * (a2 + b2) / 5.0,
        ],
        (Shape::Ellipsoid, true) => ellipsoid_shell(s, m),
        (Shape::Box, false) => [
            m * (b2 + c2) / 3.0,
            m * (a2 + c2) / 3.0,
            m * (a2 + b2) / 3.0,
        ],
        (Shape::Box, true) => box_shell(s, m),
    }
}

/// A capsule: a cylinder of height h = 2 s[1] and two hemispheres of radius r, the mass split by
/// volume (solid: sphere mass m 4r/(4r + 3h)) or by area (shell); each hemisphere's moment about
/// x is moved from its centre of mass to the capsule's (MuJoCo's `SetInertia`).
fn capsule(r: f64, half: f64, m: f64, shell: bool) -> [f64; 3] {
    let h = 2.0 * half;
    if shell {
        let sphere_area = 4.0 * PI * r * r;
        let ms = m * sphere_area / (sphere_area + 2.0 * PI * r * h);
        let mc = m - ms;
        let (hs_com, hs_pos) = (r / 2.0, half + r / 2.0);
        let x = mc * (6.0 * r * r + h * h) / 12.0
            + 2.0 * ms * r * r / 3.0
            + ms * (hs_pos * hs_pos - hs_com * hs_com);
        return [x, x, mc * r * r + 2.0 * ms * r * r / 3.0];
    }
    let ms = m * 4.0 * r / (4.0 * r + 3.0 * h);
    let mc = m - ms;
    let sphere = 2.0 * ms * r * r / 5.0;
    let x = mc * (3.0 * r * r + h * h) / 12.0 + sphere + ms * h * (3.0 * r + 2.0 * h) / 8.0;
    [x, x, mc * r * r / 2.0 + sphere]
}

/// A cylinder's surface: the tube and two disks, the mass split by area.
fn cylinder_shell(r: f64, half: f64, m: f64) -> [f64; 3] {
    let h = 2.0 * half;
    let disk = PI * r * r;
    let md = m * disk / (2.0 * disk + 2.0 * PI * r * h);
    let mc = m - 2.0 * md;
    let x = mc * (6.0 * r * r + h * h) / 12.0 + 2.0 * (md * r * r / 4.0 + md * half * half);
    [x, x, mc * r * r + 2.0 * (md * r * r / 2.0)]
}

/// An ellipsoid's surface: the solid with semi-axes + 1e-6 minus the solid, at the density that
/// gives the layer mass m.
fn ellipsoid_shell(s: [f64; 3], m: f64) -> [f64; 3] {
    let solid = |a: [f64; 3], mass: f64| {
        let [a2, b2, c2] = a.map(|x| x * x);
        [
            mass * (b2 + c2) / 5.0,
            mass * (a2 + c2) / 5.0,
            mass * (a2 + b2) / 5.0,
        ]
    };
    let e = s.map(|x| x + 1e-6);
    let (va, vb) = (
        4.0 * PI * s[0] * s[1] * s[2] / 3.0,
        4.0 * PI * e[0] * e[1] * e[2] / 3.0,
    );
    let density = m / (vb - va);
    let (ia, ib) = (solid(s, va * density), solid(e, vb * density));
    [ib[0] - ia[0], ib[1] - ia[1], ib[2] - ia[2]]
}

/// A box's surface: three pairs of faces, the mass split by area, each face a thin plate moved
/// to the box's centre.
fn box_shell(s: [f64; 3], m: f64) -> [f64; 3] {
    let [s00, s11, s22] = s.map(|x| x * x);
    let [lx, ly, lz] = s.map(|x| 2.0 * x);
    let (a0, a1, a2) = (lx * ly, ly * lz, lz * lx);
    let total = 2.0 * (a0 + a1 + a2);
    let (m0, m1, m2) = (m * a0 / total, m * a1 / total, m * a2 / total);
    let i0 = [m0 * ly * ly, m0 * lx * lx, m0 * (lx * lx + ly * ly)].map(|x| x / 12.0);
    let i1 = [m1 * (ly * ly + lz * lz), m1 * lz * lz, m1 * ly * ly].map(|x| x / 12.0);
    let i2 = [m2 * lz * lz, m2 * (lx * lx + lz * lz), m2 * lx * lx].map(|x| x / 12.0);
    [
        2.0 * (m0 * s22 + m2 * s11 + i0[0] + i1[0] + i2[0]),
        2.0 * (m0 * s22 + m1 * s00 + i0[1] + i1[1] + i2[1]),
        2.0 * (m1 * s00 + m2 * s11 + i0[2] + i1[2] + i2[2]),
    ]
}

/// Mass properties in a body frame: mass, centre of mass, inertia about it.
#[derive(Clone, Debug)]
pub(crate) struct MassProps {
    pub mass: f64,
    pub com: Vector3<f64>,
    pub inertia: Matrix3<f64>,
}

/// One geom's share: its mass, its centre (the geom frame's origin) and its principal moments
/// in the geom frame `rot`.
pub(crate) struct GeomMass {
    pub mass: f64,
    pub pos: Vector3<f64>,
    pub rot: UnitQuaternion<f64>,
    pub principal: [f64; 3],
}

/// The body's mass properties from its geoms (`InertiaFromGeom`): the geoms of more than
/// [`MJ_EPS`] mass counted; the masses summed, the centre of mass their weighted mean, the
/// inertia sum_i R_i diag(I_i) R_i^T + m_i (|d_i|^2 1 - d_i d_i^T), d_i = p_i - com (parallel
/// axes). `None` when no geom counts (MuJoCo leaves the body's inertial unset).
pub(crate) fn combine(geoms: &[GeomMass]) -> Option<MassProps> {
    let sel: Vec<&GeomMass> = geoms.iter().filter(|g| g.mass > MJ_EPS).collect();
    let mass: f64 = sel.iter().map(|g| g.mass).sum();
    if sel.is_empty() {
        return None;
    }
    let com = if sel.len() == 1 {
        sel[0].pos
    } else {
        sel.iter().map(|g| g.pos * g.mass).sum::<Vector3<f64>>() / mass
    };
    let mut inertia = Matrix3::zeros();
    for g in sel {
        let r = g.rot.to_rotation_matrix();
        let local = Matrix3::from_diagonal(&Vector3::from(g.principal));
        inertia += Matrix3::from(super::rotate_inertia(r.matrix(), &local));
        let d = g.pos - com;
        inertia += g.mass * (Matrix3::identity() * d.norm_squared() - d * d.transpose());
    }
    Some(MassProps { mass, com, inertia })
}

/// `boundmass` / `boundinertia`: mass = max(mass, boundmass), each principal moment =
/// max(moment, boundinertia) (the tensor rebuilt from its principal axes); unchanged when both
/// bounds are 0.
pub(crate) fn bound(p: MassProps, boundmass: f64, boundinertia: f64) -> MassProps {
    let mass = p.mass.max(boundmass);
    if boundinertia <= 0.0 {
        return MassProps { mass, ..p };
    }
    let eig = SymmetricEigen::new(p.inertia);
    if eig.eigenvalues.iter().all(|&x| x >= boundinertia) {
        return MassProps { mass, ..p };
    }
    let clamped = eig.eigenvalues.map(|x| x.max(boundinertia));
    let inertia = Matrix3::from(super::rotate_inertia(
        &eig.eigenvectors,
        &Matrix3::from_diagonal(&clamped),
    ));
    MassProps { mass, inertia, ..p }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) {
        assert!((a - b).abs() <= 1e-14 * b.abs().max(1.0), "{a} vs {b}");
    }

    #[test]
    fn closed_forms() {
        let m = 2.5;
        let [x, y, z] = principal(Shape::Sphere, [0.3, 0.0, 0.0], m, false);
        for v in [x, y, z] {
            close(v, 0.4 * m * 0.09);
        }
        let [x, y, z] = principal(Shape::Box, [0.1, 0.2, 0.3], m, false);
        // m/12 (b^2 + c^2) with full lengths b = 0.4, c = 0.6
        close(x, m / 12.0 * (0.16 + 0.36));
        close(y, m / 12.0 * (0.04 + 0.36));
        close(z, m / 12.0 * (0.04 + 0.16));
        let [x, _, z] = principal(Shape::Cylinder, [0.1, 0.5, 0.0], m, false);
        close(x, m * (3.0 * 0.01 + 1.0) / 12.0);
        close(z, m * 0.01 / 2.0);
        close(
            volume(Shape::Ellipsoid, [0.1, 0.2, 0.3], false),
            4.0 * PI * 0.006 / 3.0,
        );
    }

    /// The capsule: a cylinder plus two hemispheres by direct integration (hemisphere moment
    /// about its base diameter 2/5 m r^2, moved by the base offset h/2).
    #[test]
    fn capsule_by_parts() {
        let (r, half, rho) = (0.1, 0.3, 1000.0);
        let h = 2.0 * half;
        let mc = rho * PI * r * r * h;
        let mh = rho * 2.0 * PI * r * r * r / 3.0; // one hemisphere
        let m = mc + 2.0 * mh;
        close(volume(Shape::Capsule, [r, half, 0.0], false) * rho, m);
        let hemi_com = 3.0 * r / 8.0;
        // about its own centre of mass, then moved to the capsule's centre (h/2 + 3r/8)
        let hemi_x =
            2.0 * mh * r * r / 5.0 - mh * hemi_com * hemi_com + mh * (half + hemi_com).powi(2);
        let x = mc * (3.0 * r * r + h * h) / 12.0 + 2.0 * hemi_x;
        let z = mc * r * r / 2.0 + 2.0 * 2.0 * mh * r * r / 5.0;
        let [px, py, pz] = principal(Shape::Capsule, [r, half, 0.0], m, false);
        close(px, x);
        close(py, x);
        close(pz, z);
    }

    #[test]
    fn two_spheres_parallel_axes() {
        let g = |x: f64| GeomMass {
            mass: 1.0,
            pos: Vector3::new(x, 0.0, 0.0),
            rot: UnitQuaternion::identity(),
            principal: [0.1; 3],
        };
        let p = combine(&[g(-1.0), g(1.0)]).unwrap();
        close(p.mass, 2.0);
        assert_eq!(p.com, Vector3::zeros());
        close(p.inertia[(0, 0)], 0.2);
        close(p.inertia[(1, 1)], 2.2);
        close(p.inertia[(2, 2)], 2.2);
        let b = bound(p, 3.0, 0.5);
        close(b.mass, 3.0);
        close(b.inertia[(0, 0)], 0.5);
        close(b.inertia[(1, 1)], 2.2);
        assert!(combine(&[GeomMass {
            mass: 0.0,
            ..g(0.0)
        }])
        .is_none());
    }
}
