//! Extraction quality against ground truth on the committed fixtures, the angle sweep, and
//! determinism across thread counts. Larger (500 k-point) runs live in scripts/quality.sh.

use crate::common;

use crease::curves::{read_obj, Polyline};
use crease::eval::{evaluate, EvalOptions, Scores};
use crease::extract::Params;
use crease::run::{extract_cloud, Extraction, RunOptions};

/// The in-memory pipeline, with default options.
fn extract(points: &[glam::DVec3], params: &Params) -> Extraction {
    extract_cloud(points, params, &RunOptions::default()).expect("extraction")
}
use crease::io::{Filter, PointReader};
use crease::synth::{self, shape, Sampling, SynthOptions};
use glam::DVec3;
use std::path::{Path, PathBuf};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures").join(name)
}

fn run_fixture(name: &str) -> (Vec<Polyline>, Scores) {
    let pts = PointReader::open(&fixture(&format!("{name}.las")), &Filter::default()).unwrap().read_all().unwrap();
    let truth = read_obj(&fixture(&format!("{name}.truth.obj"))).unwrap();
    let ex = extract(&pts.xyz, &Params::default());
    let s = evaluate(&truth, &ex.curves, &EvalOptions::default());
    eprintln!("{name}: {s:?}");
    (ex.curves, s)
}

fn assert_scores(name: &str, s: &Scores, recall: f64, precision: f64, mean: f64) {
    assert!(s.recall >= recall, "{name}: recall {} < {recall}", s.recall);
    let p = s.precision.expect("curves were extracted");
    assert!(p >= precision, "{name}: precision {p} < {precision}");
    let m = s.mean_distance.unwrap();
    assert!(m <= mean, "{name}: mean distance {m} dB > {mean}");
}

/// The cube: exactly 12 curves meeting in 8 corners, each corner shared by three curves and
/// within 0.005 dB of the true corner.
#[test]
fn cube_has_twelve_curves_and_eight_shared_corners() {
    let (curves, s) = run_fixture("cube");
    assert_scores("cube", &s, 0.98, 0.97, 0.001);
    assert_eq!(curves.len(), 12);
    let mut corners: Vec<DVec3> = vec![];
    for c in &curves {
        assert!(!c.closed);
        for v in [c.vertices.first().unwrap(), c.vertices.last().unwrap()] {
            assert!(v.corner, "every cube curve ends at a corner");
            if !corners.contains(&v.p) {
                corners.push(v.p);
            }
        }
    }
    assert_eq!(corners.len(), 8, "corners are shared vertices: {corners:?}");
    let db = 3f64.sqrt();
    for k in &corners {
        let ends = curves.iter().filter(|c| c.vertices.first().unwrap().p == *k || c.vertices.last().unwrap().p == *k).count();
        assert_eq!(ends, 3, "three curves meet at {k}");
        let truth = k.round();
        assert!(k.distance(truth) <= 0.005 * db, "corner {k} is {} dB from {truth}", k.distance(truth) / db);
    }
}

#[test]
fn cad_shapes_without_noise() {
    for name in ["fandisk", "holecube", "step", "octahedron"] {
        let (_, s) = run_fixture(name);
        // The fandisk's ridge fades out: the truth stops where its crease falls below 30
        // degrees, the extraction somewhat later, which costs a little precision.
        let precision = if name == "fandisk" { 0.95 } else { 0.97 };
        assert_scores(name, &s, 0.98, precision, 0.001);
    }
}

#[test]
fn sampled_mesh() {
    let (_, s) = run_fixture("anchor");
    assert_scores("anchor", &s, 0.98, 0.95, 0.002);
}

/// The anchor mesh at 0.005 dB noise (the row: recall >= 0.96, precision >= 0.95),
/// sampled and extracted as a user would, with `crease synth mesh` and `crease extract`. Under
/// noise its small bosses and holes leave short fragments of curve; completion must not link
/// them across faces (precision 0.974 here; 0.866 when ends looked the full reach ahead
/// whatever their curve's length). Needs `../shared/data/meshes`.
#[test]
#[ignore = "needs ../shared"]
fn noisy_sampled_mesh() {
    let (curves, s) = cli_mesh_scores("anchor", &["-n", "200000", "--noise", "0.005", "--seed", "2"]);
    eprintln!("anchor 0.005 dB: {} curves, {s:?}", curves.len());
    assert!(s.recall >= 0.96, "recall {}", s.recall);
    assert!(s.precision.unwrap() >= 0.95, "precision {:?}", s.precision);
}

