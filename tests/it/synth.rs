//! Ground-truth generation: shapes, mesh sampling, scene, determinism and the noise model.

use crate::common;

use crease::curves::read_obj;
use crease::io::{read_header, Filter, PointReader};
use crease::synth::{self, shape, Sampling, SynthOptions};
use glam::DVec3;
use std::collections::HashSet;

fn opts(n: usize, noise: f64, seed: u64) -> SynthOptions {
    SynthOptions { n, noise, noise_spacing: 0.0, outliers: 0.0, sampling: Sampling::Uniform, seed }
}

#[test]
fn shape_truth_counts() {
    for (name, curves) in
        [("cube", 12), ("octahedron", 12), ("holecube", 14), ("cylinder", 2), ("step", 18), ("chamfer", 15), ("wedge", 1), ("plate", 38), ("blade", 6)]
    {
        let s = shape(name, 90.0).unwrap();
        assert_eq!(s.truth.len(), curves, "{name}");
    }
    assert!(shape("nonsense", 90.0).is_none());
}

/// Every point of a noisy cube lies within noise * dB of the cube's surface, and the noise
/// is really there (some points are more than half that far).
#[test]
fn noise_model_bounds_displacement() {
    let s = shape("cube", 90.0).unwrap();
    let clean = synth::sample(&s, &opts(20_000, 0.0, 3));
    let dist = |p: DVec3| {
        // Distance to the surface of the unit cube (points may be inside or outside).
        let q = p.clamp(DVec3::ZERO, DVec3::ONE);
        let outside = p.distance(q);
        let inside = [p.x, 1.0 - p.x, p.y, 1.0 - p.y, p.z, 1.0 - p.z].into_iter().fold(f64::MAX, f64::min);
        if outside > 0.0 {
            outside
        } else {
            inside
        }
    };
    assert!(clean.iter().all(|&p| dist(p) < 1e-12));
    let noisy = synth::sample(&s, &opts(20_000, 0.01, 3));
    let r = 0.01 * 3f64.sqrt();
    let d: Vec<f64> = noisy.iter().map(|&p| dist(p)).collect();
    assert!(d.iter().all(|&x| x <= r * 1.02), "max {}", d.iter().cloned().fold(0.0, f64::max));
    assert!(d.iter().filter(|&&x| x > r / 2.0).count() > 1000);
    // Noise in point spacings: the same cube, radius 4 kappa of the clean cloud.
    let kappa = crease::spacing::spacing(&clean, 2000);
    let noisy = synth::sample(&s, &SynthOptions { noise_spacing: 4.0, ..opts(20_000, 0.0, 3) });
    let d: Vec<f64> = noisy.iter().map(|&p| dist(p)).collect();
    let r = 4.0 * kappa;
    assert!(d.iter().all(|&x| x <= r * 1.0001), "max {} of {r}", d.iter().cloned().fold(0.0, f64::max));
    assert!(d.iter().filter(|&&x| x > r / 2.0).count() > 1000);
}

/// Uniform sampling by area: each cube face gets a sixth of the points.
#[test]
fn uniform_by_area() {
    let pts = synth::sample(&shape("cube", 90.0).unwrap(), &opts(60_000, 0.0, 5));
    let on_face = |f: &dyn Fn(DVec3) -> bool| pts.iter().filter(|&&p| f(p)).count();
    for k in 0..3 {
        for v in [0.0, 1.0] {
            let c = on_face(&|p: DVec3| (p[k] - v).abs() < 1e-12);
            assert!((c as f64 - 10_000.0).abs() < 400.0, "face {k}={v}: {c}");
        }
    }
}

#[test]
fn outliers_and_scanlines() {
    let s = shape("cube", 90.0).unwrap();
    let o = SynthOptions { outliers: 0.05, ..opts(20_000, 0.0, 9) };
    let pts = synth::sample(&s, &o);
    let off = pts.iter().filter(|p| {
        let q = p.clamp(DVec3::ZERO, DVec3::ONE);
        p.distance(q) > 1e-9 || [p.x, 1.0 - p.x, p.y, 1.0 - p.y, p.z, 1.0 - p.z].iter().all(|&x| x > 1e-9)
    });
    let n = off.count();
    assert!((n as f64 - 1000.0).abs() < 150.0, "outliers {n}");
    let o = SynthOptions { sampling: Sampling::ScanLines { anisotropy: 4.0 }, ..opts(20_000, 0.0, 9) };
    let pts = synth::sample(&s, &o);
    assert_eq!(pts.len(), 20_000);
    // All points sit in thin slabs across the scan direction.
    let u = DVec3::new(0.31, 0.17, 0.935).normalize();
    let sep = (6.0 * 4.0 / 20_000f64).sqrt();
    assert!(pts.iter().all(|p| (p.dot(u) / sep).rem_euclid(1.0) < 1.0 / 32.0 + 1e-9));
}

