//! The salts of the keyed random choices. A choice made at random is drawn from a point's
//! position key or global id, so that it is the same whatever the tiling; each purpose XORs
//! the key with a salt of its own, so that the choices of different purposes are independent
//! (a point kept by the thinning is no likelier to be evaluated). The values are arbitrary, but
//! changing one changes which points are chosen, and so the outputs.

/// Of every keep-or-drop draw ([`crate::keys::keep_point`]), XORed with the seed: its stream
/// differs from the other streams drawn from the same seed.
pub(crate) const KEEP_POINT: u64 = 0x7417;

/// The statistics pass's sample of points (see [`crate::extract::statistics::stat_sample`]).
pub(crate) const STATISTICS_SAMPLE: u64 = 0x5A5A_5A5A;

/// A point's level in a thinned cloud's levels for neighbour queries (see
/// [`crate::extract::neighbourhood::Thinned`]), from its global id.
pub(crate) const THINNED_LEVEL: u64 = 0x6E01_5EBA;

/// The points a kept point is averaged over when a noisy cloud is thinned (see
/// [`crate::extract::Resolved::average_share`]): not the points kept.
pub(crate) const AVERAGED: u64 = 0xA7E4_6E5A;

/// The core points evaluated in stages 1 and 2 of a thinned cloud (see
/// [`crate::extract::Resolved::evaluate`]): not the points kept.
pub(crate) const EVALUATED: u64 = 0xE7A1_0A7E;

/// The sample of a run's points drawn in `preview.png` and `view.html`.
pub(crate) const PREVIEW_SAMPLE: u64 = 0x9E37_79B9;

/// The clutter (grass, trees) of a block of the synthetic scene, a stream of its own so that
/// the rest of the block is the scene without clutter.
pub(crate) const SCENE_CLUTTER: u64 = 0xC1A7;
