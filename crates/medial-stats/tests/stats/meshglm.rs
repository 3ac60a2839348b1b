//! cmrep's meshglm test data (`shared/data/cmrep/meshglm`): 40 subjects on a real mesh of
//! 1,586 points and 3,168 triangles, a planted effect (`truth`), meshglm's design and contrast.

use std::path::Path;

use medial_io::vtk::{read_polydata, DataArray, PolyData};
use medial_stats::{
    Contrast, Design, Elements, Glm, GlmOptions, Mesh, Observations, Options, Study, Support,
    TfceParameters,
};
use nalgebra::DVector;

const DATA: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../../shared/data/cmrep/meshglm/"
);

pub struct Meshglm {
    pub mesh: Mesh,
    pub design: Design,
    pub contrast: Contrast,
    pub y: Observations,
    pub truth: Vec<f64>,
}

fn array<'a>(arrays: &'a [DataArray], name: &str) -> &'a DataArray {
    arrays
        .iter()
        .find(|a| a.name == name)
        .unwrap_or_else(|| panic!("no array {name}"))
}

pub fn load(support: Support) -> Meshglm {
    let data: PolyData = read_polydata(&Path::new(DATA).join("test_meshglm_surface.vtk")).unwrap();
    let points = data.points.iter().map(|p| [p.x, p.y, p.z]).collect();
    let mesh = Mesh::new(points, data.triangles().unwrap()).unwrap();
    let arrays = match support {
        Support::Points => &data.point_data,
        Support::Cells => &data.cell_data,
    };
    let y = array(arrays, "Y");
    assert_eq!(y.components, 40);
    let design = Design::from_whitespace(
        &std::fs::read_to_string(Path::new(DATA).join("test_meshglm_surface_design.txt")).unwrap(),
    )
    .unwrap();
    let contrast_text =
        std::fs::read_to_string(Path::new(DATA).join("test_meshglm_surface_contrast.txt")).unwrap();
    let contrast = Contrast::parse(&contrast_text, &design).unwrap();
    Meshglm {
        mesh,
        design,
        contrast,
        y: Observations::new(40, y.values.clone()).unwrap(),
        truth: array(arrays, "truth").values.clone(),
    }
}

/// The area under the ROC curve of `score` for telling `positive` elements from the others
/// (the Mann–Whitney statistic, ties counted half).
pub fn auc(score: &[f64], positive: &[bool]) -> f64 {
    let (mut wins, mut pairs) = (0.0, 0.0);
    for (&si, _) in score.iter().zip(positive).filter(|(_, &p)| p) {
        for (&sj, _) in score.iter().zip(positive).filter(|(_, &p)| !p) {
            pairs += 1.0;
            wins += if si > sj {
                1.0
            } else if si == sj {
                0.5
            } else {
                0.0
            };
        }
    }
    wins / pairs
}

#[test]
fn t_equals_least_squares_at_every_point_and_cell() {
    for support in [Support::Points, Support::Cells] {
        let d = load(support);
        assert_eq!(d.design.names(), ["x1", "x2", "x3"]);
        assert_eq!(
            d.contrast
                .matrix()
                .row(0)
                .iter()
                .copied()
                .collect::<Vec<_>>(),
            [-1.0, 1.0, 0.05]
        );
        let glm = Glm::new(&d.design, &d.contrast, &d.y, &GlmOptions::default()).unwrap();
        let t = glm.statistic();
        let x = d.design.matrix();
        // Least squares by SVD, t from (XᵀX)⁻¹ by inversion.
        let svd = x.clone().svd(true, true);
        let xtx_inv = (x.transpose() * x).try_inverse().unwrap();
        let c = DVector::from_vec(vec![-1.0, 1.0, 0.05]);
        let variance_factor = (c.transpose() * &xtx_inv * &c)[(0, 0)];
        let mut worst = 0.0_f64;
        for (e, &te) in t.iter().enumerate() {
            let y = DVector::from_column_slice(d.y.element(e));
            let beta = svd.solve(&y, 1e-12).unwrap();
            let s2 = (&y - x * &beta).norm_squared() / 37.0;
            let expected = c.dot(&beta) / (s2 * variance_factor).sqrt();
            worst = worst.max((te - expected).abs() / expected.abs().max(1.0));
        }
        assert!(
            worst < 1e-9,
            "{support:?}: worst relative difference {worst:e}"
        );
    }
}

/// The planted effect is found: t ranks the elements of the truth first, and the significant
/// clusters lie in it. Prints the figures of docs/decisions/0100-stats-validation.md.
#[test]
fn the_planted_effect_is_found() {
    for support in [Support::Points, Support::Cells] {
        let d = load(support);
        let elements = Elements::new(&d.mesh, support);
        let options = Options {
            permutations: 1000,
            seed: 1,
            cluster_threshold: Some(3.0),
            tfce: Some(TfceParameters::default()),
            ..Options::default()
        };
        let r = Study::new(&d.design, &d.y, Some(&elements), options)
            .unwrap()
            .test(&d.contrast)
            .unwrap();
        let in_truth: Vec<bool> = d.truth.iter().map(|&v| v > 0.0).collect();
        let strong: Vec<bool> = d.truth.iter().map(|&v| v > 0.1).collect();
        let auc_any = auc(&r.statistic, &in_truth);
        let auc_strong = auc(&r.statistic, &strong);
        let clusters = r.clusters.as_ref().unwrap();
        let area = elements.areas();
        let significant: Vec<bool> = clusters.element_p().iter().map(|&p| p < 0.05).collect();
        let sum = |mask: &dyn Fn(usize) -> bool| {
            (0..area.len())
                .filter(|&e| mask(e))
                .map(|e| area[e])
                .sum::<f64>()
        };
        let found = sum(&|e| significant[e]);
        let inside = sum(&|e| significant[e] && in_truth[e]);
        let dice = 2.0 * sum(&|e| significant[e] && strong[e]) / (found + sum(&|e| strong[e]));
        let tfce_found = sum(&|e| r.p_tfce.as_ref().unwrap()[e] < 0.05);
        let tfce_inside = sum(&|e| r.p_tfce.as_ref().unwrap()[e] < 0.05 && in_truth[e]);
        let fwer_found = sum(&|e| r.p_fwer.as_ref().unwrap()[e] < 0.05);
        let fwer_inside = sum(&|e| r.p_fwer.as_ref().unwrap()[e] < 0.05 && in_truth[e]);
        println!(
            "{support:?}: AUC(t, truth > 0) = {auc_any:.3}, AUC(t, truth > 0.1) = {auc_strong:.3}; \
             clusters (t > 3) p < 0.05: {} of {}, {found:.1} mm², {:.1} % in truth > 0, Dice with truth > 0.1 = {dice:.3}; \
             TFCE p < 0.05: {tfce_found:.1} mm², {:.1} % in truth > 0; max-t p < 0.05: {fwer_found:.1} mm², {:.1} % in truth > 0",
            clusters.p_area.iter().filter(|&&p| p < 0.05).count(),
            clusters.found.clusters.len(),
            100.0 * inside / found,
            100.0 * tfce_inside / tfce_found,
            100.0 * fwer_inside / fwer_found,
        );
        assert!(auc_strong > 0.85, "{support:?}: AUC {auc_strong}");
        assert!(
            found > 0.0 && inside / found > 0.95,
            "{support:?}: {inside} of {found} mm²"
        );
        assert!(tfce_found > 0.0 && tfce_inside / tfce_found > 0.95);
    }
}
