//! Mesh geoms' mass properties as MuJoCo's compiler computes them, so that a body weighed by its
//! meshes has the inertia MuJoCo simulates with (read from MuJoCo's `user_mesh.cc` and
//! `mjCGeom::SetInertia`; checked against MuJoCo 4.0 by tests/python/test_robot_files_mujoco.py):
//!
//! 1. vertices: the file's float32 numbers (STL binary, MuJoCo's MSH, OBJ) or the `vertex`
//!    attribute, held in double; `refpos` subtracted, rotated by `refquat`^-1, times `scale`;
//! 2. the area-weighted centroid c_f of the faces;
//! 3. the centre of mass from the pyramids on each face with apex c_f (the area and its pyramid
//!    centre 3/4 c + 1/4 c_f per face for `inertia="shell"`); `legacy` (MuJoCo's default) takes
//!    each pyramid's volume unsigned, `exact` signed (and refuses inconsistently oriented faces);
//! 4. the second moments from the pyramids with apex at that centre (tetrahedron formula, /20;
//!    triangle formula /12 for a shell), whose volume (area) is the one the geom's mass uses;
//! 5. principal moments e_0 >= e_1 >= e_2 and axes (the mesh frame) by MuJoCo's own Jacobi
//!    iteration and tolerance ([`eig3`]: up to 1e-7 short of exact, as MuJoCo); the geom's inertia is that
//!    of the equivalent box b_i = sqrt(6 (e_j + e_k - e_i) / V) / 2, I_i = m (b_j^2 + b_k^2) / 3,
//!    and a primitive geom naming a mesh is fitted to that box (`fitaabb="false"`, the default).
//!
//! `inertia="convex"` weighs the convex hull of the vertices instead (signed volumes, steps 3 and
//! 4 over the hull's triangles, the centroid of step 2 still over the mesh's faces, as MuJoCo);
//! a mesh given without faces takes its hull's triangles as its faces ([`super::hull`]).

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

/// MuJoCo's `mjMINVAL`: smaller faces count as none; smaller areas and volumes are refused.
const MJ_MINVAL: f64 = 1e-15;

/// `<mesh inertia>`: how the mesh is weighed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum MeshInertia {
    /// pyramid volumes taken unsigned (MuJoCo's default)
    Legacy,
    /// signed volumes: right for any closed, consistently oriented mesh
    Exact,
    /// mass on the surface
    Shell,
    /// the convex hull's volume, signed
    Convex,
}

impl MeshInertia {
    pub(crate) fn parse(s: &str) -> Result<Self, String> {
        match s {
            "legacy" => Ok(Self::Legacy),
            "exact" => Ok(Self::Exact),
            "shell" => Ok(Self::Shell),
            "convex" => Ok(Self::Convex),
            o => Err(format!(
                "`inertia=\"{o}\"`: expected legacy, exact, shell or convex"
            )),
        }
    }
}

/// A triangle mesh: vertices (double, from float32 numbers) and faces (indices, counter-clockwise
/// seen from outside).
#[derive(Debug)]
pub(crate) struct Mesh {
    pub vert: Vec<[f64; 3]>,
    pub face: Vec<[usize; 3]>,
}

/// A mesh's mass properties at unit density, in the frame its vertices are given in after
/// `refpos`, `refquat` and `scale` (MuJoCo's mesh `pos_`, `quat_`, `boxsz_`, volume).
#[derive(Clone, Debug)]
pub(crate) struct MeshMass {
    /// The volume (the area for a shell): the geom's mass is density times this.
    pub measure: f64,
    /// The centre of mass.
    pub com: Vector3<f64>,
    /// The principal axes (columns in the order of `boxsz`).
    pub rot: UnitQuaternion<f64>,
    /// The equivalent inertia box's half-sizes, principal moments in decreasing order.
    pub boxsz: [f64; 3],
}

impl MeshMass {
    /// The principal moments of a geom of mass `m` (`mjCGeom::SetInertia` for a mesh).
    pub(crate) fn principal(&self, m: f64) -> [f64; 3] {
        let b = self.boxsz.map(|x| x * x);
        [
            m * (b[1] + b[2]) / 3.0,
            m * (b[0] + b[2]) / 3.0,
            m * (b[0] + b[1]) / 3.0,
        ]
    }
}

