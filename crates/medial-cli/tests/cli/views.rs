//! What a fit folder offers for viewing, checked by the tools people view it with: ParaView's
//! series, every point array seen by VTK's own legacy reader, `flow.glb` passing the Khronos
//! glTF validator, and `report.html` rendered by headless Chromium without a console message;
//! `medial report DIR` writes them again, showing any extra column of time_points.csv.
//!
//! The external tools are optional on a developer's machine (the checks that need one print
//! why they are skipped) and required in CI, where `.ci/run` installs them and sets
//! `MEDIAL_REQUIRE_TOOLS=1`: python3 with VTK (Debian's python3-vtk9), node with the npm package
//! gltf-validator (found through NODE_PATH), and Debian's chromium.

use crate::common::{medial, one_line_error, reseal, s, text};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// A short fit of the toy (an SSD stage, then three Dice AL iterations with μ rising), with
/// N = 10 time steps; returns its folder (shared by the tests of this file).
fn fitted() -> &'static Path {
    static FIT: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    let (_, out) = FIT.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let toy = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/toy");
        let toy = toy.canonicalize().unwrap();
        let config = format!(
            r#"
[model]
template = "{t}/template.vtk"
[flow]
sigma = 2.0
time_steps = 10
kinetic_weight = 0.005
[[stage]]
name = "affine"
attachment = "ssd"
transform = "{t}/affine.txt"
mu = 20.0
max_iterations = 40
[[stage]]
name = "dice"
attachment = "dice"
image = "{t}/target.nii.gz"
mu = 0.02
mu_factor = 10.0
al_iterations = 3
max_iterations = 25
"#,
            t = toy.display()
        );
        let path = dir.path().join("fit.toml");
        std::fs::write(&path, config).unwrap();
        let out = dir.path().join("toy");
        let o = medial(&["fit", s(&path), "--out", s(&out), "-q"]);
        // 4: constraints above tolerance after so few iterations; the results are written.
        assert!(
            matches!(o.status.code(), Some(0 | 4)),
            "{}",
            text(&o.stderr)
        );
        (dir, out)
    });
    out
}

/// Whether a check may run: `Ok(true)` if `available`, else says why it is skipped, or fails
/// where `MEDIAL_REQUIRE_TOOLS=1` (CI). The line is written to the process's stderr itself, not
/// through `eprintln!`, which the test harness captures: it shows without `--nocapture`
/// (libtest still prints `ok` for the test).
fn tool(available: bool, what: &str) -> bool {
    use std::io::Write;
    if !available {
        assert!(
            std::env::var("MEDIAL_REQUIRE_TOOLS").as_deref() != Ok("1"),
            "{what} is required (MEDIAL_REQUIRE_TOOLS=1) but missing"
        );
        let line = format!(
            "SKIPPED a check: {what} is not installed (.ci/run installs it; MEDIAL_REQUIRE_TOOLS=1 \
             makes this a failure)\n"
        );
        let _ = std::io::stderr().write_all(line.as_bytes());
    }
    available
}

/// Runs `program` with `args`; its output if it ran and succeeded.
fn run_ok(program: &str, args: &[&str]) -> Option<std::process::Output> {
    let o = Command::new(program).args(args).output().ok()?;
    o.status.success().then_some(o)
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn series_name_every_time_point_file_with_its_time() {
    let out = fitted();
    for kind in ["boundary", "medial"] {
        let series = read_json(&out.join(format!("flow/{kind}.vtk.series")));
        assert_eq!(series["file-series-version"], "1.0");
        let files = series["files"].as_array().unwrap();
        assert_eq!(files.len(), 11);
        for (n, file) in files.iter().enumerate() {
            let name = file["name"].as_str().unwrap();
            assert_eq!(name, format!("{kind}_t{n:03}.vtk"));
            assert!(out.join("flow").join(name).is_file());
            assert_eq!(file["time"].as_f64(), Some(n as f64 / 10.0));
        }
    }
}

/// The Python interpreter that has VTK, if one has.
fn vtk_python() -> Option<&'static str> {
    ["python3", "/usr/bin/python3"]
        .into_iter()
        .find(|p| run_ok(p, &["-c", "import vtk"]).is_some())
}

/// The names of the point arrays VTK's vtkPolyDataReader reads from `file` (default settings).
const LIST_ARRAYS: &str = "import sys, vtk
r = vtk.vtkPolyDataReader()
r.SetFileName(sys.argv[1])
r.Update()
d = r.GetOutput().GetPointData()
print(','.join(d.GetArrayName(i) for i in range(d.GetNumberOfArrays())))
n = d.GetNormals()
print(n.GetName() if n else '')";

