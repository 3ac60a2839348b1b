//! What real data does to a case that a smooth warp alone does not: a wall of another thickness
//! (everywhere, or in one region), and a segmentation with ragged edges and small holes.
//!
//! A [`Thickening`] scales every spoke of a template about its medial point before the warp
//! (the target is a thicker or thinner wall, not a larger shape: what the alignment must tell
//! apart); its regional part is a smooth bump of known place and size (the truth of a group
//! difference for statistics). [`degrade`] flips boundary voxels of a segmentation at random
//! and cuts small balls out of it, seeded, as a rater or a threshold would.

use crate::construction::inflate::{halve_at_crossings, self_intersections, LIMIT_ROUNDS};
use crate::image::volume::Volume;
use crate::model::template::MedialTemplate;
use crate::{Error, Result, TriMesh, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A smooth regional change of thickness: spokes scaled by `factor` at `centre`, by 1 from
/// `radius_mm` on, by `1 + (factor − 1)·(1 + cos πd)/2` at a fraction `d` of the radius between
/// (a raised cosine: continuous with its first derivative, so the wall stays smooth).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Region {
    /// Centre of the bump (a medial point), mm.
    pub centre: Vec3,
    /// Distance from the centre at which the change ends, mm (Euclidean).
    pub radius_mm: f64,
    /// Factor of the spokes at the centre.
    pub factor: f64,
}

/// A change of wall thickness: every spoke scaled by `global`, and by a [`Region`]'s bump on top.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Thickening {
    global: f64,
    region: Option<Region>,
}

impl Thickening {
    /// A thickening by `global` everywhere and `region` on top.
    ///
    /// Refuses a factor that is not finite and positive, a radius that is not finite and
    /// positive, a centre that is not finite.
    pub fn new(global: f64, region: Option<Region>) -> Result<Self> {
        let positive = |what: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(Error::InvalidParameter(format!(
                    "{what} must be a positive number, not {v}"
                )))
            }
        };
        positive("the thickness factor", global)?;
        if let Some(r) = &region {
            positive("the regional thickness factor", r.factor)?;
            positive("the region's radius (mm)", r.radius_mm)?;
            if !r.centre.iter().all(|c| c.is_finite()) {
                return Err(Error::NonFinite("the region's centre".into()));
            }
        }
        Ok(Self { global, region })
    }

    /// The factor everywhere.
    pub fn global(&self) -> f64 {
        self.global
    }

    /// The regional bump, if any.
    pub fn region(&self) -> Option<&Region> {
        self.region.as_ref()
    }

    /// The factor of the spokes of an atom at medial point `m`.
    pub fn factor_at(&self, m: &Vec3) -> f64 {
        let bump = self.region.map_or(1.0, |r| {
            let d = (m - r.centre).norm() / r.radius_mm;
            if d >= 1.0 {
                1.0
            } else {
                1.0 + (r.factor - 1.0) * 0.5 * (1.0 + (std::f64::consts::PI * d).cos())
            }
        });
        self.global * bump
    }

    /// The factor at every atom of `template`, in atom order.
    pub fn atom_factors(&self, template: &MedialTemplate) -> Vec<f64> {
        template
            .medial_points()
            .iter()
            .map(|m| self.factor_at(m))
            .collect()
    }

    /// The boundary of `template` with every spoke scaled by its atom's factor about its medial
    /// point (same triangles, same point order), mm, limited where the sheet cannot hold it.
    ///
    /// The offset of a curved sheet folds at its focal distance, and two sheets meeting at a
    /// seam at a narrow angle meet sooner: a wall thickened past that crosses itself, which is
    /// no shape. Where the thickened boundary crosses itself, the change asked at the atoms of
    /// the crossing triangles is halved (a factor `f` becomes `1 + (f − 1)/2`), and again, up
    /// to [`LIMIT_ROUNDS`] times; the factors kept are the truth of the case, per atom
    /// ([`Thickened::factors`]), and the atoms limited are listed.
    ///
    /// Errors: a boundary that still crosses itself with the change at those atoms cut to
    /// 2^−[`LIMIT_ROUNDS`] of it (the template's own boundary crosses itself); those of
    /// [`TriMesh::new`].
    pub fn boundary(&self, template: &MedialTemplate) -> Result<Thickened> {
        let asked = self.atom_factors(template);
        let mut factors = asked.clone();
        let medial = template.medial_points();
        let atom_of = template.medial_index();
        let mut round = 0;
        loop {
            let points = (template.boundary_points().iter().zip(atom_of))
                .map(|(b, &atom)| medial[atom] + factors[atom] * (b - medial[atom]))
                .collect();
            let mesh = TriMesh::new(points, template.boundary_triangles().to_vec())?;
            let crossing = self_intersections(&mesh);
            let Some(&(f, g)) = crossing.first() else {
                let limited: Vec<usize> = (0..factors.len())
                    .filter(|&a| factors[a] != asked[a])
                    .collect();
                let least_share = (limited.iter())
                    .map(|&a| (factors[a] - 1.0) / (asked[a] - 1.0))
                    .fold(1.0, f64::min);
                return Ok(Thickened {
                    mesh,
                    factors,
                    limited,
                    least_share,
                });
            };
            if round == LIMIT_ROUNDS {
                let most = asked.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                return Err(Error::InvalidParameter(format!(
                    "the wall thickened by up to {most:.3}× intersects itself ({} pairs of \
                     triangles, e.g. {f} and {g}) even with the change cut to 1/{} of it \
                     there: the template's own boundary crosses itself",
                    crossing.len(),
                    1u64 << LIMIT_ROUNDS
                )));
            }
            halve_at_crossings(&mut factors, &mesh, &crossing, atom_of);
            round += 1;
        }
    }
}