/// The anchor mesh at 0.01 dB noise, 500 k points, the row (recall at least 0.95,
/// precision at least 0.93, mean distance at most 0.003 dB). Its small bolt holes curve as tightly as the
/// neighbourhoods are wide; it met the row once the points kept of the thinned cloud were
/// averaged over the points dropped around them. Needs `../shared/data/meshes`.
#[test]
#[ignore = "needs ../shared"]
fn anchor_at_one_percent_noise() {
    let (curves, s) = cli_mesh_scores("anchor", &["-n", "500000", "--noise", "0.01"]);
    eprintln!("anchor 0.01 dB: {} curves, {s:?}", curves.len());
    assert!(s.recall >= 0.95, "recall {}", s.recall);
    assert!(s.precision.unwrap() >= 0.93, "precision {:?}", s.precision);
    assert!(s.mean_distance.unwrap() <= 0.003, "mean distance {:?}", s.mean_distance);
}

/// `../shared/data/meshes/<name>.off` sampled with `crease synth mesh` (options `synth`) and
/// extracted with `crease extract`, as a user would: the curves and their scores.
fn cli_mesh_scores(name: &str, synth: &[&str]) -> (Vec<Polyline>, Scores) {
    let off = common::shared_data(&format!("meshes/{name}.off"));
    let d = tempfile::tempdir().unwrap();
    let (las, out) = (d.path().join(format!("{name}.las")), d.path().join("out"));
    let crease = |args: &[&str]| {
        let st = std::process::Command::new(env!("CARGO_BIN_EXE_crease")).args(args).status().unwrap();
        assert!(st.success(), "crease {args:?}");
    };
    let mut args = vec!["synth", "mesh", off.to_str().unwrap()];
    args.extend_from_slice(synth);
    args.extend(["-o", las.to_str().unwrap()]);
    crease(&args);
    crease(&["extract", las.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"]);
    let truth = read_obj(&d.path().join(format!("{name}.truth.obj"))).unwrap();
    let curves = read_obj(&out.join("curves.obj")).unwrap();
    let s = evaluate(&truth, &curves, &EvalOptions::default());
    (curves, s)
}

#[test]
fn noisy_cube() {
    let (_, s) = run_fixture("cube_noise005");
    assert_scores("cube_noise005", &s, 0.96, 0.95, 0.003);
}

/// The 0.02 dB row of the issue (recall >= 0.90): curves must run true into the corners,
/// where the projection's edge points and corners are biased by the third surface.
#[test]
fn cube_at_two_percent_noise() {
    let o = SynthOptions { n: 200_000, noise: 0.02, noise_spacing: 0.0, outliers: 0.0, sampling: Sampling::Uniform, seed: 5 };
    let (curves, s) = synth_scores("cube", 0.0, &o);
    eprintln!("cube 0.02 dB: {} curves, {s:?}", curves.len());
    assert!(s.recall >= 0.90, "recall {}", s.recall);
    assert!(s.precision.unwrap() >= 0.90, "precision {:?}", s.precision);
}

/// Fandisk at 0.01 dB noise, the row (recall >= 0.95, precision >= 0.93, mean <= 0.003
/// dB). The feet of its fading ridge, 30-45 degree creases, are found only with the
/// candidates' crease test (without it: recall 0.928 here, 0.91 / 0.94 in the quality table at
/// seeds 1 / 2; the feet's max residual is under tau). Also: the same curves at 1 and 2
/// threads on this noisy path.
#[test]
fn fandisk_at_one_percent_noise() {
    let o = SynthOptions { n: 500_000, noise: 0.01, noise_spacing: 0.0, outliers: 0.0, sampling: Sampling::Uniform, seed: 1 };
    let sh = shape("fandisk", 0.0).unwrap();
    let pts = synth::sample(&sh, &o);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| extract(&pts, &Params::default()).curves)
    };
    let (curves, one) = (run(2), run(1));
    assert_eq!(curves, one, "1 and 2 threads differ");
    let truth = synth::truth_polylines(&sh.truth);
    let s = evaluate(&truth, &curves, &EvalOptions { diag: Some(crease::points::Bounds::of(pts.iter().copied()).diagonal()), ..Default::default() });
    eprintln!("fandisk 0.01 dB: {} curves, {s:?}", curves.len());
    assert_scores("fandisk 0.01 dB", &s, 0.95, 0.93, 0.003);
}

/// Joint at 0.01 dB noise: its bore (radius about one projection radius) gave spurious curves
/// along the wall, grown through lone edge points that the consensus filter now drops (without
/// it: precision 0.936 and mean distance 0.0049 dB at seed 1). Needs `../shared/data/meshes`.
#[test]
#[ignore = "needs ../shared"]
fn joint_bore_under_noise() {
    let (curves, s) = cli_mesh_scores("joint", &["-n", "500000", "--noise", "0.01"]);
    eprintln!("joint 0.01 dB: {} curves, {s:?}", curves.len());
    assert_scores("joint 0.01 dB", &s, 0.95, 0.95, 0.003);
}

