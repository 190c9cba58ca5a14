//! A large outdoor scene for scale tests: streets with curbs and blocks of buildings with flat
//! and gabled roofs, in a projected CRS (ETRS89 / UTM 32N), streamed to disk block by block so
//! memory stays constant however many points are asked for.
//!
//! Layout: a G x G grid of square blocks of side [`BLOCK`] m. Each block has a road strip
//! (z = 0) along its south side, a curb up to the pavement level (z = [`CURB`]), and one
//! building standing on the pavement. Every block is generated from its own random stream, so
//! the output is deterministic by seed.

use super::surface::{AreaTable, Frame, Surface};
use super::truth_polylines;
use crate::curves::write_obj;
use crate::error::{Error, Result};
use crate::io::{PointWriter, WriteOptions};
use crate::rng::Rng;
use glam::{DVec2, DVec3};
use std::path::Path;

/// Block side in metres.
pub(crate) const BLOCK: f64 = 25.0;
/// Road width in metres.
pub(crate) const ROAD: f64 = 6.0;
/// Curb height in metres.
pub(crate) const CURB: f64 = 0.15;
/// World origin of the scene (easting, northing, height) in EPSG:25832.
pub(crate) const ORIGIN: DVec3 = DVec3::new(500_000.0, 5_400_000.0, 100.0);
/// EPSG code of the scene's CRS.
pub const EPSG: u16 = 25832;

/// Scene options.
#[derive(Clone, Debug)]
pub struct SceneOptions {
    /// Number of points.
    pub n: u64,
    /// Noise radius in metres (uniform in a ball).
    pub noise: f64,
    /// Random seed.
    pub seed: u64,
    /// Clutter: a tree crown and trunk (volumetric scatter, ASPRS class 5) by the road, a strip
    /// of rough grass (bumps of a few centimetres) along the back of each block, and recessed
    /// windows in the walls. The windows' edges are designed edges (truth); the trees and
    /// the grass have none.
    pub clutter: bool,
}

/// Recessed windows: width, height, depth, sill above each floor, and their spacing along a
/// wall and between floors (metres).
const WINDOW: (f64, f64, f64, f64, f64, f64) = (1.2, 1.4, 0.2, 1.0, 2.5, 3.0);
/// Depth of the grass strip along the back of a block (metres).
const GRASS: f64 = 1.8;

/// Bumps of the grass strip (local x along the block, y across the strip): a few centimetres,
/// tapering to flat at both edges so the grass meets the pavement and the next block's curb
/// without a step.
fn grass_height(p: DVec2) -> f64 {
    let taper = (std::f64::consts::PI * p.y / GRASS).sin().powi(2);
    0.02 * taper * ((7.3 * p.x).sin() * (5.1 * p.y).sin() + 0.6 * (13.7 * p.x + 2.1 * p.y).sin())
}

/// A wall from `a` to `b` (feet at height `zb`, top at `ze`) with recessed windows: the wall
/// with the openings cut out, each opening's four reveals and back, and the truth edges of
/// the openings (rim and back).
fn windowed_wall(a: DVec3, b: DVec3, zb: f64, ze: f64, s: &mut Vec<(Surface, u8)>, t: &mut Vec<Vec<DVec3>>) {
    let (ww, wh, depth, sill, along, floor) = WINDOW;
    let len = (b - a).length();
    let x = (b - a) / len;
    let inward = -x.cross(DVec3::Z);
    let frame = Frame { origin: DVec3::new(a.x, a.y, zb), x, y: DVec3::Z };
    let (columns, floors) = (((len - 1.0) / along).floor() as usize, ((ze - zb - 1.0) / floor).floor() as usize);
    let margin = (len - columns as f64 * along) / 2.0;
    let mut loops = vec![vec![DVec2::ZERO, DVec2::new(len, 0.0), DVec2::new(len, ze - zb), DVec2::new(0.0, ze - zb)]];
    for f in 0..floors {
        for c in 0..columns {
            let lo = DVec2::new(margin + c as f64 * along + (along - ww) / 2.0, f as f64 * floor + sill);
            let hi = lo + DVec2::new(ww, wh);
            let rim = [lo, DVec2::new(hi.x, lo.y), hi, DVec2::new(lo.x, hi.y)];
            loops.push(rim.to_vec());
            let front: Vec<DVec3> = rim.iter().map(|&q| frame.at(q)).collect();
            let back: Vec<DVec3> = front.iter().map(|&q| q + inward * depth).collect();
            for k in 0..4 {
                let l = (k + 1) % 4;
                for r in rect(front[k], front[l], back[l], back[k]) {
                    s.push((r, 6));
                }
            }
            for r in rect(back[0], back[1], back[2], back[3]) {
                s.push((r, 6));
            }
            t.push(front.iter().chain(&front[..1]).copied().collect());
            t.push(back.iter().chain(&back[..1]).copied().collect());
        }
    }
    s.push((Surface::Polygon { frame, loops }, 6));
}