/// A thickened wall ([`Thickening::boundary`]).
#[derive(Clone, Debug)]
pub struct Thickened {
    /// The boundary, mm (the template's triangles and point order).
    pub mesh: TriMesh,
    /// Each atom's factor as applied: as asked, or limited where the wall crossed itself.
    pub factors: Vec<f64>,
    /// The atoms whose factor was limited, ascending.
    pub limited: Vec<usize>,
    /// The smallest share of the change asked that a limited atom kept, `(f − 1)/(f_asked − 1)`
    /// (1 when none was limited).
    pub least_share: f64,
}

/// What [`degrade`] does to a segmentation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Degradation {
    /// Probability with which each boundary voxel (one whose 6-neighbourhood holds both labels)
    /// changes label, in `[0, 1]`.
    pub flip_fraction: f64,
    /// Balls cut out of the foreground, each centred on a foreground voxel drawn at random.
    pub holes: usize,
    /// Radius of each ball, mm.
    pub hole_radius_mm: f64,
    /// Seed of the draws (ChaCha8): the same seed gives the same image.
    pub seed: u64,
}

/// A degraded segmentation and what was changed.
#[derive(Clone, Debug)]
pub struct Degraded {
    /// The image (0 and 1).
    pub image: Volume,
    /// Boundary voxels of the input.
    pub boundary_voxels: usize,
    /// Of them, those whose label was flipped.
    pub flipped: usize,
    /// Foreground voxels cleared by the holes (after the flips).
    pub cleared: usize,
}

