//! The convex hull of a point set, as outward triangles: what MuJoCo's compiler weighs for a mesh
//! with `inertia="convex"` and takes as the faces of a mesh given without faces (it calls qhull
//! with triangulated output; here quickhull, written for this).
//!
//! Quickhull: a tetrahedron of extreme points, each other point assigned to a face it lies
//! outside of; then, while a face has outside points, its farthest point p is joined to the
//! horizon of the faces p sees (found by walking edge neighbours), and the outside points of the
//! removed faces are handed to the new ones. Points within `eps` of a face count as on it (as
//! qhull's merging treats points within round-off): the hull's volume then differs from qhull's by
//! round-off only. The triangulation of a flat facet may differ from qhull's; a volume integral
//! over it does not.

use std::collections::HashMap;

struct Face {
    v: [usize; 3],
    n: [f64; 3],
    d: f64,
    outside: Vec<usize>,
    alive: bool,
}

fn sub(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: &[f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// The plane through a, b, c (unit normal by the right-hand rule, offset); a degenerate triangle
/// gets a zero normal, so that no point is ever outside it.
fn plane(p: &[[f64; 3]], v: [usize; 3]) -> ([f64; 3], f64) {
    let n = cross(&sub(&p[v[1]], &p[v[0]]), &sub(&p[v[2]], &p[v[0]]));
    let len = norm(&n);
    if len == 0.0 {
        return ([0.0; 3], 0.0);
    }
    let n = n.map(|x| x / len);
    (n, dot(&n, &p[v[0]]))
}

struct Hull<'a> {
    p: &'a [[f64; 3]],
    eps: f64,
    faces: Vec<Face>,
    /// directed edge (a, b) -> the face that has it
    edge: HashMap<(usize, usize), usize>,
}

impl Hull<'_> {
    fn dist(&self, f: usize, k: usize) -> f64 {
        let f = &self.faces[f];
        dot(&f.n, &self.p[k]) - f.d
    }

    fn add(&mut self, v: [usize; 3]) -> usize {
        let (n, d) = plane(self.p, v);
        let id = self.faces.len();
        self.faces.push(Face {
            v,
            n,
            d,
            outside: vec![],
            alive: true,
        });
        for j in 0..3 {
            self.edge.insert((v[j], v[(j + 1) % 3]), id);
        }
        id
    }

    /// Each point to the face among `faces` it is farthest outside of (beyond `eps`), if any.
    fn assign(&mut self, points: &[usize], faces: &[usize]) {
        for &k in points {
            let best = faces.iter().map(|&f| (f, self.dist(f, k))).fold(
                None,
                |b: Option<(usize, f64)>, (f, d)| match b {
                    Some((_, bd)) if bd >= d => b,
                    _ if d > self.eps => Some((f, d)),
                    _ => b,
                },
            );
            if let Some((f, _)) = best {
                self.faces[f].outside.push(k);
            }
        }
    }

    /// Adds the farthest outside point of face `f`: removes the faces it sees, joins it to their
    /// horizon. Returns the new faces, or an error if the hull's edges stop matching up.
    fn expand(&mut self, f: usize) -> Result<Vec<usize>, String> {
        let out = std::mem::take(&mut self.faces[f].outside);
        let &apex = out
            .iter()
            .max_by(|&&a, &&b| self.dist(f, a).total_cmp(&self.dist(f, b)))
            .expect("expand is called on a face with outside points");
        let mut visible = vec![f];
        self.faces[f].alive = false;
        let mut horizon = vec![];
        let mut i = 0;
        while i < visible.len() {
            let g = visible[i];
            i += 1;
            let v = self.faces[g].v;
            for j in 0..3 {
                let (a, b) = (v[j], v[(j + 1) % 3]);
                let &nb = self
                    .edge
                    .get(&(b, a))
                    .ok_or("an edge without a neighbour")?;
                if !self.faces[nb].alive {
                    continue;
                }
                if self.dist(nb, apex) > self.eps {
                    self.faces[nb].alive = false;
                    visible.push(nb);
                } else {
                    horizon.push((a, b));
                }
            }
        }
        let mut points = out;
        for &g in &visible {
            points.extend(std::mem::take(&mut self.faces[g].outside));
            let v = self.faces[g].v;
            for j in 0..3 {
                self.edge.remove(&(v[j], v[(j + 1) % 3]));
            }
        }
        points.retain(|&k| k != apex);
        let new: Vec<usize> = horizon
            .iter()
            .map(|&(a, b)| self.add([a, b, apex]))
            .collect();
        self.assign(&points, &new);
        Ok(new)
    }
}