/// Area, unit normal and centre of a triangle (MuJoCo's `triangle`: no area below `mjMINVAL`).
fn triangle(v1: &[f64; 3], v2: &[f64; 3], v3: &[f64; 3]) -> (f64, [f64; 3], [f64; 3]) {
    let center = [0, 1, 2].map(|i| (v1[i] + v2[i] + v3[i]) / 3.0);
    let b = [0, 1, 2].map(|i| v2[i] - v1[i]);
    let c = [0, 1, 2].map(|i| v3[i] - v1[i]);
    let n = [
        b[1] * c[2] - b[2] * c[1],
        b[2] * c[0] - b[0] * c[2],
        b[0] * c[1] - b[1] * c[0],
    ];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if len < MJ_MINVAL {
        return (0.0, n, center);
    }
    (0.5 * len, n.map(|x| x / len), center)
}

fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Faces sharing a directed edge: the first such edge (1-based vertices, as MuJoCo reports).
fn misoriented(vert: &[[f64; 3]], face: &[[usize; 3]]) -> Option<(usize, usize)> {
    let mut edges: Vec<(usize, usize)> = Vec::with_capacity(3 * face.len());
    for f in face {
        let [a, b, c] = f.map(|k| &vert[k]);
        if triangle(a, b, c).0 > MJ_MINVAL.sqrt() {
            edges.extend([(f[0], f[1]), (f[1], f[2]), (f[2], f[0])]);
        }
    }
    edges.sort_unstable();
    edges
        .windows(2)
        .find(|w| w[0] == w[1])
        .map(|w| (w[0].0 + 1, w[0].1 + 1))
}

/// `refpos`, `refquat` (normalized) and `scale` applied to the vertices, in MuJoCo's order.
pub(crate) fn transform(m: &mut Mesh, refpos: [f64; 3], refquat: [f64; 4], scale: [f64; 3]) {
    for v in &mut m.vert {
        for i in 0..3 {
            v[i] -= refpos[i];
        }
    }
    if refquat != [1.0, 0.0, 0.0, 0.0] {
        let q = nalgebra::Quaternion::new(refquat[0], refquat[1], refquat[2], refquat[3]);
        let r_inv = UnitQuaternion::from_quaternion(q)
            .to_rotation_matrix()
            .inverse();
        for v in &mut m.vert {
            *v = (r_inv * Vector3::from(*v)).into();
        }
    }
    for v in &mut m.vert {
        for i in 0..3 {
            v[i] *= scale[i];
        }
    }
}

/// The mass properties of a transformed mesh (steps 2 to 5 of the module docs); the error says why
/// MuJoCo would refuse the mesh.
pub(crate) fn mass(m: &Mesh, kind: MeshInertia) -> Result<MeshMass, String> {
    // a mesh without faces is its hull (MuJoCo's `CopyGraph`); `convex` weighs the hull
    let hull = if m.face.is_empty() || kind == MeshInertia::Convex {
        super::hull::hull(&m.vert)?
    } else {
        vec![]
    };
    let surface: &[[usize; 3]] = if m.face.is_empty() { &hull } else { &m.face };
    let solid: &[[usize; 3]] = if kind == MeshInertia::Convex {
        &hull
    } else {
        surface
    };
    if kind == MeshInertia::Exact {
        if let Some((a, b)) = misoriented(&m.vert, surface) {
            return Err(format!("faces have inconsistent orientation (the faces containing vertices {a} and {b}); MuJoCo refuses such a mesh with inertia=\"exact\""));
        }
    }
    let tri = |f: &[usize; 3]| triangle(&m.vert[f[0]], &m.vert[f[1]], &m.vert[f[2]]);
    // step 2: area-weighted face centroid
    let (mut fc, mut total_area) = ([0.0; 3], 0.0);
    for f in surface {
        let (area, _, c) = tri(f);
        for i in 0..3 {
            fc[i] += area * c[i];
        }
        total_area += area;
    }
    if total_area < MJ_MINVAL {
        return Err("the mesh's surface area is too small".into());
    }
    fc = fc.map(|x| x / total_area);
    // step 3: centre of mass from pyramids with apex fc
    let (mut com, mut total) = ([0.0; 3], 0.0);
    for f in solid {
        let (area, n, c) = tri(f);
        let w = match kind {
            MeshInertia::Shell => area,
            _ => {
                let vec = [c[0] - fc[0], c[1] - fc[1], c[2] - fc[2]];
                let v = dot(&vec, &n) * area / 3.0;
                if kind == MeshInertia::Legacy {
                    v.abs()
                } else {
                    v
                }
            }
        };
        total += w;
        for i in 0..3 {
            com[i] += w * (c[i] * 3.0 / 4.0 + fc[i] / 4.0);
        }
    }
    if total < MJ_MINVAL {
        return Err(match kind {
            MeshInertia::Shell => "the mesh's surface area is too small".into(),
            _ if total < 0.0 => "the mesh's volume is negative (misoriented triangles)".into(),
            _ => "the mesh's volume is too small (MuJoCo suggests inertia=\"shell\")".into(),
        });
    }
    com = com.map(|x| x / total);
    let (inert, measure) = second_moments(&m.vert, solid, kind, &com);
    principal_frame(inert, measure, com)
}