#[test]
fn vtk_sees_every_point_array() {
    let Some(python) = vtk_python() else {
        tool(false, "python3 with VTK (python3-vtk9)");
        return;
    };
    let out = fitted();
    for (file, normals) in [
        ("flow/boundary_t010.vtk", ""),
        ("flow/medial_t010.vtk", ""),
        ("fitted_template.vtk", "Normals"),
    ] {
        let path = out.join(file);
        let ours: Vec<String> = medial_io::vtk::read_polydata(&path)
            .unwrap()
            .point_data
            .into_iter()
            .map(|a| a.name)
            .collect();
        assert!(ours.len() >= 2, "{file}: {ours:?}");
        let o = run_ok(python, &["-c", LIST_ARRAYS, s(&path)]).expect("the VTK script runs");
        let printed = text(&o.stdout);
        let mut lines = printed.lines();
        let seen: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
        assert_eq!(
            seen, ours,
            "{file}: VTK reads other arrays than medial wrote"
        );
        // cmrep reads a template's normals as the point data's normals.
        assert_eq!(lines.next().unwrap_or_default(), normals, "{file}");
    }
}

/// Validates `glb` with the Khronos glTF validator; its report, if node has the validator.
fn validate_gltf(glb: &Path) -> Option<Value> {
    const VALIDATE: &str = "const v = require('gltf-validator');
const bytes = new Uint8Array(require('fs').readFileSync(process.argv[1]));
v.validateBytes(bytes, { maxIssues: 50 }).then(
  (r) => console.log(JSON.stringify(r.issues)),
  (e) => { console.error(e); process.exit(2); });";
    run_ok("node", &["-e", "require.resolve('gltf-validator')"])?;
    let o = run_ok("node", &["-e", VALIDATE, s(glb)]).expect("the validator runs");
    Some(serde_json::from_slice(&o.stdout).expect("the validator's JSON report"))
}

#[test]
fn flow_glb_passes_the_gltf_validator() {
    let glb = fitted().join("flow.glb");
    let gltf = gltf::Gltf::open(&glb).expect("flow.glb reads");
    let names: Vec<&str> = gltf
        .default_scene()
        .unwrap()
        .nodes()
        .filter_map(|n| n.name())
        .collect();
    assert_eq!(names, ["boundary", "medial"]);
    assert_eq!(gltf.animations().count(), 1);
    let Some(issues) = validate_gltf(&glb) else {
        tool(
            false,
            "node with the npm package gltf-validator (NODE_PATH)",
        );
        return;
    };
    assert_eq!(issues["numErrors"], 0, "{issues}");
    assert_eq!(issues["numWarnings"], 0, "{issues}");
    // The check can fail: a file cut short is reported.
    let dir = tempfile::tempdir().unwrap();
    let cut = dir.path().join("cut.glb");
    let bytes = std::fs::read(&glb).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() - 8]).unwrap();
    let issues = validate_gltf(&cut).unwrap();
    assert!(issues["numErrors"].as_u64() > Some(0), "{issues}");
}

/// Renders `page` in headless Chromium into `png`; the lines Chromium logged for the page's
/// console (`:CONSOLE`), or `None` without Chromium.
fn render(page: &Path, png: &Path, profile: &Path) -> Option<Vec<String>> {
    run_ok("chromium", &["--version"])?;
    let url = format!("file://{}", page.canonicalize().unwrap().display());
    let o = Command::new("chromium")
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
            "--enable-logging=stderr",
            "--log-level=0",
            "--window-size=1100,3000",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("--screenshot={}", png.display()))
        .arg(url)
        .output()
        .expect("chromium runs");
    assert!(png.is_file(), "no screenshot: {}", text(&o.stderr));
    let log = text(&o.stderr);
    Some(
        log.lines()
            .filter(|l| l.contains(":CONSOLE"))
            .map(str::to_owned)
            .collect(),
    )
}

/// The share of pixels of a PNG that are not white, and the number of distinct colours.
fn ink(png: &Path) -> (f64, usize) {
    let bytes = std::fs::read(png).unwrap();
    let mut reader = png::Decoder::new(std::io::Cursor::new(bytes))
        .read_info()
        .unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    let pixels: Vec<&[u8]> = buf[..info.buffer_size()].chunks(channels).collect();
    let inked = pixels
        .iter()
        .filter(|p| p[..3].iter().any(|&c| c < 235))
        .count();
    let mut colours: Vec<&[u8]> = pixels.clone();
    colours.sort_unstable();
    colours.dedup();
    (inked as f64 / pixels.len() as f64, colours.len())
}

