//! The method, after Daniels et al. 2007 and 2008: one module a stage,
//! each a function of plain data, per tile where the stage is local.
//!
//! | stage | module | per tile |
//! |---|---|---|
//! | statistics (spacing, noise) | `statistics` | `statistics::tile_statistics` |
//! | defaults from them | `params` | |
//! | 1. candidates (MLS residual) | `candidates` | `candidates::tile_residuals`, `candidates::tile_candidates` |
//! | 2. robust projection, corners | `project` | `project::tile_edges` |
//! | 3. smoothing, consensus filter | `smooth`, `consensus` | `block_edges::sort_edges`, `block_edges::smooth_core` (per growth block, `blocks`) |
//! | 4. growing | `grow` | `polylines::grow_block`, then `stitch` |
//! | 5. completion | `complete` | per group of polylines that can act on each other (`groups`) |
//!
//! In a few lines each:
//! - **Statistics**: the spacing from the 16th neighbour, and the noise as the RMS of a quadric
//!   fitted about the point's own surface (the densest band of its ball, so that a thin part's
//!   far face is not taken for noise), over a ball at least `statistics::NOISE_BALL`
//!   deviations wide, at about 20 000 points sampled by position. Every default length follows
//!   from them (`params`); noisy clouds are thinned so that a fit holds about
//!   `params::TARGET_NEIGHBOURS` points, each point kept averaged over those dropped near it.
//! - **Candidates**: points whose MLS fit leaves a residual above tau (the mean residual), and
//!   under noise also where two planes fit the neighbourhood clearly better than a quadric.
//! - **Projection**: a forward search splits a candidate's ball into surfaces; two or more
//!   nearby give an edge point on their intersection, kept only where the data reaches the
//!   edge line and both surfaces fit within a few noise deviations (scatter such as a tree
//!   crown does not); three give a corner point.
//! - **Curves**: edge points smoothed by adaptive PCA, kept where their neighbours found the
//!   same two surfaces, grown into polylines in steps of at most `step` that turn no more than
//!   `max_turn`, stitched across block borders, then completed: gaps closed, corners re-solved
//!   from the straight runs of their curves and joined, and each curve's normals and confidence
//!   taken from the smoothed edge points.
//!
//! `neighbourhood` holds a tile's points indexed for neighbour queries, `fit` the small
//! fits every stage uses. The pipeline that runs the stages over tiles is [`crate::run`].

pub(crate) mod block_edges;
pub(crate) mod blocks;
pub(crate) mod candidates;
pub(crate) mod complete;
pub(crate) mod consensus;
pub(crate) mod fit;
pub(crate) mod groups;
pub(crate) mod grow;
pub(crate) mod neighbourhood;
pub(crate) mod params;
pub(crate) mod polylines;
pub(crate) mod project;
pub(crate) mod smooth;
pub(crate) mod statistics;
pub(crate) mod stitch;
pub(crate) mod sweep;

pub use blocks::BASE_STEPS;
pub use params::{Model, Params, Resolved};
pub use polylines::DEFAULT_MIN_CONFIDENCE;
pub(crate) use project::{TileEdges, WorldCorner, WorldEdge};

use serde::{Deserialize, Serialize};

/// Counts per stage.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Counts {
    /// Input points (after filtering, far points left out).
    pub points: u64,
    /// Points left out as far from all the others (stray points that would have set the
    /// bounds; see the run's far-point rule).
    #[serde(default)]
    pub far_points: u64,
    /// Points dropped as copies at the very position of another (overlapping scans, tiles
    /// merged twice): counted in `points`, left out of the statistics and the fits.
    #[serde(default)]
    pub exact_duplicates: u64,
    /// Points dropped as near copies of another (within a small share of the spacing, see
    /// `statistics::NEAR_DUPLICATE`): counted in `points`, left out as the exact ones are.
    #[serde(default)]
    pub near_duplicates: u64,
    /// Points at which stages 1-2 were evaluated (fewer than the input where a noisy cloud is
    /// thinned, see [`Resolved::keep`]).
    #[serde(default)]
    pub evaluated: u64,
    /// Candidates (residual above tau).
    pub candidates: u64,
    /// Candidates dropped as outliers (one surface).
    pub one_surface: u64,
    /// Candidates dropped as scatter: a surface through them fitted worse than the noise
    /// allows (see `project::SURFACE_NOISE`).
    #[serde(default)]
    pub scattered: u64,
    /// Edge points after projection and culling.
    pub edge_points: u64,
    /// Corner points before grouping.
    pub corner_points: u64,
    /// Edge points dropped before growing because no neighbour agreed on their two surfaces
    /// (see `consensus`).
    #[serde(default)]
    pub unconfirmed: u64,
    /// Corners after grouping.
    pub corners: u64,
    /// Growth blocks of the curve stage (see `blocks`).
    #[serde(default)]
    pub blocks: u64,
    /// Polylines grown.
    pub grown: u64,
    /// Curves written (after completion, less those left out).
    pub curves: u64,
    /// Curves left out for confidence or length below `--min-confidence` or `--min-length`.
    #[serde(default)]
    pub left_out: u64,
    /// Clusters of pieces of polylines cut because they outgrew
    /// `sweep::MAX_CLUSTER_VERTICES`: lines across such a cut come out in two.
    #[serde(default)]
    pub clusters_cut: u64,
    /// Batches in which the curve stage completed, attributed and wrote the curves (see
    /// `groups`): more as the curves outgrow a sixteenth of `--memory`.
    #[serde(default)]
    pub batches: u64,
}

/// Seconds per stage.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Timings {
    /// Spacing estimate and k-d tree.
    pub index: f64,
    /// Stage 1.
    pub candidates: f64,
    /// Stage 2.
    pub projection: f64,
    /// Stage 3.
    pub smoothing: f64,
    /// Stage 4.
    pub growing: f64,
    /// Stage 5.
    pub completion: f64,
}