fn synth_scores(name: &str, angle: f64, opts: &SynthOptions) -> (Vec<Polyline>, Scores) {
    let sh = shape(name, angle).unwrap();
    let pts = synth::sample(&sh, opts);
    let truth = synth::truth_polylines(&sh.truth);
    let ex = extract(&pts, &Params::default());
    let s = evaluate(&truth, &ex.curves, &EvalOptions { diag: Some(crease::points::Bounds::of(pts.iter().copied()).diagonal()), ..Default::default() });
    (ex.curves, s)
}

/// Weber's angle sweep: two planes meeting at a dihedral angle.
#[test]
fn angle_sweep() {
    for angle in [25.0, 45.0, 60.0, 90.0, 110.0, 140.0, 150.0, 160.0, 170.0] {
        let o = SynthOptions { n: 20_000, noise: 0.0, noise_spacing: 0.0, outliers: 0.0, sampling: Sampling::Uniform, seed: angle as u64 };
        let (curves, s) = synth_scores("wedge", angle, &o);
        eprintln!("wedge {angle}: {} curves, recall {} precision {:?}", curves.len(), s.recall, s.precision);
        if angle <= 150.0 {
            assert!(s.recall >= 0.95, "wedge {angle}: recall {}", s.recall);
        }
        if !curves.is_empty() {
            assert!(s.precision.unwrap() >= 0.95, "wedge {angle}: precision {:?}", s.precision);
        }
    }
}

/// Outliers and scan-line sampling: no curve through empty space.
#[test]
fn outliers_and_scan_lines() {
    let o = SynthOptions { n: 30_000, noise: 0.0, noise_spacing: 0.0, outliers: 0.05, sampling: Sampling::Uniform, seed: 3 };
    let (_, s) = synth_scores("cube", 90.0, &o);
    assert!(s.recall >= 0.95 && s.precision.unwrap() >= 0.95, "outliers: {s:?}");
    let o = SynthOptions { n: 60_000, noise: 0.0, noise_spacing: 0.0, outliers: 0.0, sampling: Sampling::ScanLines { anisotropy: 4.0 }, seed: 4 };
    let (_, s) = synth_scores("cube", 90.0, &o);
    assert!(s.recall >= 0.95 && s.precision.unwrap() >= 0.95, "scan lines: {s:?}");
}

/// The same input gives the same curves whatever the thread count.
#[test]
fn deterministic_across_thread_counts() {
    let pts = PointReader::open(&fixture("fandisk.las"), &Filter::default()).unwrap().read_all().unwrap();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| extract(&pts.xyz, &Params::default()).curves)
    };
    let (a, b) = (run(1), run(2));
    assert!(!a.is_empty());
    assert_eq!(a, b);
}

/// A file and its points in memory give the same curves, to the bit, though the file's header
/// declares bounds a little wider than its points (fandisk's are rounded to 1e-5): the curve
/// stage is anchored on whole cells, not at the declared bounds' corner (the Python binding's
/// `extract` and `crease extract` agree).
#[test]
fn a_file_and_its_points_in_memory_give_the_same_curves() {
    let f = fixture("fandisk.las");
    let pts = PointReader::open(&f, &Filter::default()).unwrap().read_all().unwrap();
    let header = crease::io::read_header(&f).unwrap();
    let exact = crease::points::Bounds::of(pts.xyz.iter().copied());
    assert_ne!(header.bounds.min, exact.min, "the fixture's header bounds are no longer looser than its points");
    let memory = extract(&pts.xyz, &Params::default()).curves;
    let d = tempfile::tempdir().unwrap();
    crease::run::run_extract(&[f], d.path(), &Params::default(), &Filter::default(), &RunOptions::default()).unwrap();
    let file = crease::curves::read_ply(&d.path().join("curves.ply")).unwrap();
    assert!(!memory.is_empty());
    assert_eq!(memory.len(), file.len());
    for (a, b) in memory.iter().zip(&file) {
        assert!(a.vertices.iter().map(|v| v.p).eq(b.vertices.iter().map(|v| v.p)), "curve {}: positions differ", a.id);
    }
}

