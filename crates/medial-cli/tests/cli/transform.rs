//! The transform of an SSD stage in the conventions users bring: a plain RAS matrix (ours,
//! greedy's), the same matrix in LPS (`transform_convention = "lps"`), an ITK transform file
//! (always LPS, about its centre), and the inverse map with `transform_invert = true` — all
//! give the same SSD targets, read through `medial eval` at zero momenta.

use crate::common::{f, one_line_error, run_json, s};
use nalgebra::{Matrix4, Vector3, Vector4};
use std::path::{Path, PathBuf};

fn toy(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/toy")
        .join(name)
}

/// `D M D`, `D = diag(−1, −1, 1, 1)`.
fn flip(m: &Matrix4<f64>) -> Matrix4<f64> {
    let d = Matrix4::from_diagonal(&Vector4::new(-1.0, -1.0, 1.0, 1.0));
    d * m * d
}

fn matrix_text(m: &Matrix4<f64>) -> String {
    m.row_iter()
        .map(|r| format!("{:e} {:e} {:e} {:e}\n", r[0], r[1], r[2], r[3]))
        .collect()
}

/// An ITK file of the LPS map `m`, written about the centre `c`: `A (x − c) + t + c`, so
/// `t = m_t + A c − c`.
fn itk_text(m: &Matrix4<f64>, c: Vector3<f64>) -> String {
    let a = m.fixed_view::<3, 3>(0, 0).into_owned();
    let t = m.fixed_view::<3, 1>(0, 3).into_owned() + a * c - c;
    let mut parameters: Vec<String> = a.transpose().iter().map(|v| format!("{v:e}")).collect();
    parameters.extend(t.iter().map(|v| format!("{v:e}")));
    format!(
        "#Insight Transform File V1.0\n#Transform 0\nTransform: AffineTransform_double_3_3\n\
         Parameters: {}\nFixedParameters: {} {} {}\n",
        parameters.join(" "),
        c.x,
        c.y,
        c.z
    )
}

/// The data term of an SSD stage with the transform lines `keys`, at zero momenta.
fn ssd_data(dir: &Path, name: &str, keys: &str) -> f64 {
    let config = dir.join(format!("{name}.toml"));
    std::fs::write(
        &config,
        format!(
            "[model]\ntemplate = {:?}\n[flow]\nsigma = 2.0\ntime_steps = 2\n[[stage]]\n\
             name = \"affine\"\nattachment = \"ssd\"\nconstraints = false\n{keys}\n",
            s(&toy("template.vtk"))
        ),
    )
    .unwrap();
    let momenta = dir.join("u.npy");
    medial_io::npy::write_npy(&momenta, &[2, 311, 3], &vec![0.0; 2 * 311 * 3]).unwrap();
    f(&run_json(&["eval", s(&config), "--momenta", s(&momenta)])["data"])
}

#[test]
fn every_convention_gives_the_same_targets() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ras = medial_io::affine::read_affine(&toy("affine.txt"))
        .unwrap()
        .into_inner();
    let lps = flip(&ras);
    let write = |name: &str, text: String| {
        let path = d.join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    let plain = write("ras.txt", matrix_text(&ras));
    let lps_file = write("lps.txt", matrix_text(&lps));
    let itk = write("itk.txt", itk_text(&lps, Vector3::new(4.0, -7.0, 12.0)));
    let mut inverse = ras.try_inverse().unwrap();
    inverse.set_row(3, &nalgebra::RowVector4::new(0.0, 0.0, 0.0, 1.0));
    let inverse = write("inverse.txt", matrix_text(&inverse));
    let reference = ssd_data(d, "ras", &format!("transform = {:?}", s(&plain)));
    assert!(
        reference > 1.0,
        "the toy's affine part moves it: {reference}"
    );
    let cases = [
        (
            "lps",
            format!(
                "transform = {:?}\ntransform_convention = \"lps\"",
                s(&lps_file)
            ),
        ),
        ("itk", format!("transform = {:?}", s(&itk))),
        (
            "inverse",
            format!("transform = {:?}\ntransform_invert = true", s(&inverse)),
        ),
    ];
    for (name, keys) in cases {
        let data = ssd_data(d, name, &keys);
        assert!(
            (data - reference).abs() <= 1e-9 * reference,
            "{name}: {data} vs {reference}"
        );
    }
}

#[test]
fn transform_keys_need_a_transform_and_known_values() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("fit.toml");
    let write = |keys: &str| {
        std::fs::write(
            &config,
            format!(
                "[model]\ntemplate = {:?}\n[flow]\nsigma = 2.0\ntime_steps = 2\n[[stage]]\n\
                 name = \"b\"\nattachment = \"ssd\"\n{keys}\n",
                s(&toy("template.vtk"))
            ),
        )
        .unwrap();
    };
    let out = dir.path().join("out");
    write(&format!(
        "target = {:?}\ntransform_invert = true",
        s(&toy("target_boundary.vtk"))
    ));
    one_line_error(
        &["fit", s(&config), "--out", s(&out), "-q"],
        1,
        &["transform_invert needs transform"],
    );
    write(&format!(
        "transform = {:?}\ntransform_convention = \"xyz\"",
        s(&toy("affine.txt"))
    ));
    one_line_error(
        &["fit", s(&config), "--out", s(&out), "-q"],
        1,
        &["unknown variant `xyz`", "ras", "lps"],
    );
}
