//! The inscribed-ball fidelity on real templates: small on cmrep's t001 and on every shipped
//! template (the figures the README quotes), large once the boundary moves without its medial
//! sheet or the medial sheet leaves the object.

use medial::mesh::PrincipalAxes;
use medial::model::fidelity::{BallFidelity, FidelitySummary};
use medial::model::template::MedialTemplate;
use medial::synth::Warp;
use medial::Vec3;
use nalgebra::Matrix4;
use std::path::Path;

const T001: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/data/cmrep/t001_template_bcmrep.vtk"
);
const EXAMPLES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/examples");

fn read(path: &Path) -> MedialTemplate {
    medial::io::cmrep::read_template(path).expect("a valid template")
}

fn summary(t: &MedialTemplate, q: &[Vec3]) -> FidelitySummary {
    BallFidelity::new(t).measure(q).summary
}

#[test]
fn t001_sheet_atoms_are_within_a_few_per_cent_of_inscribed_balls() {
    let t = read(Path::new(T001));
    let f = BallFidelity::new(&t).measure(t.landmarks());
    let s = f.summary;
    assert_eq!((s.sheet.atoms, s.edge.atoms), (125, 64));
    // The butterfly surface: 1.31 % on sheet atoms (the chords alone give 5.8 %).
    assert!((0.0125..0.014).contains(&s.sheet.mean_residual), "{s:?}");
    assert!((0.16..0.18).contains(&s.edge.mean_residual), "{s:?}");
    assert!(f.inside.iter().all(|&i| i), "every medial point is inside");
    assert_eq!(s.sheet.poking_out, 5, "{s:?}");
    // The surface passes through the spoke ends: no ball is larger than its shortest spoke.
    for (m, d) in f.distance.iter().enumerate() {
        let shortest = t
            .spokes(m)
            .iter()
            .map(|&b| (t.landmarks()[b] - t.landmarks()[t.atom_landmark(m)]).norm())
            .fold(f64::INFINITY, f64::min);
        assert!(*d <= shortest + 1e-12, "atom {m}: {d} > {shortest}");
    }
}

#[test]
fn shipped_templates_have_small_sheet_residuals() {
    for (case, at_most) in [
        ("toy", 0.02),
        ("cup", 0.002),
        ("t001", 0.014),
        ("t001-bent", 0.014),
    ] {
        let t = read(&Path::new(EXAMPLES).join(case).join("template.vtk"));
        let s = summary(&t, t.landmarks());
        assert!(
            s.sheet.mean_residual < at_most,
            "{case}: {} ≥ {at_most}",
            s.sheet.mean_residual
        );
    }
}

/// Bending the boundary of t001 by 25° and twisting it by 10° (the warp of
/// examples/t001-bent) while its medial points stay behind: the sheet atoms' residual grows
/// more than tenfold and most of their balls poke out.
#[test]
fn a_boundary_bent_without_its_medial_sheet_is_not_medial() {
    let t = read(Path::new(T001));
    let axes = PrincipalAxes::of(t.boundary_points()).unwrap();
    let warp = Warp::bending(&axes, 25.0, 10.0, &Matrix4::identity()).unwrap();
    let mut q = t.landmarks().to_vec();
    for p in &mut q[..t.boundary_count()] {
        *p = warp.apply(p);
    }
    let before = summary(&t, t.landmarks());
    let after = summary(&t, &q);
    assert!(
        after.sheet.mean_residual > 10.0 * before.sheet.mean_residual,
        "{:?} vs {:?}",
        after.sheet,
        before.sheet
    );
    assert!(
        2 * after.sheet.poking_out > after.sheet.atoms,
        "{:?}",
        after.sheet
    );
}

/// Medial points pushed out through the boundary along their first spoke (a fold of the
/// medial sheet through the wall): every one is outside, every ball pokes out.
#[test]
fn medial_points_outside_the_boundary_all_poke_out() {
    let t = read(Path::new(T001));
    let mut q = t.landmarks().to_vec();
    for m in 0..t.medial_count() {
        let (b, a) = (t.spokes(m)[0], t.atom_landmark(m));
        let spoke = q[b] - q[a];
        q[a] += 1.5 * spoke;
    }
    let f = BallFidelity::new(&t).measure(&q);
    assert!(f.inside.iter().all(|&i| !i));
    assert_eq!(
        f.summary.sheet.poking_out + f.summary.edge.poking_out,
        t.medial_count()
    );
}
