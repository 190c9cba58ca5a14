//! The method's parameters: what the user gives ([`Params`]), and every default resolved from
//! the measured spacing and noise ([`Resolved`]).

use super::statistics::{median, quantile, PointStats};
use crate::keys::settle;
use serde::{Deserialize, Serialize};

/// User parameters; every length is in model units and defaults to a multiple of the point
/// spacing kappa (the median nearest-neighbour distance).
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Params {
    /// Point spacing kappa (default: estimated).
    pub kappa: Option<f64>,
    /// Neighbourhood radius of the candidate fit (default 6 kappa).
    pub fit_radius: Option<f64>,
    /// Neighbourhood radius of the robust projection (default 9 kappa).
    pub rmls_radius: Option<f64>,
    /// Residual threshold tau (default: mean residual over all points).
    pub tau: Option<f64>,
    /// Polyline step s_max (default 4.5 kappa).
    pub step: Option<f64>,
    /// Largest turn while growing, degrees (default 30).
    pub max_turn_deg: Option<f64>,
    /// Creases whose surface normals differ by less than this many degrees are ignored
    /// (default 28).
    pub min_angle_deg: Option<f64>,
    /// Seed of the robust fits' random streams (default 1).
    pub seed: Option<u64>,
    /// Evaluate stages 1 and 2 at about this many points of each fit's disk, not at every
    /// point (default: every point; see [`Resolved::evaluate`]).
    pub evaluate_per_fit: Option<f64>,
    /// How stage 2 searches for the surfaces around a candidate (default [`Model::Balls`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<Model>,
}

/// How stage 2 searches for the surfaces that meet at a candidate (see
/// `super::project::project`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Model {
    /// One forward search per candidate, over its own ball (Daniels 2007).
    #[default]
    Balls,
    /// One forward search per cell of candidates a quarter of the ball wide, over the ball
    /// around the cell's centre, shared by its candidates: faster under noise, where the band
    /// of candidates along a feature widens, at a little recall and precision.
    Cells,
    /// Surfaces first: within each candidate's ball, the points off the band of candidates
    /// fall into patches (their connected pieces, which the band separates at every feature),
    /// and each patch is searched for surfaces on its own, so no fit takes points of a surface
    /// across a feature, however close.
    Patches,
}

impl Model {
    /// The model named `name` (`balls`, `cells` or `patches`).
    pub fn parse(name: &str) -> Option<Model> {
        match name {
            "balls" => Some(Model::Balls),
            "cells" => Some(Model::Cells),
            "patches" => Some(Model::Patches),
            _ => None,
        }
    }
}