/// Step 4: the inertia about `com` at unit density and the volume (area) it recomputes.
fn second_moments(
    vert: &[[f64; 3]],
    faces: &[[usize; 3]],
    kind: MeshInertia,
    com: &[f64; 3],
) -> (Matrix3<f64>, f64) {
    let centred: Vec<[f64; 3]> = vert
        .iter()
        .map(|v| [v[0] - com[0], v[1] - com[1], v[2] - com[2]])
        .collect();
    const K: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)];
    let c = if kind == MeshInertia::Shell {
        12.0
    } else {
        20.0
    };
    let (mut p, mut total) = ([0.0; 6], 0.0);
    for f in faces {
        let [d, e, g] = f.map(|k| &centred[k]);
        let (area, n, cen) = triangle(d, e, g);
        let mut vol = match kind {
            MeshInertia::Shell => area,
            _ => dot(&cen, &n) * area / 3.0,
        };
        if kind == MeshInertia::Legacy {
            vol = vol.abs();
        }
        total += vol;
        for (j, &(a, b)) in K.iter().enumerate() {
            p[j] += vol / c
                * (2.0 * (d[a] * d[b] + e[a] * e[b] + g[a] * g[b])
                    + d[a] * e[b]
                    + d[b] * e[a]
                    + d[a] * g[b]
                    + d[b] * g[a]
                    + e[a] * g[b]
                    + e[b] * g[a]);
        }
    }
    let i = [p[1] + p[2], p[0] + p[2], p[0] + p[1], -p[3], -p[4], -p[5]];
    let full = Matrix3::new(i[0], i[3], i[4], i[3], i[1], i[5], i[4], i[5], i[2]);
    (full, total)
}

