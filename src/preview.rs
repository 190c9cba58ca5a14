//! `preview.png`: a quick look at a run. The cloud from the top and from an oblique view, side
//! by side, points subsampled and shaded by the slope of their depth, and the curves drawn
//! over them in the colour of their typed pieces' kind (see [`kind_colour`]), so that a user
//! sees at a glance what a CAD program will get: lines, arcs, circles or splines.

use crate::curves::typed::{self, Kind};
use crate::curves::Curves;
use crate::error::{Error, Result};
use glam::{DMat3, DVec3};
use std::path::Path;

/// Side of each view, in pixels.
pub(crate) const SIDE: usize = 800;
/// About this many points of a cloud are drawn.
pub(crate) const PREVIEW_POINTS: f64 = 1_000_000.0;

/// An RGB image.
pub(crate) struct Image {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Pixels, row by row from the top, three bytes each.
    pub rgb: Vec<u8>,
}

impl Image {
    fn new(width: usize, height: usize) -> Image {
        Image { width, height, rgb: vec![255; width * height * 3] }
    }

    fn set(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            let o = 3 * (y as usize * self.width + x as usize);
            self.rgb[o..o + 3].copy_from_slice(&c);
        }
    }
}

/// The two views of `points` and `curves` (world coordinates), side by side, the curves typed
/// within `tol`.
pub(crate) fn render(points: &[DVec3], curves: &(impl Curves + ?Sized), tol: f64) -> Result<Image> {
    let mut image = Image::new(2 * SIDE, SIDE);
    // Top: looking down. Oblique: turned 30 degrees about the vertical, tilted to look down at
    // 35 degrees.
    let oblique = DMat3::from_rotation_x(-55f64.to_radians()) * DMat3::from_rotation_z(-30f64.to_radians());
    for (k, view) in [DMat3::IDENTITY, oblique].into_iter().enumerate() {
        draw_view(&mut image, k * SIDE, view, points, curves, tol)?;
    }
    Ok(image)
}

/// Writes the preview of `points` and `curves` (typed within `tol`) to `path` as PNG.
pub(crate) fn write_png(path: &Path, points: &[DVec3], curves: &(impl Curves + ?Sized), tol: f64) -> Result<()> {
    let image = render(points, curves, tol)?;
    let f = std::fs::File::create(path).map_err(|e| Error::output(path, e))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(f), image.width as u32, image.height as u32);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    // (The default deflate took 0.1 s of a 1.6 s run; a quick look need not be small.)
    enc.set_compression(png::Compression::Fast);
    let io = |e: png::EncodingError| Error::output(path, std::io::Error::other(e));
    let mut w = enc.write_header().map_err(io)?;
    w.write_image_data(&image.rgb).map_err(io)?;
    w.finish().map_err(io)
}

/// Draws one view into the square of `image` starting at column `x0`: `view` turns world
/// directions into view directions (x right, y up, z towards the viewer).
fn draw_view(image: &mut Image, x0: usize, view: DMat3, points: &[DVec3], curves: &(impl Curves + ?Sized), tol: f64) -> Result<()> {
    let centre = points.iter().fold(DVec3::ZERO, |s, &p| s + p) / points.len().max(1) as f64;
    let to_view = |p: DVec3| view * (p - centre);
    let (mut lo, mut hi) = (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN));
    for &p in points {
        let v = to_view(p);
        (lo, hi) = (lo.min(v), hi.max(v));
    }
    if points.is_empty() || !(hi.x >= lo.x && hi.y >= lo.y) {
        return Ok(());
    }
    let margin = 0.04 * SIDE as f64;
    let span = (hi.x - lo.x).max(hi.y - lo.y).max(f64::MIN_POSITIVE);
    let per_pixel = span / (SIDE as f64 - 2.0 * margin);
    let pixel = |v: DVec3| ((v.x - lo.x) / per_pixel + margin, (hi.y - v.y) / per_pixel + margin);
    // Depth buffer: the nearest point in each pixel; sparse clouds are splatted wider.
    let mut depth = vec![f64::NEG_INFINITY; SIDE * SIDE];
    // (Wide enough that the splats of a surface seen square-on cover about twice its pixels.)
    let splat = ((SIDE * SIDE) as f64 * 2.0 / points.len() as f64).sqrt().clamp(1.0, 6.0) as i64;
    for &p in points {
        let v = to_view(p);
        let (px, py) = pixel(v);
        for dy in 0..splat {
            for dx in 0..splat {
                let (x, y) = (px as i64 + dx, py as i64 + dy);
                if x >= 0 && y >= 0 && (x as usize) < SIDE && (y as usize) < SIDE {
                    let d = &mut depth[y as usize * SIDE + x as usize];
                    *d = d.max(v.z);
                }
            }
        }
    }
    // Shading from the depth's slope (a surface normal in view space), lit from the upper left.
    let light = DVec3::new(-0.4, 0.5, 0.77).normalize();
    for y in 0..SIDE {
        for x in 0..SIDE {
            let d = depth[y * SIDE + x];
            if d == f64::NEG_INFINITY {
                continue;
            }
            let at = |x: usize, y: usize| Some(depth[y * SIDE + x]).filter(|v| v.is_finite()).unwrap_or(d);
            // (Over four pixels: single points' depths are noisy.)
            let gx = (at((x + 2).min(SIDE - 1), y) - at(x.saturating_sub(2), y)) / (4.0 * per_pixel);
            let gy = (at(x, y.saturating_sub(2)) - at(x, (y + 2).min(SIDE - 1))) / (4.0 * per_pixel);
            let n = DVec3::new(-gx, -gy, 1.0).normalize();
            let g = (40.0 + 200.0 * n.dot(light).max(0.0)) as u8;
            image.set((x0 + x) as i64, y as i64, [g, g, g]);
        }
    }
    curves.each(&mut |c| {
        let n = c.vertices.len();
        let mut colours = vec![kind_colour(Kind::Polyline); c.segment_count()];
        for p in typed::pieces(c, tol) {
            for k in 0..p.segments {
                colours[(p.first + k) % n] = kind_colour(p.kind);
            }
        }
        for (s, &colour) in colours.iter().enumerate() {
            let (a, b) = (pixel(to_view(c.vertices[s].p)), pixel(to_view(c.vertices[(s + 1) % n].p)));
            let steps = (b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil().max(1.0) as usize;
            for i in 0..=steps {
                let t = i as f64 / steps as f64;
                let (x, y) = (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (x, y) = (x as i64 + dx, y as i64 + dy);
                    if x >= 0 && (x as usize) < SIDE {
                        image.set(x + x0 as i64, y, colour);
                    }
                }
            }
        }
        Ok(())
    })
}