/// Parameters with every default resolved to a value.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Resolved {
    /// Point spacing (median nearest-neighbour distance).
    pub kappa: f64,
    /// Estimated noise: standard deviation of points about their local plane.
    pub noise: f64,
    /// The noise of the smoothest quarter of the sampled surfaces (the first quartile of the
    /// sampled noise): the scanner's own, which rough ground and vegetation inflate less than
    /// the median. What a surface must fit to within (see
    /// `SURFACE_NOISE`).
    #[serde(default)]
    pub surface_noise: f64,
    /// Length unit of the defaults: max(kappa, `NOISE_SCALE` noise), so neighbourhoods outgrow
    /// the noise, and under noise at least wide enough for a fit of `MIN_NOISY_FIT` points
    /// (up to `NOISY_FIT_NOISE` deviations).
    pub scale: f64,
    /// Share of points used by the fits (1: all; less when noise makes neighbourhoods large,
    /// each then averaged over the points around it: see [`Resolved::average`]).
    pub keep: f64,
    /// Share of the points used by the fits at which stages 1 and 2 are evaluated (1: all;
    /// less only when [`Params::evaluate_per_fit`] asks for fewer than a fit's disk holds).
    /// The fits still see every point kept; the candidates and edge points are fewer, as
    /// dense on the scale of the neighbourhoods as `evaluate_per_fit` says. Under noise, where
    /// a fit's disk holds up to `TARGET_NEIGHBOURS` points, this is several times faster, at
    /// a cost in recall where features are weak or thin.
    #[serde(default = "every_point")]
    pub evaluate: f64,
    /// Radius of the ball over which each point kept of a thinned cloud is averaged (0: the
    /// points as they are): it is moved to the mean of the points within it, kept or not (a
    /// share of them, see [`Resolved::average_share`]), so that the points dropped still narrow
    /// the noise (see `AVERAGE_NOISE`).
    #[serde(default)]
    pub average: f64,
    /// Share of the points that the averaging takes (1: all; see `AVERAGE_POINTS`), drawn
    /// from the position key.
    #[serde(default = "every_point")]
    pub average_share: f64,
    /// Candidate fit radius.
    pub fit_radius: f64,
    /// Robust projection radius.
    pub rmls_radius: f64,
    /// Smallest inlier threshold of the robust fits.
    pub min_threshold: f64,
    /// Polyline step.
    pub step: f64,
    /// Largest turn while growing, degrees.
    pub max_turn_deg: f64,
    /// Gentlest crease kept, degrees between the surface normals.
    pub min_angle_deg: f64,
    /// Corner grouping radius.
    pub corner_radius: f64,
    /// Completion search reach, in steps.
    pub reach_steps: f64,
    /// Completion cone half-aperture, degrees.
    pub aperture_deg: f64,
    /// Smoothing linearity target.
    pub linearity: f64,
    /// Random seed.
    pub seed: u64,
    /// How stage 2 searches for surfaces.
    #[serde(default)]
    pub model: Model,
    /// Radius within which near duplicates are collapsed as the tiles are loaded (0: exact
    /// copies only; see `statistics::near_duplicate_radius`). Written only where the
    /// cloud has them, so that a clean cloud's files read as before.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub near: f64,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// Default largest turn while growing, degrees.
pub(crate) const DEFAULT_MAX_TURN_DEG: f64 = 30.0;
/// Default gentlest crease kept, degrees between the surface normals.
pub(crate) const DEFAULT_MIN_ANGLE_DEG: f64 = 28.0;
/// Default seed of the robust fits' random streams.
pub(crate) const DEFAULT_SEED: u64 = 1;
/// Neighbours a fit should see; denser clouds are thinned to about this many.
pub(crate) const TARGET_NEIGHBOURS: f64 = 150.0;
/// Fit radius, in length units (see [`Resolved::scale`]).
pub(crate) const FIT_SCALES: f64 = 6.0;
/// Fewest points a fit holds where the noise sizes the neighbourhoods (see [`NOISE_SCALE`]).
/// At 2 point spacings of noise, 1.25 deviations make fits of about 35 points, and the quality
/// table's 2-spacing row lost recall (chamfer 1.0 -> 0.97, blade 1.0 -> 0.94, fandisk 0.99 ->
/// 0.98); 1.5 deviations of the noise as measured before made about 50; 150 found every
/// feature but doubled fandisk's mean distance (0.00033 -> 0.00067 dB) and took 1.5 times as
/// long.
pub(crate) const MIN_NOISY_FIT: f64 = 50.0;
/// The length unit widens for [`MIN_NOISY_FIT`] up to this many noise deviations, so that it
/// grows with the noise from the spacing on. (Widened only where 1.25 deviations exceed the
/// spacing, a shared real scan whose noise is 0.76 spacings, `plane.laz`, fell back to the
/// spacing, fits of about 28 points, and 61 curves on its plane; 4 with this, 6 before.)
pub(crate) const NOISY_FIT_NOISE: f64 = 2.0;
/// The default length unit is at least this many noise deviations, and under noise at least
/// wide enough for a fit of [`MIN_NOISY_FIT`] points. (1.5 was chosen when the
/// noise was measured within 16 spacings, which measured 0.77-0.9 of the deviation of the
/// quality clouds' dB noise at 500 k points; measured within 5 deviations (see
/// [`super::statistics::NOISE_BALL`]) it comes out 0.9-0.95 of it, and 1.25 sizes the
/// neighbourhoods about as before at 0.02 dB, a little narrower at 0.01 and 0.005.)
pub(crate) const NOISE_SCALE: f64 = 1.25;
/// Radius, in noise deviations, of the ball over which each point kept of a thinned cloud is
/// averaged (see [`Resolved::average`]). Thinning to [`TARGET_NEIGHBOURS`] a fit drops most of
/// a noisy cloud (96 % of fandisk at 0.02 dB); averaging lets the points dropped narrow the
/// noise of those kept instead. A ball narrower than the noise's spread across the surface
/// (a uniform ball of radius R deviates by R / sqrt(5)) leans towards its own point's side, so
/// it narrows the noise less than its count of points would; a wider one rounds a crease by
/// about its radius. Over the quality table (seed 1, the dB rows, against no averaging, with
/// every point of the ball): radius 2 raised mean recall at 0.005 / 0.01 /
/// 0.02 dB 0.964 / 0.818 / 0.671 -> 0.971 / 0.880 / 0.725 and precision 0.984 / 0.864 / 0.750
/// -> 0.984 / 0.892 / 0.796, and lowered the mean distance on almost every cloud (cube at
/// 0.01 0.00099 -> 0.00063 dB); radius 3 raised recall more (0.971 / 0.903 / 0.747) but moved
/// the edge points off the truth where features are sharp and close (anchor at 0.01 mean
/// 0.0025 -> 0.0032 dB, cylinder at 0.005 0.00054 -> 0.00091).
pub(crate) const AVERAGE_NOISE: f64 = 2.0;
/// Points about which a kept point is averaged (see [`AVERAGE_NOISE`]); where the ball holds
/// more, a share of them is taken. The ball leans towards its own point's side more than its
/// count narrows the noise: on a plane under uniform noise its mean deviates by about 0.6 of
/// the noise with 78 points, of which the count's own part, 1 / sqrt(78), is 0.11; with 48
/// points it is 0.14, the whole 0.62. A cloud thinned to 3 % holds about 270 points a ball,
/// and averaging them all took longer than the fits.
pub(crate) const AVERAGE_POINTS: f64 = 48.0;