/// The convex hull of `p` as triangles over its indices, counter-clockwise seen from outside.
/// Errors when the points span no volume (fewer than 4, or all on a plane within round-off).
pub(crate) fn hull(p: &[[f64; 3]]) -> Result<Vec<[usize; 3]>, String> {
    let degenerate = |what: &str| format!("the vertices {what}: their convex hull has no volume");
    if p.len() < 4 {
        return Err(degenerate("are fewer than 4"));
    }
    let size: f64 = (0..3)
        .map(|i| p.iter().fold(0.0f64, |m, v| m.max(v[i].abs())))
        .sum();
    // distances below a few units of round-off of the coordinates count as zero
    let eps = 3.0 * f64::EPSILON * size;
    // the initial tetrahedron: the two farthest of the axis extremes, the point farthest from
    // their line, the point farthest from the plane of the three
    let mut ext = vec![];
    for i in 0..3 {
        let by = |a: &&[f64; 3], b: &&[f64; 3]| a[i].total_cmp(&b[i]);
        let lo = (0..p.len()).min_by(|&a, &b| by(&&p[a], &&p[b])).unwrap();
        let hi = (0..p.len()).max_by(|&a, &b| by(&&p[a], &&p[b])).unwrap();
        ext.extend([lo, hi]);
    }
    let (mut i0, mut i1, mut far) = (0, 0, -1.0);
    for &a in &ext {
        for &b in &ext {
            let d = norm(&sub(&p[a], &p[b]));
            if d > far {
                (i0, i1, far) = (a, b, d);
            }
        }
    }
    if far <= eps {
        return Err(degenerate("coincide"));
    }
    let axis = sub(&p[i1], &p[i0]);
    let from_line = |k: usize| norm(&cross(&axis, &sub(&p[k], &p[i0]))) / far;
    let i2 = (0..p.len())
        .max_by(|&a, &b| from_line(a).total_cmp(&from_line(b)))
        .unwrap();
    if from_line(i2) <= eps {
        return Err(degenerate("lie on a line"));
    }
    let (n, d) = plane(p, [i0, i1, i2]);
    let off = |k: usize| dot(&n, &p[k]) - d;
    let i3 = (0..p.len())
        .max_by(|&a, &b| off(a).abs().total_cmp(&off(b).abs()))
        .unwrap();
    if off(i3).abs() <= eps {
        return Err(degenerate("lie on a plane"));
    }
    // the base faces away from the apex i3
    let [a, b, c] = if off(i3) > 0.0 {
        [i0, i2, i1]
    } else {
        [i0, i1, i2]
    };
    let mut h = Hull {
        p,
        eps,
        faces: vec![],
        edge: HashMap::new(),
    };
    let first: Vec<usize> = [[a, b, c], [b, a, i3], [c, b, i3], [a, c, i3]]
        .into_iter()
        .map(|v| h.add(v))
        .collect();
    let rest: Vec<usize> = (0..p.len())
        .filter(|k| ![a, b, c, i3].contains(k))
        .collect();
    h.assign(&rest, &first);
    let mut todo = first;
    while let Some(f) = todo.pop() {
        if h.faces[f].alive && !h.faces[f].outside.is_empty() {
            let new = h.expand(f).map_err(|e| {
                format!("the convex hull could not be built ({e}): the vertices are degenerate")
            })?;
            todo.extend(new);
        }
    }
    let out: Vec<[usize; 3]> = h.faces.iter().filter(|f| f.alive).map(|f| f.v).collect();
    // a closed surface: every edge's reverse belongs to another face
    if out
        .iter()
        .flat_map(|v| (0..3).map(move |j| (v[(j + 1) % 3], v[j])))
        .any(|e| !h.edge.contains_key(&e))
    {
        return Err("the convex hull could not be built (its surface is not closed): the vertices are degenerate".into());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Signed volume of a closed, outward surface (divergence theorem).
    fn volume(p: &[[f64; 3]], f: &[[usize; 3]]) -> f64 {
        f.iter()
            .map(|v| dot(&p[v[0]], &cross(&p[v[1]], &p[v[2]])) / 6.0)
            .sum()
    }

    /// A deterministic pseudo-random sequence in [0, 1) (no dependency for a test).
    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*seed >> 11) as f64 / (1u64 << 53) as f64
    }

    #[test]
    fn the_hull_of_a_box_with_inner_and_face_points_is_the_box() {
        let a = [0.3, 0.5, 0.7];
        let mut p: Vec<[f64; 3]> = (0..8)
            .map(|k| [0, 1, 2].map(|i| if k >> i & 1 == 1 { a[i] } else { -a[i] }))
            .collect();
        let mut s = 7;
        for _ in 0..300 {
            let r = [0, 1, 2].map(|i| (2.0 * lcg(&mut s) - 1.0) * a[i]);
            p.push(r);
            // a point on a face and one on an edge: on the hull, adding nothing
            p.push([a[0], r[1], r[2]]);
            p.push([r[0], -a[1], a[2]]);
        }
        let f = hull(&p).unwrap();
        let v = volume(&p, &f);
        assert!((v - 8.0 * a[0] * a[1] * a[2]).abs() < 1e-14, "{v}");
        // every triangle's normal points away from the centre
        for t in &f {
            let (n, d) = plane(&p, *t);
            assert!(d > 0.0 && norm(&n) > 0.5, "{t:?}");
        }
    }

    #[test]
    fn the_hull_of_points_on_a_sphere_converges_to_the_ball() {
        let mut s = 11;
        let p: Vec<[f64; 3]> = (0..4000)
            .map(|_| {
                let z = 2.0 * lcg(&mut s) - 1.0;
                let t = std::f64::consts::TAU * lcg(&mut s);
                let r = (1.0 - z * z).sqrt();
                [r * t.cos(), r * t.sin(), z]
            })
            .collect();
        let f = hull(&p).unwrap();
        // every point is a vertex, on or inside every face's plane
        let used: std::collections::HashSet<usize> = f.iter().flatten().copied().collect();
        assert_eq!(used.len(), p.len());
        for t in &f {
            let (n, d) = plane(&p, *t);
            let worst = p.iter().map(|q| dot(&n, q) - d).fold(f64::MIN, f64::max);
            assert!(worst < 1e-12, "{worst}");
        }
        let v = volume(&p, &f);
        let ball = 4.0 / 3.0 * std::f64::consts::PI;
        assert!(v < ball && v > 0.99 * ball, "{v}");
    }

    #[test]
    fn flat_or_too_few_points_are_refused() {
        let flat: Vec<[f64; 3]> = (0..20)
            .map(|k| [k as f64, (k * k % 7) as f64, 0.0])
            .collect();
        assert!(hull(&flat).unwrap_err().contains("plane"));
        assert!(hull(&flat[..3]).unwrap_err().contains("fewer than 4"));
        let line: Vec<[f64; 3]> = (0..9).map(|k| [k as f64, 2.0 * k as f64, 0.5]).collect();
        assert!(hull(&line).unwrap_err().contains("line"));
    }
}