/// `image`'s foreground (values > 0.5) with boundary voxels flipped and holes cut, as
/// [`Degradation`] says.
///
/// Errors: a fraction outside `[0, 1]`, a hole radius that is not finite and positive when
/// holes are asked for.
pub fn degrade(image: &Volume, how: &Degradation) -> Result<Degraded> {
    if !(0.0..=1.0).contains(&how.flip_fraction) {
        return Err(Error::InvalidParameter(format!(
            "the fraction of boundary voxels to flip must be in [0, 1], not {}",
            how.flip_fraction
        )));
    }
    if how.holes > 0 && !(how.hole_radius_mm.is_finite() && how.hole_radius_mm > 0.0) {
        return Err(Error::InvalidParameter(format!(
            "the holes' radius must be a positive number of mm, not {}",
            how.hole_radius_mm
        )));
    }
    let [nx, ny, nz] = image.dims();
    let inside: Vec<bool> = image.data().iter().map(|&v| v > 0.5).collect();
    let index = |i: usize, j: usize, k: usize| i + nx * (j + ny * k);
    let mut rng = ChaCha8Rng::seed_from_u64(how.seed);
    let mut label = inside.clone();
    let (mut boundary_voxels, mut flipped) = (0, 0);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let here = inside[index(i, j, k)];
                let differs = |a: usize, b: usize, c: usize| inside[index(a, b, c)] != here;
                let on_boundary = (i > 0 && differs(i - 1, j, k))
                    || (i + 1 < nx && differs(i + 1, j, k))
                    || (j > 0 && differs(i, j - 1, k))
                    || (j + 1 < ny && differs(i, j + 1, k))
                    || (k > 0 && differs(i, j, k - 1))
                    || (k + 1 < nz && differs(i, j, k + 1));
                if on_boundary {
                    boundary_voxels += 1;
                    if rng.gen_bool(how.flip_fraction) {
                        label[index(i, j, k)] = !here;
                        flipped += 1;
                    }
                }
            }
        }
    }
    let foreground: Vec<usize> = (0..label.len()).filter(|&n| label[n]).collect();
    let mut cleared = 0;
    if !foreground.is_empty() {
        let spacing = image.spacing();
        let reach: [usize; 3] =
            std::array::from_fn(|a| (how.hole_radius_mm / spacing[a]).ceil() as usize);
        for _ in 0..how.holes {
            let n = foreground[rng.gen_range(0..foreground.len())];
            let centre = [n % nx, (n / nx) % ny, n / (nx * ny)];
            let c = image.voxel_centre(centre);
            let range = |a: usize, len: usize| {
                centre[a].saturating_sub(reach[a])..(centre[a] + reach[a] + 1).min(len)
            };
            for k in range(2, nz) {
                for j in range(1, ny) {
                    for i in range(0, nx) {
                        let m = index(i, j, k);
                        if label[m]
                            && (image.voxel_centre([i, j, k]) - c).norm() <= how.hole_radius_mm
                        {
                            label[m] = false;
                            cleared += 1;
                        }
                    }
                }
            }
        }
    }
    let data = label.iter().map(|&l| f64::from(u8::from(l))).collect();
    Ok(Degraded {
        image: Volume::new(image.dims(), data, *image.voxel_to_world())?,
        boundary_voxels,
        flipped,
        cleared,
    })
}