impl Resolved {
    /// True if every length is finite and positive (the noise lengths not negative), every
    /// share in (0, 1] and every angle within its range: what the statistics pass gives. A
    /// manifest edited by hand (a step of -1) gave 0 curves and exit 0.
    pub(crate) fn is_sane(&self) -> bool {
        let positive = [self.kappa, self.scale, self.fit_radius, self.rmls_radius, self.min_threshold, self.step, self.corner_radius, self.reach_steps];
        let not_negative = [self.noise, self.surface_noise, self.average];
        let shares = [self.keep, self.evaluate, self.average_share, self.linearity];
        let angles = [self.max_turn_deg, self.min_angle_deg, self.aperture_deg];
        positive.iter().all(|&x| x.is_finite() && x > 0.0)
            && not_negative.iter().all(|&x| x.is_finite() && x >= 0.0)
            && shares.iter().all(|&x| x > 0.0 && x <= 1.0)
            && angles.iter().all(|&x| x.is_finite() && (0.0..=180.0).contains(&x))
    }

    /// The halo a tile needs around its core for stages 1-2: the widest neighbourhood they
    /// read, with a margin. Sparse neighbourhoods are widened no farther, so that every
    /// point's neighbourhood is the same in any tiling.
    pub fn halo(&self) -> f64 {
        1.25 * self.fit_radius.max(self.rmls_radius)
    }

    /// Side of the grid cells a tile's cloud is stored by for stages 1-2 (see
    /// [`Cloud::gridded`](super::neighbourhood::Cloud::gridded)): the same for both, so that the two passes load a tile in the same
    /// order. 1.5 fit radii, the block size that made the fewest instructions (see
    /// `BLOCK_CELL` in `cloud.rs`) for the residual pass, whose many cheap fits feel it most.
    /// (10 M scene, two runs each: 52.9-54.1 s of CPU; 52.9-56.5 s with 1.5 times the mean of
    /// the radii, 55.1-56.4 s with 1.5 projection radii.)
    pub(crate) fn cell_side(&self) -> f64 {
        1.5 * self.fit_radius
    }

