//! **Volume elements.** Between consecutive sheets, over each subdivided triangle `(u, v, w)`,
//! lies a prism with corners `u_i v_i w_i u_{i+1} v_{i+1} w_{i+1}`. Its signed volume comes from
//! the divergence theorem over its closed triangulated surface,
//! `vol = (1/6) Σ_faces p · (q × r)`: the caps `(u_i, v_i, w_i)` and `(u_{i+1}, w_{i+1}, v_{i+1})`
//! and the three quadrilateral sides, each split along the diagonal that starts at the bottom
//! corner of lower vertex id. The split depends only on the edge, so the two prisms sharing a
//! side split it the same way and their face terms cancel; caps cancel between layers; at the
//! medial sheet the caps of the two sides of the object cancel (the constructor checks that
//! every medial triangle is covered by two opposite boundary triangles); at a free edge the
//! rim side is shared by the prisms of both sides. The prisms therefore tile the model: their
//! volumes add up to the volume enclosed by the boundary mesh, for any landmark positions, up
//! to rounding. A prism turned inside out has a negative volume; it is reported
//! ([`DiceValue::negative_volume`]), never clipped.

use super::lanes::{Lanes, Points, LANES};

/// Signed volumes of the prisms of up to [`LANES`] layers with corners `x` (one per lane) and
/// their gradients with respect to each corner, from the closed triangulated surface whose
/// faces not touching corner 0 are `faces` (see [`prism_faces`]), the same for every layer.
/// Coordinates are taken relative to corner 0: the volume of a closed surface does not depend
/// on the origin, the faces through the origin contribute nothing (nor to the gradient at the
/// other corners), and the gradient at corner 0 is minus the sum of the others:
/// `vol = (1/6) Σ_faces y_a · (y_b × y_c)`, `∂vol/∂y_a = (1/6) y_b × y_c` (and cyclically).
// Inlined into the per-triangle loop (compiled there for the dispatched instruction set).
#[inline(always)]
pub(super) fn prism_volumes(x: &[Points; 6], faces: &[[usize; 3]]) -> (Lanes, [Points; 6]) {
    let mut y = [Points::default(); 6];
    for n in 1..6 {
        y[n] = x[n].sub(&x[0]);
    }
    let mut vol = [0.0; LANES];
    let mut grad = [Points::default(); 6];
    for &[a, b, c] in faces {
        let bc = y[b].cross(&y[c]);
        let term = y[a].dot(&bc);
        for l in 0..LANES {
            vol[l] += term[l];
        }
        grad[a].add_assign(&bc);
        grad[b].add_assign(&y[c].cross(&y[a]));
        grad[c].add_assign(&y[a].cross(&y[b]));
    }
    for n in 1..6 {
        grad[n] = grad[n].div(6.0);
        grad[0] = grad[0].sub(&grad[n]);
    }
    for v in &mut vol {
        *v /= 6.0;
    }
    (vol, grad)
}

/// The outward faces of the prism over triangle `tri` (corner indices, see
/// [`DiceAttachment::faces`]) that do not touch corner 0: three to five of the eight. The caps
/// are `(0, 1, 2)` and `(3, 5, 4)`; the side over edge `a → b` is the quadrilateral
/// `(b, a, a', b')` (primes on the next sheet), split along the diagonal from the bottom corner
/// of lower vertex id: `a — b'` if `tri[a] < tri[b]`, else `b — a'`.
pub(super) fn prism_faces(tri: &[usize; 3]) -> PrismFaces {
    let mut kept = PrismFaces {
        faces: [[0; 3]; 5],
        len: 0,
    };
    let sides = (0..3).flat_map(|a| side_faces(tri, a));
    for face in std::iter::once([3, 5, 4])
        .chain(sides)
        .filter(|f| !f.contains(&0))
    {
        kept.faces[kept.len] = face;
        kept.len += 1;
    }
    kept
}

/// At most five faces of a prism (those not touching corner 0).
#[derive(Clone, Copy, Debug)]
pub(super) struct PrismFaces {
    faces: [[usize; 3]; 5],
    len: usize,
}

impl PrismFaces {
    pub(super) fn as_slice(&self) -> &[[usize; 3]] {
        &self.faces[..self.len]
    }
}

/// The two triangles of the side over edge `a → b = a + 1 (mod 3)` (see [`prism_faces`]).
fn side_faces(tri: &[usize; 3], a: usize) -> [[usize; 3]; 2] {
    let b = (a + 1) % 3;
    if tri[a] < tri[b] {
        [[b, a, b + 3], [a, a + 3, b + 3]]
    } else {
        [[b, a, a + 3], [b, a + 3, b + 3]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Vec3;
    use std::collections::HashMap;

    /// The five faces not touching corner 0, plus the three that do, close the prism.
    #[test]
    fn prism_faces_close_the_prism() {
        for tri in [[0, 1, 2], [2, 1, 0], [5, 9, 7], [9, 5, 7]] {
            let mut faces = vec![[0, 1, 2], [3, 5, 4]];
            (0..3).for_each(|a| faces.extend(side_faces(&tri, a)));
            let mut edges = HashMap::new();
            for f in &faces {
                for e in 0..3 {
                    *edges.entry((f[e], f[(e + 1) % 3])).or_insert(0) += 1;
                }
            }
            assert_eq!(edges.len(), 24, "{tri:?}: {faces:?}");
            for (&(a, b), &n) in &edges {
                assert_eq!(n, 1);
                assert_eq!(edges.get(&(b, a)), Some(&1), "edge {a}->{b} of {tri:?}");
            }
            faces.retain(|f| !f.contains(&0));
            assert_eq!(prism_faces(&tri).as_slice(), faces.as_slice());
        }
    }

    #[test]
    fn prism_volume_and_gradient() {
        // A right prism over the unit right triangle, height 2 (outward bottom cap faces −z,
        // so the bottom triangle is listed clockwise seen from +z), volume 1; in the other
        // lanes the same prism sheared by `l/10` along x and moved by `l` along y.
        let base = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 2.0),
            Vec3::new(0.0, 1.0, 2.0),
            Vec3::new(1.0, 0.0, 2.0),
        ];
        let lanes = |x: &[Vec3; 6]| -> [Points; 6] {
            std::array::from_fn(|c| {
                Points::of(std::array::from_fn(|l| {
                    x[c] + Vec3::new(0.1 * l as f64 * base[c].z, l as f64, 0.0)
                }))
            })
        };
        let faces = prism_faces(&[0, 1, 2]);
        let faces = faces.as_slice();
        let (vol, grad) = prism_volumes(&lanes(&base), faces);
        for (l, v) in vol.iter().enumerate() {
            assert!((v - 1.0).abs() < 1e-14, "lane {l}: {v}");
        }
        let h = 1e-6;
        for c in 0..6 {
            for a in 0..3 {
                let (mut xp, mut xm) = (base, base);
                xp[c][a] += h;
                xm[c][a] -= h;
                let (vp, vm) = (
                    prism_volumes(&lanes(&xp), faces).0,
                    prism_volumes(&lanes(&xm), faces).0,
                );
                for l in 0..LANES {
                    let fd = (vp[l] - vm[l]) / (2.0 * h);
                    assert!(
                        (fd - grad[c].lane(l)[a]).abs() < 1e-8,
                        "corner {c} axis {a} lane {l}"
                    );
                }
            }
        }
    }
}