/// Step 5: principal moments (decreasing), axes and the equivalent box, with MuJoCo's checks.
/// The axes are MuJoCo 4.0's own ([`eig3`] with the compiler's tolerance 1e-7): they stop up to
/// about 1e-7 relative short of the exact ones, and a mesh body's inertia is what MuJoCo makes it.
fn principal_frame(inert: Matrix3<f64>, measure: f64, com: [f64; 3]) -> Result<MeshMass, String> {
    let (e, q) = eig3(&inert, MESH_EIG_TOL);
    if !(e[2] > 0.0) {
        return Err(format!(
            "an eigenvalue of the mesh's inertia is not positive ({:e})",
            e[2]
        ));
    }
    let (rtol, atol) = (1e-6, 1e-9);
    if e[1] + e[2] < e[0] * (1.0 - rtol) - atol
        || e[0] + e[2] < e[1] * (1.0 - rtol) - atol
        || e[0] + e[1] < e[2] * (1.0 - rtol) - atol
    {
        return Err(format!(
            "the principal moments of the mesh's inertia violate A + B >= C ({e:?})"
        ));
    }
    let rot = UnitQuaternion::new_normalize(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
    let b = |i: usize, j: usize, k: usize| 0.5 * (6.0 * (e[j] + e[k] - e[i]) / measure).sqrt();
    Ok(MeshMass {
        measure,
        com: Vector3::from(com),
        rot,
        boxsz: [b(0, 1, 2), b(1, 0, 2), b(2, 0, 1)],
    })
}

/// The relative tolerance MuJoCo 4.0's compiler gives its Jacobi iteration for a mesh's axes
/// (found by calling libmujoco's `mju_eig3Tol` on 201 random meshes and the test blob: 1e-7
/// reproduces every one of MuJoCo's mesh frames to 1e-14; 5e-8 and 2e-7 do not).
const MESH_EIG_TOL: f64 = 1e-7;

/// A symmetric 3x3 matrix's eigen-decomposition as MuJoCo 4.0's `mju_eig3Tol` computes it, to
/// the bit (read from libmujoco 4.0's machine code; equal on 4000 random and near-diagonal
/// matrices): Jacobi rotations on the largest off-diagonal element of D = R^T A R, accumulated as
/// a quaternion, until that element is at most max(`tol`, 4e-15) times the largest entry of A (at
/// most 500); then eigenvalues sorted decreasing by quarter turns (ties within 1e-12 max|A| kept).
/// The rotation's half angle comes from h = tan(phi/2) = t / (1 + sqrt(1 + t^2)), free of the
/// cancellation of sqrt((1 - cos phi) / 2) that once made small rotations differ from MuJoCo's
/// by 1e-10. Returns (eigenvalues, quaternion w x y z of R).
pub(crate) fn eig3(a: &Matrix3<f64>, tol: f64) -> ([f64; 3], [f64; 4]) {
    let big = a.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let stop = tol.max(4e-15) * big;
    let a: [[f64; 3]; 3] = [0, 1, 2].map(|i| [0, 1, 2].map(|j| a[(i, j)]));
    let mut q = [1.0, 0.0, 0.0, 0.0];
    let mut e = [0.0; 3];
    for _ in 0..500 {
        // D = (R^T A) R, each entry summed in index order (mju_mulMatTMat3, mju_mulMatMat3)
        let r = quat_mat(&q);
        let rta = [0, 1, 2]
            .map(|i| [0, 1, 2].map(|j| r[0][i] * a[0][j] + r[1][i] * a[1][j] + r[2][i] * a[2][j]));
        let d = [0, 1, 2].map(|i| {
            [0, 1, 2].map(|j| rta[i][0] * r[0][j] + rta[i][1] * r[1][j] + rta[i][2] * r[2][j])
        });
        e = [d[0][0], d[1][1], d[2][2]];
        let (o01, o02, o12) = (d[0][1].abs(), d[0][2].abs(), d[1][2].abs());
        let (rk, ck, rotk) = if o01 > o02 && o01 > o12 {
            (0, 1, 2)
        } else if o02 > o12 {
            (0, 2, 1)
        } else {
            (1, 2, 0)
        };
        let off = d[rk][ck];
        if off.abs() <= stop {
            break;
        }
        let tau = (d[ck][ck] - d[rk][rk]) / (2.0 * off);
        let root = (1.0 + tau * tau).sqrt();
        let t = if tau >= 0.0 {
            1.0 / (tau + root)
        } else {
            -1.0 / (root - tau)
        };
        let h = t / ((t * t + 1.0).sqrt() + 1.0);
        let ch = 1.0 / (h * h + 1.0).sqrt();
        let mut step = [ch, 0.0, 0.0, 0.0];
        step[rotk + 1] = if rotk == 1 { h * ch } else { -h * ch };
        q = normalize4(quat_mul(&q, &step));
    }
    let ties = 1e-12 * big;
    for j in 0..3 {
        let j1 = j % 2;
        if e[j1] + ties < e[j1 + 1] {
            e.swap(j1, j1 + 1);
            // MuJoCo's literal for cos(pi/4), one digit short of FRAC_1_SQRT_2: kept to match it
            #[allow(clippy::approx_constant)]
            let mut turn = [0.707106781186548, 0.0, 0.0, 0.0];
            turn[(j1 + 2) % 3 + 1] = turn[0];
            q = normalize4(quat_mul(&q, &turn));
        }
    }
    (e, q)
}

/// The rotation matrix (rows) of a unit quaternion (w, x, y, z), grouped as MuJoCo 4.0's
/// `mju_quat2Mat` computes it.
fn quat_mat(q: &[f64; 4]) -> [[f64; 3]; 3] {
    if *q == [1.0, 0.0, 0.0, 0.0] {
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    }
    let [w, x, y, z] = *q;
    let (q00, q01, q02, q03) = (w * w, w * x, w * y, w * z);
    let (q11, q12, q13, q22, q23, q33) = (x * x, x * y, x * z, y * y, y * z, z * z);
    [
        [
            (q00 - q22) + (q11 - q33),
            2.0 * (q12 - q03),
            2.0 * (q13 + q02),
        ],
        [
            2.0 * (q12 + q03),
            (q00 + q22) - (q11 + q33),
            2.0 * (q23 - q01),
        ],
        [
            2.0 * (q13 - q02),
            2.0 * (q23 + q01),
            (q00 - q22) - (q11 - q33),
        ],
    ]
}

/// Hamilton product p q.
fn quat_mul(p: &[f64; 4], q: &[f64; 4]) -> [f64; 4] {
    [
        p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
        p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2],
        p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1],
        p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0],
    ]
}