    /// True if the neighbourhoods are sized by the noise rather than by the spacing (see
    /// [`NOISE_SCALE`]): the candidates then also take the crease test (see
    /// [`CREASE_RATIO`](super::candidates::CREASE_RATIO)), and edge points the consensus filter (see [`consensus`](super::consensus)).
    pub(crate) fn noise_limited(&self) -> bool {
        self.scale > self.kappa
    }
}

impl Params {
    /// Checks every value given, with the message the command line shows for it: lengths
    /// positive and finite, tau finite and 0 or more, the largest turn above 0 and at most 180
    /// degrees, the gentlest crease from 0 to below 180 degrees. Every entry point calls it.
    ///
    /// ```
    /// use crease::extract::Params;
    /// assert!(Params::default().validate().is_ok());
    /// let bad = Params { kappa: Some(-1.0), ..Params::default() };
    /// assert_eq!(bad.validate().unwrap_err().to_string(), "--kappa must be a positive number");
    /// ```
    pub fn validate(&self) -> crate::Result<()> {
        let refuse = |m: &str| Err(crate::Error::Usage(m.to_string()));
        for (name, v) in [
            ("kappa", self.kappa),
            ("fit-radius", self.fit_radius),
            ("rmls-radius", self.rmls_radius),
            ("step", self.step),
            ("evaluate-per-fit", self.evaluate_per_fit),
        ] {
            if let Some(v) = v
                && !(v > 0.0 && v.is_finite())
            {
                return refuse(&format!("--{name} must be a positive number"));
            }
        }
        if let Some(t) = self.tau
            && !(t >= 0.0 && t.is_finite())
        {
            return refuse("--tau must be a residual of 0 or more");
        }
        if let Some(a) = self.max_turn_deg
            && !(a > 0.0 && a <= 180.0)
        {
            return refuse("--max-turn must be an angle above 0 and at most 180 degrees");
        }
        if let Some(a) = self.min_angle_deg
            && !(0.0..180.0).contains(&a)
        {
            return refuse("--min-angle must be an angle from 0 to below 180 degrees");
        }
        Ok(())
    }

    /// The same parameters with those given at their default value left unset, so that a job
    /// that names a default (`--seed 1`) is the job that does not.
    pub(crate) fn without_defaults(&self) -> Params {
        let unless = |v: Option<f64>, default: f64| v.filter(|&x| x != default);
        Params {
            max_turn_deg: unless(self.max_turn_deg, DEFAULT_MAX_TURN_DEG),
            min_angle_deg: unless(self.min_angle_deg, DEFAULT_MIN_ANGLE_DEG),
            seed: self.seed.filter(|&s| s != DEFAULT_SEED),
            model: self.model.filter(|&m| m != Model::default()),
            ..self.clone()
        }
    }

    /// Resolves defaults given the measured spacing `kappa` and noise `noise`.
    #[cfg(test)]
    pub(crate) fn resolve(&self, kappa: f64, noise: f64) -> Resolved {
        self.resolve_at_least(kappa, noise, 0.0)
    }

    /// As [`Params::resolve`], with the length unit at least `floor` or
    /// [`NOISY_FIT_NOISE`] noise deviations, whichever is less.
    fn resolve_at_least(&self, kappa: f64, noise: f64, floor: f64) -> Resolved {
        let kappa = self.kappa.unwrap_or(kappa);
        let scale = kappa.max(NOISE_SCALE * noise).max(floor.min(NOISY_FIT_NOISE * noise));
        let rmls = self.rmls_radius.unwrap_or(9.0 * scale);
        let step = self.step.unwrap_or(4.5 * scale);
        Resolved {
            kappa,
            noise,
            surface_noise: noise,
            scale,
            keep: 1.0,
            evaluate: 1.0,
            average: 0.0,
            average_share: 1.0,
            fit_radius: self.fit_radius.unwrap_or(FIT_SCALES * scale),
            rmls_radius: rmls,
            min_threshold: 0.05 * scale,
            step,
            max_turn_deg: self.max_turn_deg.unwrap_or(DEFAULT_MAX_TURN_DEG),
            min_angle_deg: self.min_angle_deg.unwrap_or(DEFAULT_MIN_ANGLE_DEG),
            corner_radius: rmls,
            reach_steps: 4.0,
            aperture_deg: 45.0,
            linearity: 0.7,
            seed: self.seed.unwrap_or(DEFAULT_SEED),
            model: self.model.unwrap_or_default(),
            near: 0.0,
        }
    }
}