#[test]
fn report_renders_in_chromium_without_console_messages() {
    let out = fitted();
    let page = out.join("report.html");
    let html = std::fs::read_to_string(&page).unwrap();
    // Self-contained: nothing to load, no script (SVG's namespace is a name, not a load).
    let loads = html.replace("xmlns=\"http://www.w3.org/2000/svg\"", "");
    for outside in ["<script", "src=", "<link", "url(", "http:", "https:"] {
        assert!(!loads.contains(outside), "the report holds {outside:?}");
    }
    // The slices, the 3-D view, per stage a figure, the figures over time, the histogram.
    assert_eq!(html.matches("<svg").count(), 6);
    for needle in [
        "The model on the data",
        "data:image/png;base64,",
        "Stage 'affine'",
        "Stage 'dice'",
        "μ = 0.2",
        "data term g",
        "kinetic energy KE",
        "penalty P",
        "max spoke–normal angle (°)",
        "max spoke mismatch (%)",
        "min thickness (mm)",
        "spoke lengths of the model",
        "mu_factor = 10.0",
    ] {
        assert!(html.contains(needle), "the report lacks {needle:?}");
    }
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("report.png");
    let Some(console) = render(&page, &png, &dir.path().join("profile")) else {
        tool(false, "chromium");
        return;
    };
    assert!(console.is_empty(), "the page logged: {console:?}");
    let (inked, colours) = ink(&png);
    assert!(
        inked > 0.03 && colours > 50,
        "blank screenshot: {inked} inked, {colours} colours"
    );
    // The console check can fail: a page with an error is caught.
    let bad = dir.path().join("bad.html");
    std::fs::write(&bad, "<p>x</p><script>undefinedFunction()</script>").unwrap();
    let console = render(&bad, &dir.path().join("bad.png"), &dir.path().join("p2")).unwrap();
    assert!(
        console.iter().any(|l| l.contains("undefinedFunction")),
        "{console:?}"
    );
}

/// A copy of the shared fit's folder in `dir`, named `toy` as the fit's (the report names its
/// folder).
fn copy_fit(dir: &Path) -> PathBuf {
    let copy = dir.join("toy");
    std::fs::create_dir_all(copy.join("flow")).unwrap();
    for entry in std::fs::read_dir(fitted())
        .unwrap()
        .chain(std::fs::read_dir(fitted().join("flow")).unwrap())
    {
        let path = entry.unwrap().path();
        let relative = path.strip_prefix(fitted()).unwrap();
        if path.is_file() {
            std::fs::copy(&path, copy.join(relative)).unwrap();
        }
    }
    copy
}