/// MuJoCo's `mju_normalize4`: left alone within 1e-15 of unit length, the identity below 1e-15.
fn normalize4(q: [f64; 4]) -> [f64; 4] {
    let n = ((q[0] * q[0] + q[1] * q[1]) + (q[2] * q[2] + q[3] * q[3])).sqrt();
    if n < MJ_MINVAL {
        [1.0, 0.0, 0.0, 0.0]
    } else if (n - 1.0).abs() > MJ_MINVAL {
        let inv = 1.0 / n;
        q.map(|x| x * inv)
    } else {
        q
    }
}

/// Vertices made one where their float32 numbers are equal (MuJoCo does so for STL files, whose
/// triangles list their corners each time); faces renumbered.
fn merge_repeated(vert: Vec<[f32; 3]>, face: &mut [[usize; 3]]) -> Vec<[f64; 3]> {
    let key = |v: &[f32; 3]| v.map(|x| if x == 0.0 { 0u32 } else { x.to_bits() });
    let mut index = std::collections::HashMap::new();
    let mut out = vec![];
    let mut map = Vec::with_capacity(vert.len());
    for v in &vert {
        let k = *index.entry(key(v)).or_insert_with(|| {
            out.push(v.map(f64::from));
            out.len() - 1
        });
        map.push(k);
    }
    for f in face.iter_mut() {
        *f = f.map(|k| map[k]);
    }
    out
}

/// Whether `scale` keeps the handedness (else faces are reversed, as MuJoCo does on loading).
fn righthand(scale: [f64; 3]) -> bool {
    scale[0] * scale[1] * scale[2] > 0.0
}

/// A binary STL file (MuJoCo reads no ASCII STL): 80-byte header, face count, 50 bytes a face.
pub(crate) fn stl(bytes: &[u8], scale: [f64; 3]) -> Result<Mesh, String> {
    if bytes.len() < 84 {
        return Err("too short for a binary STL header (84 bytes)".into());
    }
    let n = u32::from_le_bytes(bytes[80..84].try_into().unwrap()) as usize;
    if !(1..=200_000).contains(&n) {
        return Err(format!("{n} faces: a binary STL file has 1 to 200000 (MuJoCo's bound); perhaps this is an ASCII STL file, which MuJoCo does not read"));
    }
    if n * 50 != bytes.len() - 84 {
        return Err(format!("{} bytes for {n} faces (expected {}); perhaps this is an ASCII STL file, which MuJoCo does not read", bytes.len(), 84 + 50 * n));
    }
    let f32_at = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
    let (mut vert, mut face) = (Vec::with_capacity(3 * n), Vec::with_capacity(n));
    for i in 0..n {
        let mut f = [0; 3];
        for j in 0..3 {
            let o = 84 + 50 * i + 12 * (j + 1);
            let v = [f32_at(o), f32_at(o + 4), f32_at(o + 8)];
            if v.iter().any(|x| !x.is_finite() || x.abs() > 2f32.powi(30)) {
                return Err(format!(
                    "face {i}: a vertex is not finite or exceeds 2^30 ({v:?})"
                ));
            }
            f[j] = vert.len();
            vert.push(v);
        }
        face.push(f);
    }
    finish(vert, face, scale, true)
}