/// The colour of a piece's kind: lines blue, arcs green, circles orange, splines magenta, and
/// polyline runs (where no spline holds) red.
pub(crate) fn kind_colour(kind: Kind) -> [u8; 3] {
    match kind {
        Kind::Line => [30, 90, 220],
        Kind::Arc => [20, 160, 40],
        Kind::Circle => [235, 140, 0],
        Kind::Spline => [200, 0, 200],
        Kind::Polyline => [220, 0, 0],
    }
}

/// A saturated colour for curve `id`: hues a golden angle apart, so neighbours differ.
pub(crate) fn curve_colour(id: u32) -> [u8; 3] {
    let h = (id as f64 * 0.618_033_988_75).fract() * 6.0;
    let x = 1.0 - (h % 2.0 - 1.0).abs();
    let (r, g, b) = match h as u32 {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        3 => (0.0, x, 1.0),
        4 => (x, 0.0, 1.0),
        _ => (1.0, 0.0, x),
    };
    // (Darkened a little so that yellows show on light grey.)
    [(r * 220.0) as u8, (g * 220.0) as u8, (b * 220.0) as u8]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat square seen from the top is grey where its points are and white around it, and
    /// a straight curve along its edge is drawn in the colour of lines.
    #[test]
    fn points_are_shaded_and_curves_coloured() {
        let points: Vec<DVec3> = (0..40_000).map(|i| DVec3::new((i % 200) as f64 * 0.005, (i / 200) as f64 * 0.005, 0.0)).collect();
        let curve = crate::curves::Polyline::from_points(3, [DVec3::ZERO, DVec3::new(0.995, 0.0, 0.0)]);
        let image = render(&points, &[curve][..], 1e-3).unwrap();
        let at = |x: usize, y: usize| &image.rgb[3 * (y * image.width + x)..3 * (y * image.width + x) + 3];
        // The square fills the top view but its margin; its middle is lit grey, not white.
        let middle = at(SIDE / 2, SIDE / 2);
        assert!(middle[0] == middle[1] && middle[1] == middle[2] && middle[0] < 255, "{middle:?}");
        assert_eq!(at(5, 5), &[255, 255, 255]);
        // The curve runs along the bottom edge of the top view (y = 0 is the lowest row drawn).
        let row = (SIDE as f64 * 0.96) as usize;
        let coloured = (0..SIDE).filter(|&x| (row - 2..=row + 1).any(|y| at(x, y) == kind_colour(Kind::Line))).count();
        assert!(coloured > SIDE / 2, "{coloured} pixels of the curve");
    }

    #[test]
    fn render_makes_two_views_side_by_side() -> crate::Result<()> {
        use crate::curves::Polyline;
        use glam::DVec3;

        let points: Vec<DVec3> = (0..10_000).map(|i| DVec3::new((i % 100) as f64, (i / 100) as f64, 0.0)).collect();
        let curves = [Polyline::from_points(0, [DVec3::ZERO, DVec3::new(99.0, 0.0, 0.0)])];
        let image = crate::preview::render(&points, &curves[..], 1e-3)?;
        assert_eq!((image.width, image.height), (2 * crate::preview::SIDE, crate::preview::SIDE));
        Ok(())
    }
}