/// Clutter: one block of the scene with a tree by the road (volumetric scatter), rough grass
/// and recessed windows, 0.01 m noise. The tree's "surfaces" fit too badly to meet at edges,
/// so its curves are gone (crease 0.4 drew curves through it: precision 0.917 at 0.1 m on this
/// block), and the designed edges, windows included, are found.
#[test]
fn clutter_scene_keeps_the_designed_edges_and_nothing_in_the_tree() {
    let d = tempfile::tempdir().unwrap();
    let las = d.path().join("block.las");
    let opts = synth::SceneOptions { n: 400_000, noise: 0.01, seed: 3, clutter: true };
    synth::write_scene(&opts, &las).unwrap();
    let pts = PointReader::open(&las, &Filter::default()).unwrap().read_all().unwrap();
    assert!(pts.class.contains(&5), "the block has a tree");
    let truth = read_obj(&synth::truth_path(&las)).unwrap();
    let ex = extract(&pts.xyz, &Params::default());
    assert!(ex.counts.scattered > 0);
    // Scored at 0.1 m: the block's diagonal is about 40 m.
    let diag = 40.0;
    let s = evaluate(&truth, &ex.curves, &EvalOptions { diag: Some(diag), tol: 0.1 / diag, step: 0.02 / diag, resolvable: None });
    eprintln!("clutter block: {s:?}");
    assert!(s.recall >= 0.95, "recall {}", s.recall);
    assert!(s.precision.unwrap() >= 0.97, "precision {:?}", s.precision);
}

/// Each curve's `angle` is the dihedral angle of its crease (the wedge the two surfaces enclose),
/// not the angle between unoriented normals, which reads 60 for a 120 degree crease.
#[test]
fn a_curve_states_the_dihedral_angle_of_its_crease() {
    let octahedron = 180.0 - (1.0f64 / 3.0).acos().to_degrees();
    for (name, angle, dihedral) in [("wedge", 60.0, 60.0), ("wedge", 120.0, 120.0), ("wedge", 150.0, 150.0), ("octahedron", 90.0, octahedron)] {
        let s = shape(name, angle).unwrap();
        let pts = synth::sample(&s, &SynthOptions { n: 60_000, seed: 1, ..Default::default() });
        let curves = extract(&pts, &Params::default()).curves;
        assert!(!curves.is_empty(), "{name} {angle}");
        for c in &curves {
            let a = c.mean_dihedral_angle().expect("normals");
            assert!((a - dihedral).abs() < 1.0, "{name} {angle}: curve {} at {a:.2} degrees, not {dihedral:.2}", c.id);
        }
    }
}

/// Seen from where a scanner stood, each crease of the step (an L-shaped prism) reads convex or
/// concave as it is: the inside corner of the L concave, every other edge that the scanner sees
/// a surface of convex, clean and under noise. Edges whose both surfaces face away from the
/// scanner were not seen by it, and are not checked. Seen from above, the top's outline is
/// convex and the vertical edges are not told.
#[test]
fn a_curve_states_whether_its_crease_is_convex_or_concave() {
    use crease::curves::{Outside, Shape};
    let step = shape("step", 90.0).unwrap();
    let scanner = Outside::Scanners(vec![DVec3::new(3.0, 3.0, 3.0)]);
    let near = |a: f64, b: f64| (a - b).abs() < 0.05;
    for noise in [0.0, 0.01] {
        let pts = synth::sample(&step, &SynthOptions { n: 100_000, noise, seed: 3, ..Default::default() });
        let curves = extract(&pts, &Params::default()).curves;
        let (mut checked, mut vertical) = (0, 0);
        for c in &curves {
            let m = c.vertices[c.vertices.len() / 2].p;
            let (first, last) = (c.vertices[0].p, c.vertices[c.vertices.len() - 1].p);
            let unseen = (near(m.x, 0.0) && near(m.y, 0.0)) || (near(m.z, 0.0) && (near(m.x, 0.0) || near(m.y, 0.0)));
            if !unseen {
                let truth = if near(m.x, 0.4) && near(m.y, 0.4) { Shape::Concave } else { Shape::Convex };
                assert_eq!(scanner.shape(c), truth, "noise {noise}: curve {} through {m}", c.id);
                checked += 1;
            }
            if near(m.z, 1.0) && near(first.z, 1.0) && near(last.z, 1.0) {
                assert_eq!(Outside::Up.shape(c), Shape::Convex, "noise {noise}: top edge {} through {m}", c.id);
            } else if (last - first).normalize().z.abs() > 0.99 {
                assert_eq!(Outside::Up.shape(c), Shape::Unknown, "noise {noise}: vertical edge {} through {m}", c.id);
                vertical += 1;
            }
        }
        assert!(checked >= 14 && vertical == 6, "noise {noise}: {checked} curves checked, {vertical} vertical, of {}", curves.len());
        if noise == 0.0 {
            // The library labels the curves it returns when told where the scanner stood.
            let told = extract_cloud(&pts, &Params::default(), &RunOptions { outside: Some(scanner.clone()), ..Default::default() }).unwrap();
            assert!(told.curves.iter().all(|c| c.shape == scanner.shape(c)));
            assert!(told.curves.iter().any(|c| c.shape == Shape::Concave));
        }
    }
}