/// MuJoCo's MSH file: four int32 counts (vertices, normals, texture coordinates, faces), then the
/// float32 vertices, normals and texture coordinates, then int32 faces.
pub(crate) fn msh(bytes: &[u8], scale: [f64; 3]) -> Result<Mesh, String> {
    let int = |k: usize| i32::from_le_bytes(bytes[4 * k..4 * k + 4].try_into().unwrap()) as i64;
    if bytes.len() < 16 {
        return Err("missing the MSH header (16 bytes)".into());
    }
    let [nv, nn, nt, nf] = [int(0), int(1), int(2), int(3)];
    if nv < 4 || nf < 0 || nn < 0 || nt < 0 || (nn > 0 && nn != nv) || (nt > 0 && nt != nv) {
        return Err(format!("invalid sizes in the MSH header ({nv} vertices, {nn} normals, {nt} texture coordinates, {nf} faces)"));
    }
    let expected = 16 + 12 * (nv + nn + nf) + 8 * nt;
    if bytes.len() as i64 != expected {
        return Err(format!("{} bytes, the header says {expected}", bytes.len()));
    }
    let f32_at = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
    let vert: Vec<[f32; 3]> = (0..nv as usize)
        .map(|i| [0, 1, 2].map(|j| f32_at(16 + 12 * i + 4 * j)))
        .collect();
    let start = (16 + 12 * (nv + nn) + 8 * nt) as usize;
    let mut face = vec![];
    for i in 0..nf as usize {
        let f = [0, 1, 2].map(|j| int(start / 4 + 3 * i + j));
        if f.iter().any(|&k| k < 0 || k >= nv) {
            return Err(format!(
                "face {i} names a vertex that does not exist ({f:?})"
            ));
        }
        face.push(f.map(|k| k as usize));
    }
    finish(vert, face, scale, false)
}

/// An OBJ file as MuJoCo's loader (tinyobjloader) reads it: every `v`; the `f` faces of the first
/// object or group that has faces (indices 1-based, negative from the end, `v/vt/vn` forms),
/// quads split along their shorter diagonal, larger polygons as fans.
pub(crate) fn obj(text: &str, scale: [f64; 3]) -> Result<Mesh, String> {
    let (mut vert, mut face) = (vec![], vec![]);
    let mut shapes_done = false;
    for (ln, line) in text.lines().enumerate() {
        let mut w = line.split_whitespace();
        match w.next() {
            Some("v") => {
                let xs: Vec<f32> = w
                    .take(3)
                    .map(|s| s.parse::<f64>().map(|x| x as f32))
                    .collect::<Result<_, _>>()
                    .map_err(|_| format!("line {}: `{line}` is not a vertex", ln + 1))?;
                if xs.len() != 3 || xs.iter().any(|x| !x.is_finite()) {
                    return Err(format!("line {}: `{line}` is not a vertex", ln + 1));
                }
                vert.push([xs[0], xs[1], xs[2]]);
            }
            Some("o" | "g") if !face.is_empty() => shapes_done = true,
            Some("f") if !shapes_done => {
                let idx: Vec<usize> = w
                    .map(|s| obj_index(s, vert.len()))
                    .collect::<Option<_>>()
                    .ok_or_else(|| {
                        format!("line {}: `{line}`: a face index is not a vertex", ln + 1)
                    })?;
                if idx.len() < 3 {
                    return Err(format!("line {}: a face needs 3 vertices", ln + 1));
                }
                if idx.len() == 4 {
                    let d = |a: usize, b: usize| {
                        let (p, q) = (vert[idx[a]], vert[idx[b]]);
                        (0..3).map(|i| (q[i] - p[i]) * (q[i] - p[i])).sum::<f32>()
                    };
                    if d(0, 2) < d(1, 3) {
                        face.extend([[idx[0], idx[1], idx[2]], [idx[0], idx[2], idx[3]]]);
                    } else {
                        face.extend([[idx[0], idx[1], idx[3]], [idx[1], idx[2], idx[3]]]);
                    }
                } else {
                    face.extend((1..idx.len() - 1).map(|k| [idx[0], idx[k], idx[k + 1]]));
                }
            }
            _ => {}
        }
    }
    if vert.len() < 4 {
        return Err(format!("{} vertices: a mesh needs at least 4", vert.len()));
    }
    let vert64 = vert.iter().map(|v| v.map(f64::from)).collect();
    orient(&mut face, scale);
    Ok(Mesh { vert: vert64, face })
}