fn every_point() -> f64 {
    1.0
}

/// Resolves the parameters from the sampled statistics: spacing and noise are their medians;
/// `keep` thins the cloud so that a fit sees about [`TARGET_NEIGHBOURS`] points. A kappa given
/// by the user replaces the measured one.
pub(crate) fn resolve(params: &Params, stats: &[PointStats]) -> Resolved {
    let mut k: Vec<f64> = stats.iter().map(|s| s.spacing).collect();
    let mut n: Vec<f64> = stats.iter().map(|s| s.noise).collect();
    let mut d: Vec<f64> = stats.iter().map(|s| s.density).collect();
    let spacing = settle(median(&mut k));
    // (On a noise-free cloud the fits leave rounding residue, 1e-31 or so, that differs with
    // the tiles' origins: below a 2^-26 share of the spacing, noise is zero.)
    let noise = |x: f64| if x < spacing * super::statistics::CLEAN { 0.0 } else { settle(x) };
    // (Settled as the spacing is: the share of points kept must be the same in any tiling.)
    let density = settle(median(&mut d));
    let floor = if density > 0.0 { (MIN_NOISY_FIT / (std::f64::consts::PI * density)).sqrt() / FIT_SCALES } else { 0.0 };
    let mut r = params.resolve_at_least(spacing, noise(median(&mut n)), floor);
    r.surface_noise = noise(quantile(&mut n, 0.25));
    let count = density * std::f64::consts::PI * r.fit_radius.powi(2);
    r.keep = if count > 0.0 { (TARGET_NEIGHBOURS / count).min(1.0) } else { 1.0 };
    if r.keep >= 0.7 {
        r.keep = 1.0;
    }
    if r.keep < 1.0 {
        r.average = AVERAGE_NOISE * r.noise;
        let in_ball = count * (r.average / r.fit_radius).powi(2);
        r.average_share = (AVERAGE_POINTS / in_ball).min(1.0);
    }
    let kept = count * r.keep;
    if let Some(per_fit) = params.evaluate_per_fit
        && kept > per_fit
    {
        r.evaluate = per_fit / kept;
    }
    if let Some(k) = params.kappa {
        r.kappa = k;
    }
    r
}