struct Block {
    surfaces: Vec<(Surface, u8)>,
    truth: Vec<Vec<DVec3>>,
}

fn rect(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> [Surface; 2] {
    [Surface::Triangle([a, b, c]), Surface::Triangle([a, c, d])]
}

/// The surfaces (with ASPRS class) and edges of block (i, j), in scene-local coordinates.
fn block(i: usize, j: usize, seed: u64, g: usize, clutter: bool) -> Block {
    let mut rng = Rng::stream(seed, (j * g + i) as u64);
    let o = DVec3::new(i as f64 * BLOCK, j as f64 * BLOCK, 0.0);
    let p = |x: f64, y: f64, z: f64| o + DVec3::new(x, y, z);
    let mut s = street(o, j);
    let mut t: Vec<Vec<DVec3>> = vec![];
    // Building footprint and height.
    let (w, d) = (rng.range(8.0, 16.0), rng.range(7.0, BLOCK - ROAD - 5.0));
    let x0 = rng.range(2.0, BLOCK - 2.0 - w);
    let y0 = rng.range(ROAD + 2.0, BLOCK - 2.0 - d);
    let (x1, y1) = (x0 + w, y0 + d);
    let h = rng.range(4.0, 14.0);
    let gabled = rng.f64() < 0.5;
    let zb = CURB;
    let ze = zb + h;
    // Pavement with the footprint cut out (and the grass strip, with clutter).
    let back = if clutter { BLOCK - GRASS } else { BLOCK };
    let pavement = Surface::Polygon {
        frame: Frame { origin: p(0.0, 0.0, CURB), x: DVec3::X, y: DVec3::Y },
        loops: vec![
            vec![DVec2::new(0.0, ROAD), DVec2::new(BLOCK, ROAD), DVec2::new(BLOCK, back), DVec2::new(0.0, back)],
            vec![DVec2::new(x0, y0), DVec2::new(x1, y0), DVec2::new(x1, y1), DVec2::new(x0, y1)],
        ],
    };
    s.push((pavement, 2));
    let c = [p(x0, y0, 0.0), p(x1, y0, 0.0), p(x1, y1, 0.0), p(x0, y1, 0.0)];
    let up = |q: DVec3, z: f64| DVec3::new(q.x, q.y, z);
    // Walls, wall corners and wall feet.
    for k in 0..4 {
        let (a, b) = (c[k], c[(k + 1) % 4]);
        if clutter {
            windowed_wall(a, b, zb, ze, &mut s, &mut t);
        } else {
            for r in rect(up(a, zb), up(b, zb), up(b, ze), up(a, ze)) {
                s.push((r, 6));
            }
        }
        t.push(vec![up(a, zb), up(a, ze)]);
        t.push(vec![up(a, zb), up(b, zb)]);
    }
    if gabled {
        // Ridge along x, over the middle of the footprint; gable triangles on the x walls.
        let pitch = rng.range(25f64, 40.0).to_radians();
        let zr = ze + (d / 2.0) * pitch.tan();
        let ym = (y0 + y1) / 2.0;
        let (r0, r1) = (p(x0, ym, zr), p(x1, ym, zr));
        for r in rect(up(c[0], ze), up(c[1], ze), r1, r0) {
            s.push((r, 6));
        }
        for r in rect(up(c[3], ze), r0, r1, up(c[2], ze)) {
            s.push((r, 6));
        }
        s.push((Surface::Triangle([up(c[0], ze), r0, up(c[3], ze)]), 6));
        s.push((Surface::Triangle([up(c[1], ze), up(c[2], ze), r1]), 6));
        t.push(vec![r0, r1]);
        t.push(vec![up(c[0], ze), up(c[1], ze)]);
        t.push(vec![up(c[3], ze), up(c[2], ze)]);
        t.push(vec![up(c[0], ze), r0, up(c[3], ze)]);
        t.push(vec![up(c[1], ze), r1, up(c[2], ze)]);
    } else {
        for r in rect(up(c[0], ze), up(c[1], ze), up(c[2], ze), up(c[3], ze)) {
            s.push((r, 6));
        }
        for k in 0..4 {
            t.push(vec![up(c[k], ze), up(c[(k + 1) % 4], ze)]);
        }
    }
    if clutter {
        // (From a stream of its own, so that the rest of the block is the scene without clutter.)
        s.extend(clutter_of(o, Rng::stream(seed ^ crate::salts::SCENE_CLUTTER, (j * g + i) as u64)));
    }
    Block { surfaces: s, truth: t }
}

/// The road of a block at `o` (scene-local) in row `j`, and its curbs: the face up to the
/// pavement, and, past the first row, the far curb where the previous row's pavement drops to
/// this block's road at y = 0. (With ASPRS class 2, ground.)
fn street(o: DVec3, j: usize) -> Vec<(Surface, u8)> {
    let p = |x: f64, y: f64, z: f64| o + DVec3::new(x, y, z);
    let mut s = vec![];
    for r in rect(p(0.0, 0.0, 0.0), p(BLOCK, 0.0, 0.0), p(BLOCK, ROAD, 0.0), p(0.0, ROAD, 0.0)) {
        s.push((r, 2));
    }
    for r in rect(p(0.0, ROAD, 0.0), p(BLOCK, ROAD, 0.0), p(BLOCK, ROAD, CURB), p(0.0, ROAD, CURB)) {
        s.push((r, 2));
    }
    if j > 0 {
        for r in rect(p(0.0, 0.0, 0.0), p(BLOCK, 0.0, 0.0), p(BLOCK, 0.0, CURB), p(0.0, 0.0, CURB)) {
            s.push((r, 2));
        }
    }
    s
}

/// The clutter of a block at `o`, drawn from `rng`: a grass strip along its back, and a tree
/// (trunk and crown, scatter of class 5) by the road.
fn clutter_of(o: DVec3, mut rng: Rng) -> Vec<(Surface, u8)> {
    let p = |x: f64, y: f64, z: f64| o + DVec3::new(x, y, z);
    let mut s = vec![];
    let grass = Frame { origin: p(0.0, BLOCK - GRASS, CURB), x: DVec3::X, y: DVec3::Y };
    s.push((Surface::HeightField { frame: grass, min: DVec2::ZERO, max: DVec2::new(BLOCK, GRASS), f: grass_height, max_slope: 0.6 }, 2));
    let (tx, crown) = (rng.range(3.0, BLOCK - 3.0), rng.range(2.0, 3.0));
    let trunk = rng.range(2.0, 3.5);
    s.push((Surface::Scatter { centre: p(tx, ROAD + 1.0, CURB + trunk / 2.0), radii: DVec3::new(0.3, 0.3, trunk / 2.0) }, 5));
    s.push((Surface::Scatter { centre: p(tx, ROAD + 1.0, CURB + trunk + 0.8 * crown), radii: DVec3::new(crown, crown, 0.8 * crown) }, 5));
    s
}

fn block_area(b: &Block) -> f64 {
    b.surfaces.iter().map(|(s, _)| s.area()).sum()
}

/// Grid side so that blocks hold about `per_block` points each at the target spacing.
fn grid_side(n: u64) -> usize {
    // About 1000 m^2 of surface per block at 5 cm spacing (400 points/m^2).
    let per_block = 400.0 * 1000.0;
    ((n as f64 / per_block).sqrt().ceil() as usize).max(1)
}

/// Streams the scene to `out` (LAS) and its truth to `OUT.truth.obj`. Returns the point count.
pub fn write_scene(opts: &SceneOptions, out: &Path) -> Result<u64> {
    if opts.n == 0 {
        return Err(Error::Usage("-n must be at least 1".into()));
    }
    let g = grid_side(opts.n);
    // First pass: areas only, to give every block its exact share of the n points.
    let areas: Vec<f64> = (0..g * g).map(|k| block_area(&block(k % g, k / g, opts.seed, g, opts.clutter))).collect();
    let total: f64 = areas.iter().sum();
    let wopts = WriteOptions { scale: 0.001, offset: ORIGIN, epsg: Some(EPSG) };
    let mut w = PointWriter::create(out, &wopts)?;
    let mut truth: Vec<Vec<DVec3>> = vec![];
    let (mut cum, mut written) = (0.0, 0u64);
    let mut xyz = Vec::new();
    let mut class = Vec::new();
    for (k, area) in areas.iter().enumerate() {
        let (i, j) = (k % g, k / g);
        cum += area;
        let target = ((cum / total) * opts.n as f64).round() as u64;
        let count = (target - written) as usize;
        let b = block(i, j, opts.seed, g, opts.clutter);
        let surfaces: Vec<Surface> = b.surfaces.iter().map(|(s, _)| s.clone()).collect();
        let table = AreaTable::new(&surfaces);
        let mut rng = Rng::stream(opts.seed ^ 0xB10C, k as u64);
        // Write in slices of at most 1 M points so memory stays bounded.
        let mut left = count;
        while left > 0 {
            let m = left.min(1 << 20);
            xyz.clear();
            class.clear();
            for _ in 0..m {
                let si = table.pick(&mut rng);
                xyz.push(surfaces[si].sample(&mut rng) + ORIGIN);
                class.push(b.surfaces[si].1);
            }
            if opts.noise > 0.0 {
                let mut r = Rng::stream(opts.seed ^ 0x7015E, k as u64 * 4096 + (left >> 20) as u64);
                for p in xyz.iter_mut() {
                    *p += r.in_ball(opts.noise);
                }
            }
            w.write(&xyz, &class)?;
            left -= m;
        }
        written = target;
        truth.extend(b.truth.into_iter().map(|l| l.into_iter().map(|q| q + ORIGIN).collect()));
    }
    // Curbs run unbroken along each row of blocks.
    let len = g as f64 * BLOCK;
    for j in 0..g {
        let y = j as f64 * BLOCK;
        for (yy, z) in [(y + ROAD, 0.0), (y + ROAD, CURB)] {
            truth.push(vec![ORIGIN + DVec3::new(0.0, yy, z), ORIGIN + DVec3::new(len, yy, z)]);
        }
        if j > 0 {
            for z in [0.0, CURB] {
                truth.push(vec![ORIGIN + DVec3::new(0.0, y, z), ORIGIN + DVec3::new(len, y, z)]);
            }
        }
    }
    w.finish()?;
    write_obj(&super::truth_path(out), &truth_polylines(&truth), &crate::crs::Crs { epsg: Some(EPSG.into()), ..Default::default() })?;
    Ok(written)
}