/// `count` unit vectors drawn uniformly on the sphere from `seed` (ChaCha8; normalised
/// Gaussian triples): the axes of a stress case's rotation and shift.
pub fn seeded_directions(seed: u64, count: usize) -> Vec<Vec3> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut gaussian = || {
        // Box–Muller from two uniforms in (0, 1].
        let (u, v): (f64, f64) = (1.0 - rng.gen::<f64>(), rng.gen::<f64>());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    };
    (0..count)
        .map(|_| loop {
            let v = Vec3::new(gaussian(), gaussian(), gaussian());
            if v.norm() > 1e-6 {
                break v.normalize();
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{Shape, SyntheticCase};
    use nalgebra::Matrix4;

    fn ball(n: usize, radius: f64) -> Volume {
        let c = (n as f64 - 1.0) / 2.0;
        let data = (0..n * n * n)
            .map(|m| {
                let p = Vec3::new(
                    (m % n) as f64 - c,
                    ((m / n) % n) as f64 - c,
                    (m / (n * n)) as f64 - c,
                );
                f64::from(u8::from(p.norm() <= radius))
            })
            .collect();
        Volume::new([n; 3], data, Matrix4::identity()).unwrap()
    }

    #[test]
    fn a_global_thickening_scales_every_spoke_and_keeps_the_medial_points() {
        let case = SyntheticCase::build(Shape::Toy).unwrap();
        let t = case.template();
        let thick = Thickening::new(1.3, None).unwrap();
        let thickened = thick.boundary(t).unwrap();
        assert!(thickened.limited.is_empty());
        assert!(thickened.factors.iter().all(|&f| f == 1.3));
        let boundary = thickened.mesh;
        for (i, (b, &atom)) in boundary.points().iter().zip(t.medial_index()).enumerate() {
            let m = t.medial_points()[atom];
            let before = (t.boundary_points()[i] - m).norm();
            assert!(((b - m).norm() - 1.3 * before).abs() < 1e-12 * (1.0 + before));
        }
    }

    #[test]
    fn a_thickening_past_the_focal_distance_is_limited_where_the_wall_would_cross_itself() {
        let case = SyntheticCase::build(Shape::Toy).unwrap();
        let t = case.template();
        // Past the focal distance of the toy's sheets at its seam (about ×1.4) the wall as
        // asked crosses itself; the change is halved at the atoms of the crossing triangles.
        let thick = Thickening::new(1.7, None).unwrap();
        let asked: Vec<usize> = (0..t.medial_points().len()).collect();
        let scaled = |factors: &[f64]| -> TriMesh {
            let points = (t.boundary_points().iter().zip(t.medial_index()))
                .map(|(b, &a)| t.medial_points()[a] + factors[a] * (b - t.medial_points()[a]))
                .collect();
            TriMesh::new(points, t.boundary_triangles().to_vec()).unwrap()
        };
        assert!(!self_intersections(&scaled(&vec![1.7; asked.len()])).is_empty());
        let thickened = thick.boundary(t).unwrap();
        assert!(self_intersections(&thickened.mesh).is_empty());
        assert_eq!(scaled(&thickened.factors).points(), thickened.mesh.points());
        let limited = &thickened.limited;
        assert!(
            !limited.is_empty() && limited.len() < asked.len() / 2,
            "{limited:?}"
        );
        for (a, &f) in thickened.factors.iter().enumerate() {
            if limited.contains(&a) {
                // 1 + 0.7/2^k for some k ≥ 1.
                let k = (0.7 / (f - 1.0)).log2();
                assert!(
                    k >= 1.0 - 1e-9 && (k - k.round()).abs() < 1e-9,
                    "atom {a}: {f}"
                );
            } else {
                assert_eq!(f, 1.7);
            }
        }
        let least = thickened.least_share;
        assert!(least > 0.0 && least <= 0.5 + 1e-12, "{least}");
    }

    #[test]
    fn a_regional_bump_is_the_factor_at_its_centre_one_outside_and_smooth_between() {
        let region = Region {
            centre: Vec3::new(1.0, 2.0, 3.0),
            radius_mm: 4.0,
            factor: 2.5,
        };
        let t = Thickening::new(0.8, Some(region)).unwrap();
        assert!((t.factor_at(&region.centre) - 0.8 * 2.5).abs() < 1e-15);
        assert_eq!(t.factor_at(&Vec3::new(1.0, 2.0, 7.0)), 0.8);
        assert_eq!(t.factor_at(&Vec3::new(9.0, 2.0, 3.0)), 0.8);
        // Half way: half the change.
        let half = t.factor_at(&Vec3::new(3.0, 2.0, 3.0));
        assert!((half - 0.8 * 1.75).abs() < 1e-12);
        // Continuous at the rim, with a flat slope there.
        let near = t.factor_at(&Vec3::new(1.0, 2.0, 3.0 + 4.0 - 1e-4));
        assert!((near - 0.8).abs() < 1e-7);
        assert!(Thickening::new(0.0, None).is_err());
        assert!(Thickening::new(
            1.0,
            Some(Region {
                radius_mm: -1.0,
                ..region
            })
        )
        .is_err());
    }

    #[test]
    fn seeded_directions_are_unit_reproducible_and_spread() {
        let a = seeded_directions(3, 400);
        assert_eq!(a, seeded_directions(3, 400));
        assert!(a.iter().all(|v| (v.norm() - 1.0).abs() < 1e-12));
        // Uniform on the sphere: the mean of 400 is within 4/sqrt(3·400) ≈ 0.12 of 0 per axis.
        let mean = a.iter().sum::<Vec3>() / 400.0;
        assert!(mean.amax() < 0.12, "{mean}");
    }

    #[test]
    fn degradation_flips_about_its_fraction_of_the_boundary_and_cuts_its_holes() {
        let image = ball(24, 8.0);
        let none = degrade(
            &image,
            &Degradation {
                flip_fraction: 0.0,
                holes: 0,
                hole_radius_mm: 1.0,
                seed: 1,
            },
        )
        .unwrap();
        assert_eq!(none.image, image);
        assert_eq!(none.flipped, 0);
        let how = Degradation {
            flip_fraction: 0.3,
            holes: 3,
            hole_radius_mm: 1.0,
            seed: 7,
        };
        let a = degrade(&image, &how).unwrap();
        let b = degrade(&image, &how).unwrap();
        assert_eq!(a.image, b.image, "the same seed gives the same image");
        let share = a.flipped as f64 / a.boundary_voxels as f64;
        // Binomial with n ≈ 1,600 boundary voxels: 5 standard deviations is ±0.06.
        assert!((share - 0.3).abs() < 0.06, "{share}");
        // A hole of radius one voxel clears at most 7 voxels; three of them at most 21.
        assert!(a.cleared > 0 && a.cleared <= 21, "{}", a.cleared);
        let changed = a
            .image
            .data()
            .iter()
            .zip(image.data())
            .filter(|(x, y)| x != y)
            .count();
        assert!(changed <= a.flipped + a.cleared && changed > 0);
        assert!(degrade(
            &image,
            &Degradation {
                flip_fraction: 1.5,
                ..how
            }
        )
        .is_err());
    }
}