/// Refuses a length the user gave (`--kappa`, `--fit-radius`, `--rmls-radius`, `--step`)
/// below a hundredth of the spacing the statistics `stats` measured, or beyond the cloud's
/// `diagonal`: each was taken, and gave no curve without a word, `--step 1e-15` after a
/// minute of growing. (Checked once the statistics are in: before, the cloud's spacing is not
/// known.)
pub(crate) fn check_given_lengths(params: &Params, stats: &[PointStats], diagonal: f64) -> crate::error::Result<()> {
    let spacing = median(&mut stats.iter().map(|s| s.spacing).collect::<Vec<_>>());
    if !(spacing > 0.0 && spacing.is_finite() && diagonal > 0.0 && diagonal.is_finite()) {
        return Ok(());
    }
    let given = [("--kappa", params.kappa), ("--fit-radius", params.fit_radius), ("--rmls-radius", params.rmls_radius), ("--step", params.step)];
    for (name, v) in given.into_iter().filter_map(|(n, v)| v.map(|v| (n, v))) {
        if v < 0.01 * spacing || v > diagonal {
            return Err(crate::error::Error::Usage(format!(
                "{name} {v}: outside what this cloud allows, a hundredth of its point spacing ({:.3e}) to its diagonal ({diagonal:.3e}); give another value with --force to start the run over",
                0.01 * spacing
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stats(spacing: f64, noise: f64, density: f64) -> Vec<PointStats> {
        vec![PointStats { spacing, noise, density, twin: false }; 5]
    }

    /// Evaluation is thinned only when asked, and only to what a fit's disk holds: a clean
    /// cloud's disk (about 25 points at 6 spacings) is evaluated whole at 40 a disk, a noisy
    /// one thinned to hold 150 is evaluated at 40 of its 150.
    #[test]
    fn the_share_evaluated_follows_the_points_a_fit_holds() {
        let density = 2f64.ln() / std::f64::consts::PI; // a median spacing of 1
        let clean = resolve(&Params::default(), &stats(1.0, 0.0, density));
        assert_eq!(clean.evaluate, 1.0);
        let asked = Params { evaluate_per_fit: Some(40.0), ..Params::default() };
        assert_eq!(resolve(&asked, &stats(1.0, 0.0, density)).evaluate, 1.0);
        let noisy = resolve(&asked, &stats(1.0, 3.0, density));
        assert!(noisy.keep < 1.0);
        let held = density * std::f64::consts::PI * noisy.fit_radius.powi(2) * noisy.keep;
        assert!((held - TARGET_NEIGHBOURS).abs() < 1e-6 * TARGET_NEIGHBOURS, "{held}");
        assert!((noisy.evaluate - 40.0 / TARGET_NEIGHBOURS).abs() < 1e-9, "{}", noisy.evaluate);
        assert_eq!(resolve(&Params::default(), &stats(1.0, 3.0, density)).evaluate, 1.0);
    }

    /// Where the noise sizes the neighbourhoods, a fit holds at least [`MIN_NOISY_FIT`] points;
    /// a clean cloud's length unit stays its spacing, and a noisier one's the noise's.
    #[test]
    fn noisy_fits_hold_enough_points() {
        let density = 2f64.ln() / std::f64::consts::PI; // a median spacing of 1
        let held = |r: &Resolved| density * std::f64::consts::PI * r.fit_radius.powi(2);
        let clean = resolve(&Params::default(), &stats(1.0, 0.0, density));
        assert_eq!(clean.scale, 1.0);
        assert!(held(&clean) < MIN_NOISY_FIT);
        // Noise of about 2 spacings: 1.25 of its deviations would make fits of about 28 points.
        let two = resolve(&Params::default(), &stats(1.0, 0.9, density));
        assert!(two.noise_limited());
        assert!((held(&two) - MIN_NOISY_FIT).abs() < 1e-9 * MIN_NOISY_FIT, "{}", held(&two));
        let far = resolve(&Params::default(), &stats(1.0, 3.0, density));
        assert_eq!(far.scale, NOISE_SCALE * 3.0);
        // Between: the unit grows with the noise from the spacing on (no jump where the noise
        // starts to size it).
        let units: Vec<f64> = [0.3, 0.45, 0.55, 0.6, 0.7, 0.9].iter().map(|&x| resolve(&Params::default(), &stats(1.0, x, density)).scale).collect();
        assert_eq!(units[0], 1.0);
        assert!(units.windows(2).all(|w| w[1] >= w[0] && w[1] - w[0] <= 2.0 * 0.2 + 1e-6), "{units:?}");
        assert!((units[3] - NOISY_FIT_NOISE * 0.6).abs() < 1e-6, "{units:?}");
    }

    /// Only a thinned cloud's kept points are averaged, over [`AVERAGE_NOISE`] deviations and
    /// about [`AVERAGE_POINTS`] points.
    #[test]
    fn only_a_thinned_cloud_is_averaged() {
        let density = 2f64.ln() / std::f64::consts::PI;
        let clean = resolve(&Params::default(), &stats(1.0, 0.0, density));
        assert_eq!((clean.keep, clean.average), (1.0, 0.0));
        let noisy = resolve(&Params::default(), &stats(1.0, 3.0, density));
        assert!(noisy.keep < 1.0);
        assert_eq!(noisy.average, AVERAGE_NOISE * noisy.noise);
        // (About 25 points in its ball: all taken. Twenty times denser, a share of them.)
        assert_eq!(noisy.average_share, 1.0);
        let dense = resolve(&Params::default(), &stats(1.0, 3.0, 20.0 * density));
        let in_ball = 20.0 * density * std::f64::consts::PI * dense.average.powi(2);
        assert!((in_ball * dense.average_share - AVERAGE_POINTS).abs() < 1e-6, "{in_ball} {}", dense.average_share);
    }
}