/// An OBJ vertex reference (`k`, `k/t`, `k//n`, `k/t/n`; negative counts from the last vertex).
fn obj_index(s: &str, nvert: usize) -> Option<usize> {
    let k: i64 = s.split('/').next()?.parse().ok()?;
    let i = if k < 0 { nvert as i64 + k } else { k - 1 };
    (0..nvert as i64).contains(&i).then_some(i as usize)
}

/// Faces reversed under a left-handed `scale`.
fn orient(face: &mut [[usize; 3]], scale: [f64; 3]) {
    if !righthand(scale) {
        for f in face {
            f.swap(1, 2);
        }
    }
}

fn finish(
    vert: Vec<[f32; 3]>,
    mut face: Vec<[usize; 3]>,
    scale: [f64; 3],
    merge: bool,
) -> Result<Mesh, String> {
    let vert = if merge {
        merge_repeated(vert, &mut face)
    } else {
        vert.iter().map(|v| v.map(f64::from)).collect()
    };
    if vert.len() < 4 {
        return Err(format!("{} vertices: a mesh needs at least 4", vert.len()));
    }
    orient(&mut face, scale);
    Ok(Mesh { vert, face })
}

/// A mesh given in the XML (`vertex`, `face`): float32 numbers, faces required.
pub(crate) fn inline(
    vertex: &[f64],
    face: Option<&[f64]>,
    scale: [f64; 3],
) -> Result<Mesh, String> {
    if vertex.len() % 3 != 0 || vertex.len() < 12 {
        return Err(format!(
            "`vertex` holds {} numbers: a multiple of 3, at least 4 vertices",
            vertex.len()
        ));
    }
    let vert: Vec<[f32; 3]> = vertex
        .chunks(3)
        .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32])
        .collect();
    let Some(face) = face else {
        // no faces: the mesh is its vertices' convex hull ([`mass`])
        return finish(vert, vec![], scale, false);
    };
    if face.len() % 3 != 0 {
        return Err(format!(
            "`face` holds {} numbers: a multiple of 3",
            face.len()
        ));
    }
    let mut faces = vec![];
    for c in face.chunks(3) {
        let f = [c[0], c[1], c[2]];
        if f.iter()
            .any(|&k| k < 0.0 || k.fract() != 0.0 || k >= vert.len() as f64)
        {
            return Err(format!("face {f:?} names a vertex that does not exist"));
        }
        faces.push(f.map(|k| k as usize));
    }
    finish(vert, faces, scale, false)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box of half-sizes a, outward faces (12 triangles).
    fn cube(a: [f64; 3]) -> Mesh {
        let vert = (0..8)
            .map(|k| [0, 1, 2].map(|i| if k >> i & 1 == 1 { a[i] } else { -a[i] }))
            .collect();
        // faces as quads (corners by bit pattern), counter-clockwise from outside
        let quads = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let face = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        Mesh { vert, face }
    }

    #[test]
    fn a_box_mesh_weighs_as_the_box() {
        let a = [0.3, 0.5, 0.7];
        let mut m = cube(a);
        transform(&mut m, [0.1, -0.2, 0.05], [1.0, 0.0, 0.0, 0.0], [1.0; 3]);
        for kind in [MeshInertia::Legacy, MeshInertia::Exact] {
            let p = mass(&m, kind).unwrap();
            let vol = 8.0 * a[0] * a[1] * a[2];
            assert!((p.measure - vol).abs() < 1e-15, "{}", p.measure);
            assert!((p.com - Vector3::new(-0.1, 0.2, -0.05)).norm() < 1e-15);
            // the box about its centre: the largest moment about the shortest side's axis
            let want = a;
            for i in 0..3 {
                assert!((p.boxsz[i] - want[i]).abs() < 1e-14, "{:?}", p.boxsz);
            }
        }
        // a face turned inside out: exact refuses, legacy weighs it as before
        m.face[0].swap(1, 2);
        assert!(mass(&m, MeshInertia::Exact)
            .unwrap_err()
            .contains("inconsistent orientation"));
        assert!(mass(&m, MeshInertia::Legacy).is_ok());
    }

    #[test]
    fn eig3_sorts_and_stops_at_its_tolerance() {
        let r = UnitQuaternion::from_euler_angles(0.3, -0.7, 1.1).to_rotation_matrix();
        let a = r.matrix()
            * Matrix3::from_diagonal(&Vector3::new(2e-5, 7e-5, 4e-5))
            * r.matrix().transpose();
        let (e, q) = eig3(&a, MESH_EIG_TOL);
        assert!(e[0] >= e[1] && e[1] >= e[2], "{e:?}");
        let rq = Matrix3::from_fn(|i, j| quat_mat(&q)[i][j]);
        let back = rq * Matrix3::from_diagonal(&Vector3::from(e)) * rq.transpose();
        let err = (back - a).abs().max() / a.abs().max();
        assert!(err <= MESH_EIG_TOL, "{err:e}");
        // control: the loose tolerance is not exact
        let (e, q) = eig3(&a, 1e-2);
        let rq = Matrix3::from_fn(|i, j| quat_mat(&q)[i][j]);
        let back = rq * Matrix3::from_diagonal(&Vector3::from(e)) * rq.transpose();
        assert!((back - a).abs().max() / a.abs().max() > 1e-12);
    }

    #[test]
    fn binary_stl_and_obj_give_the_same_mesh() {
        let m = cube([1.0, 2.0, 3.0]);
        let mut stl_bytes = vec![0u8; 80];
        stl_bytes.extend((m.face.len() as u32).to_le_bytes());
        for f in &m.face {
            stl_bytes.extend([0u8; 12]);
            for &k in f {
                for x in m.vert[k] {
                    stl_bytes.extend((x as f32).to_le_bytes());
                }
            }
            stl_bytes.extend([0u8; 2]);
        }
        let s = stl(&stl_bytes, [1.0; 3]).unwrap();
        assert_eq!(s.vert.len(), 8, "corners merged");
        let mut text = String::from("# cube\no cube\n");
        for v in &m.vert {
            text += &format!("v {} {} {}\n", v[0], v[1], v[2]);
        }
        for f in &m.face {
            text += &format!("f {}/1/1 {}//2 {}\n", f[0] + 1, f[1] + 1, f[2] as i64 - 8);
        }
        let o = obj(&text, [1.0; 3]).unwrap();
        let (ps, po) = (
            mass(&s, MeshInertia::Exact).unwrap(),
            mass(&o, MeshInertia::Exact).unwrap(),
        );
        assert!((ps.measure - 48.0).abs() < 1e-13 && (po.measure - 48.0).abs() < 1e-13);
        // an ASCII STL is refused with the reason
        let ascii = b"solid cube\n facet normal 0 0 1\n".repeat(4);
        assert!(stl(&ascii, [1.0; 3]).unwrap_err().contains("ASCII"));
        // a negative scale reverses the faces: the volume stays positive
        let mut r = obj(&text, [-1.0, 1.0, 1.0]).unwrap();
        transform(&mut r, [0.0; 3], [1.0, 0.0, 0.0, 0.0], [-1.0, 1.0, 1.0]);
        assert!((mass(&r, MeshInertia::Exact).unwrap().measure - 48.0).abs() < 1e-13);
    }
}