#[test]
fn same_seed_same_bytes() {
    let d = tempfile::tempdir().unwrap();
    let s = shape("fandisk", 90.0).unwrap();
    for (k, seed) in [(0, 7), (1, 7), (2, 8)] {
        synth::write_sampled(&s, &opts(5_000, 0.01, seed), &d.path().join(format!("{k}.las"))).unwrap();
    }
    let r = |k: usize| std::fs::read(d.path().join(format!("{k}.las"))).unwrap();
    assert_eq!(r(0), r(1));
    assert_ne!(r(0), r(2));
}

/// Independently of the library: parse the OFF, find edges whose face normals differ by more
/// than 30 degrees, and compare with the truth polylines' segments.
#[test]
#[ignore = "needs ../shared"]
fn mesh_truth_is_exactly_the_sharp_edges() {
    let off = common::shared_data("meshes/anchor.off");
    let text = std::fs::read_to_string(&off).unwrap();
    let nums: Vec<f64> = text.split_whitespace().skip(1).map(|t| t.parse().unwrap()).collect();
    let (nv, nf) = (nums[0] as usize, nums[1] as usize);
    let v: Vec<DVec3> = (0..nv).map(|i| DVec3::new(nums[3 + 3 * i], nums[4 + 3 * i], nums[5 + 3 * i])).collect();
    let mut at = 3 + 3 * nv;
    let mut faces = vec![];
    for _ in 0..nf {
        let k = nums[at] as usize;
        assert_eq!(k, 3, "anchor.off is a triangle mesh");
        faces.push([nums[at + 1] as usize, nums[at + 2] as usize, nums[at + 3] as usize]);
        at += 1 + k;
    }
    let mut edge_faces: std::collections::HashMap<(usize, usize), Vec<DVec3>> = Default::default();
    for f in &faces {
        let n = (v[f[1]] - v[f[0]]).cross(v[f[2]] - v[f[0]]).normalize();
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            edge_faces.entry((a.min(b), a.max(b))).or_default().push(n);
        }
    }
    let cos30 = 30f64.to_radians().cos();
    let sharp: HashSet<(usize, usize)> = edge_faces.iter().filter(|(_, n)| n.len() == 2 && n[0].dot(n[1]) < cos30).map(|(e, _)| *e).collect();
    assert!(sharp.len() > 50, "anchor has many sharp edges ({})", sharp.len());

    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("anchor.las");
    let mesh = synth::read_mesh(&off).unwrap();
    synth::write_sampled(&mesh.to_shape(30.0), &opts(10_000, 0.0, 1), &out).unwrap();
    let truth = read_obj(&synth::truth_path(&out)).unwrap();
    // Map truth vertices back to mesh vertex ids by exact position.
    let id = |p: DVec3| v.iter().position(|&q| q == p).expect("truth vertex is a mesh vertex");
    let mut segs = HashSet::new();
    let mut count = 0;
    for c in &truth {
        for (a, b) in c.segments() {
            let (i, j) = (id(a), id(b));
            segs.insert((i.min(j), i.max(j)));
            count += 1;
        }
    }
    assert_eq!(count, sharp.len(), "each sharp edge appears once");
    assert_eq!(segs, sharp);
}

#[test]
fn scene_is_exact_in_count_and_carries_crs() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("scene.las");
    let n = synth::write_scene(&synth::SceneOptions { n: 300_000, noise: 0.005, seed: 4, clutter: false }, &out).unwrap();
    assert_eq!(n, 300_000);
    let h = read_header(&out).unwrap();
    assert_eq!(h.count, 300_000);
    assert_eq!(h.crs.epsg, Some(u32::from(synth::EPSG)));
    let pts = PointReader::open(&out, &Filter::default()).unwrap().read_all().unwrap();
    assert!(pts.class.contains(&6) && pts.class.contains(&2));
    let truth = read_obj(&synth::truth_path(&out)).unwrap();
    // One block: 12 or 13 building edges (flat or gabled roof... counted per polyline) + 2 curbs.
    assert!(truth.len() >= 14, "{}", truth.len());
    // Every truth vertex lies inside the cloud's bounds (up to the noise).
    for c in &truth {
        for v in &c.vertices {
            for k in 0..3 {
                assert!(v.p[k] >= h.bounds.min[k] - 0.01 && v.p[k] <= h.bounds.max[k] + 0.01);
            }
        }
    }
}