#[test]
fn report_command_writes_the_views_again_and_shows_extra_columns() {
    let dir = tempfile::tempdir().unwrap();
    let copy = copy_fit(dir.path());
    let views = [
        "report.html",
        "flow.glb",
        "flow/boundary.vtk.series",
        "flow/medial.vtk.series",
    ];
    for view in views {
        std::fs::remove_file(copy.join(view)).unwrap();
    }
    let o = medial(&["report", s(&copy)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    for view in views {
        let again = std::fs::read(copy.join(view)).unwrap();
        let first = std::fs::read(fitted().join(view)).unwrap();
        assert!(again == first, "{view} differs");
    }
    // A column that a later version adds to time_points.csv is drawn and tabulated.
    let csv = std::fs::read_to_string(copy.join("time_points.csv")).unwrap();
    let extended: String = csv
        .lines()
        .enumerate()
        .map(|(i, line)| match i {
            0 => format!("{line},mean_ball_residual\n"),
            _ => format!("{line},{}\n", 0.01 * i as f64),
        })
        .collect();
    std::fs::write(copy.join("time_points.csv"), extended).unwrap();
    reseal(&copy);
    let o = medial(&["report", s(&copy)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let html = std::fs::read_to_string(copy.join("report.html")).unwrap();
    assert!(
        html.contains("mean ball residual"),
        "the extra column is not shown"
    );
    assert!(html.contains("<th>mean_ball_residual</th>"));
}

#[test]
fn report_of_a_folder_that_is_not_a_fit_is_one_line_error() {
    let dir = tempfile::tempdir().unwrap();
    let line = one_line_error(&["report", s(dir.path())], 1, &["summary.json"]);
    assert!(line.contains("summary.json"), "{line}");
    std::fs::write(
        dir.path().join("summary.json"),
        "{\"status\": \"converged\"}",
    )
    .unwrap();
    one_line_error(&["report", s(dir.path())], 1, &["time_steps", "fit folder"]);
}

/// The number of polylines of `colour` (`#RRGGBB`) drawn 2 px wide: the sections in the slices.
fn sections(html: &str, colour: &str) -> usize {
    html.matches(&format!("stroke=\"{colour}\" stroke-width=\"2\""))
        .count()
}

/// The slice panels' titles in the report.
fn panel_titles(html: &str) -> Vec<String> {
    let mut titles = Vec::new();
    for when in ["start (t = 0)", "fitted (t = 1)"] {
        for plane in ["sagittal, x = ", "coronal, y = ", "axial, z = "] {
            let at = html
                .find(plane)
                .and_then(|i| html[i..].find(when).map(|j| (i, i + j + when.len())));
            if let Some((a, b)) = at {
                titles.push(html[a..b].to_owned());
            }
        }
    }
    titles
}

/// Issue 34: the report shows the model on the data, the toy's segmentation at three
/// orthogonal planes with the boundary and the medial sheet cut by them, at the start and at
/// the end, and a rendered 3-D view (a PNG that decodes, with the model's colours in it).
#[test]
fn report_shows_the_model_on_the_image_at_three_planes() {
    let html = std::fs::read_to_string(fitted().join("report.html")).unwrap();
    assert_eq!(panel_titles(&html).len(), 6, "{:?}", panel_titles(&html));
    assert!(html.contains("target.nii.gz"));
    // The foreground in grey; each of the six panels cuts the boundary and the medial sheet.
    assert!(html.matches("fill=\"#C8C8C8\"").count() > 30);
    assert!(sections(&html, "#D62728") >= 6, "boundary sections");
    assert!(sections(&html, "#1F77B4") >= 6, "medial sections");
    // The 3-D view: three renderings side by side, not blank.
    let start = html.find("data:image/png;base64,").unwrap() + 22;
    let end = start + html[start..].find('"').unwrap();
    let png = decode_base64(&html[start..end]);
    let mut reader = png::Decoder::new(std::io::Cursor::new(png))
        .read_info()
        .unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (900, 250));
    let coloured = buf[..info.buffer_size()]
        .chunks(3)
        .filter(|p| p.iter().any(|&c| c < 200))
        .count();
    assert!(coloured > 900 * 250 / 10, "{coloured} pixels of the model");
}

/// Standard base64 with padding.
fn decode_base64(text: &str) -> Vec<u8> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        b'/' => 63,
        _ => panic!("not base64: {c}"),
    };
    let mut out = Vec::new();
    for group in text.as_bytes().chunks(4) {
        let digits: Vec<u8> = group
            .iter()
            .filter(|&&c| c != b'=')
            .map(|&c| value(c))
            .collect();
        let n = digits
            .iter()
            .enumerate()
            .fold(0u32, |n, (k, &d)| n | u32::from(d) << (18 - 6 * k));
        out.extend((0..digits.len() - 1).map(|k| (n >> (16 - 8 * k)) as u8));
    }
    out
}

/// `config.toml` of `copy` with the dice stage's target (its `image = ...` or `surface = ...`
/// line) replaced by `line`.
fn retarget(copy: &Path, line: &str) {
    let config = std::fs::read_to_string(copy.join("config.toml")).unwrap();
    let changed: Vec<String> = config
        .lines()
        .map(
            |l| match l.starts_with("image = ") || l.starts_with("surface = ") {
                true => line.to_owned(),
                false => l.to_owned(),
            },
        )
        .collect();
    assert_ne!(
        changed.join("\n"),
        config.trim_end(),
        "config.toml names no target"
    );
    std::fs::write(copy.join("config.toml"), changed.join("\n")).unwrap();
    reseal(copy);
}

/// For a fit to a surface the same planes show the target surface's section (black) instead of
/// the image; a target that is gone leaves the model drawn alone, with a note, and the report
/// is still written.
#[test]
fn report_of_a_surface_target_and_of_a_missing_one() {
    let dir = tempfile::tempdir().unwrap();
    let copy = copy_fit(dir.path());
    let toy = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/toy");
    let surface = toy.join("target_boundary.vtk").canonicalize().unwrap();
    retarget(&copy, &format!("surface = {:?}", s(&surface)));
    let o = medial(&["report", s(&copy)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let html = std::fs::read_to_string(copy.join("report.html")).unwrap();
    assert_eq!(panel_titles(&html).len(), 6);
    assert!(html.contains("target_boundary.vtk"));
    assert!(
        !html.contains("fill=\"#C8C8C8\""),
        "an image drawn for a surface fit"
    );
    assert!(sections(&html, "#000000") >= 6, "the surface's sections");
    assert!(sections(&html, "#D62728") >= 6);

    retarget(&copy, "image = \"/nonexistent/target.nii.gz\"");
    let o = medial(&["report", s(&copy)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let html = std::fs::read_to_string(copy.join("report.html")).unwrap();
    assert!(html.contains("/nonexistent/target.nii.gz cannot be read"));
    assert!(html.contains("the model is drawn alone"));
    assert_eq!(panel_titles(&html).len(), 6);
    assert!(sections(&html, "#D62728") >= 6);
}

/// The curves mark every start of a minimisation: each AL iteration with its μ, the switch from
/// coarse to fine time steps, a restart; the stage's title counts its iterations as the
/// summary's table does (not the log's rows, one more per minimisation). And an automatic
/// fit's alignment is a table of its steps with the map.
#[test]
fn report_marks_the_switch_and_restarts_and_tabulates_the_alignment() {
    let dir = tempfile::tempdir().unwrap();
    let copy = copy_fit(dir.path());
    // The dice stage's first AL iteration in 5 time steps, its second restarted half-way.
    let log = std::fs::read_to_string(copy.join("log.csv")).unwrap();
    let mut lines: Vec<Vec<String>> = log
        .lines()
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    let header = lines[0].clone();
    let col = |name: &str| header.iter().position(|c| c == name).unwrap();
    let (stage, al, iteration, steps) = (
        col("stage"),
        col("al_iteration"),
        col("iteration"),
        col("time_steps"),
    );
    let second: Vec<usize> = (1..lines.len())
        .filter(|&i| lines[i][stage] == "dice" && lines[i][al] == "1")
        .collect();
    assert!(second.len() > 4);
    let half = second[second.len() / 2];
    for row in lines.iter_mut().skip(1) {
        if row[stage] == "dice" && row[al] == "0" {
            row[steps] = "5".into();
        }
    }
    for &i in second.iter().filter(|&&i| i >= half) {
        let n: usize = lines[i][iteration].parse().unwrap();
        let first: usize = lines[half][iteration].parse().unwrap();
        lines[i][iteration] = (n - first).to_string();
    }
    let csv: String = lines.iter().map(|l| l.join(",") + "\n").collect();
    std::fs::write(copy.join("log.csv"), csv).unwrap();
    // An automatic fit's alignment.
    let mut summary = read_json(&copy.join("summary.json"));
    summary["alignment"] = serde_json::json!([
        "initial similarity: scale 1.0383, voxel Dice 0.695 → 0.799",
        "initial affine: anisotropy 11.3 %, voxel Dice 0.799 → 0.803"
    ]);
    summary["files"]
        .as_array_mut()
        .unwrap()
        .push("alignment.txt".into());
    std::fs::write(copy.join("summary.json"), summary.to_string()).unwrap();
    std::fs::write(
        copy.join("alignment.txt"),
        "1.5 0 0 2\n0 1 0 0\n0 0 1 0\n0 0 0 1\n",
    )
    .unwrap();
    reseal(&copy);
    let o = medial(&["report", s(&copy)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let html = std::fs::read_to_string(copy.join("report.html")).unwrap();
    for needle in [
        "AL 1, μ = 0.02",
        "AL 2, μ = 0.2, 5 → 10 time steps",
        ">\nrestart\n</text>",
        "Initial alignment",
        "<td class=\"key\">initial affine</td><td class=\"key\">anisotropy 11.3 %, voxel Dice 0.799 → 0.803</td>",
        "<td>1.5</td>",
    ] {
        assert!(html.contains(needle), "the report lacks {needle:?}");
    }
    for s in summary["stages"].as_array().unwrap() {
        let (n, al) = (&s["iterations"], s["al_iterations"].as_u64().unwrap());
        let plural = if al == 1 { "" } else { "s" };
        let title = format!(
            "Stage '{}' ({n} L-BFGS iterations in {al} AL iteration{plural})",
            s["name"].as_str().unwrap()
        );
        assert!(html.contains(&title), "no title {title:?}");
    }
}
