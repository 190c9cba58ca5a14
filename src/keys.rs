//! Canonical keys and rounding: what makes a result independent of tiling, file layout and
//! thread count.
//!
//! A point's identity is its position rounded to a fine quantum and hashed ([`position_key`]),
//! so the same point gets the same key (and random stream, see [`crate::rng`]) whichever file,
//! tile or order it comes in. Positions computed in differently placed tiles are snapped to a
//! grid far finer than the spacing ([`snap`]), and global statistics are rounded to 32
//! significant bits ([`settle`]), so that the last bits of tile-local arithmetic cannot flip a
//! discrete decision.

use crate::rng::Rng;
use glam::DVec3;

/// FNV-1a, 64 bit: a stable content hash (std's hasher may change between Rust versions).
pub(crate) fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The quantum of [`position_key`] for a cloud with bounding-box diagonal `diag`: a power of
/// two near a billionth of it, so that clouds whose bounds differ in the last bits agree.
pub(crate) fn key_quantum(diag: f64) -> f64 {
    2f64.powi((diag.max(1e-300) * 1e-9).log2().floor() as i32)
}

/// A point's identity from its position (rounded to `q`): the same point gets the same key
/// whichever file, tile or order it comes in, so sampling and thinning by key are independent
/// of how a cloud is split.
pub(crate) fn position_key(p: DVec3, q: f64) -> u64 {
    let w = (p / q).round();
    let mut bytes = [0u8; 24];
    for (k, v) in w.to_array().iter().enumerate() {
        bytes[8 * k..8 * k + 8].copy_from_slice(&(*v as i64).to_le_bytes());
    }
    fnv1a(&bytes)
}

/// True if the point with key `id` belongs to the share `keep` of a cloud thinned by key.
pub(crate) fn keep_point(id: u64, keep: f64, seed: u64) -> bool {
    if keep >= 1.0 {
        return true;
    }
    let mut r = Rng::stream(seed ^ crate::salts::KEEP_POINT, id);
    r.f64() < keep
}

/// The grid positions are snapped to for a cloud of spacing `kappa`: far finer than the
/// spacing. Positions computed in differently placed tiles differ in their last bits, and the
/// curve stages are discrete (seed order, cone tests); snapped, their input, and so the
/// curves, are the same for any tiling.
pub(crate) fn snap_quantum(kappa: f64) -> f64 {
    kappa / 4096.0
}

/// `p` on the snapping grid of quantum `q`.
pub(crate) fn snap(p: DVec3, q: f64) -> DVec3 {
    // (+ 0.0 turns a negative zero, whose sign is rounding noise, into zero.)
    (p / q).round() * q + DVec3::ZERO
}

/// `x` rounded to 32 significant bits. The global quantities (spacing, noise, tau) are
/// statistics of fits made in each tile's local coordinates, and their last bits depend on
/// where a tile's origin lies; rounded, they come out the same in any tiling (unless two
/// values straddle a rounding boundary, a chance of about one in a billion), so that no
/// candidate or projection decides differently because of the tiling.
pub(crate) fn settle(x: f64) -> f64 {
    if !x.is_finite() {
        return x;
    }
    const DROP: u32 = 52 - 31;
    let b = x.to_bits();
    f64::from_bits((b + (1 << (DROP - 1))) & !((1u64 << DROP) - 1))
}

/// Sorting key of a snapped position: its bits (equal means identical).
pub(crate) fn bits_key(p: DVec3) -> [u64; 3] {
    p.to_array().map(f64::to_bits)
}

#[cfg(test)]
mod tests {
    use super::settle;

    #[test]
    fn settled_values_forget_their_last_bits() {
        for x in [1.0f64, 0.007509334601371811, 0.0022075607504528335, 123456.789] {
            let up = f64::from_bits(x.to_bits() + 3);
            let down = f64::from_bits(x.to_bits() - 3);
            assert_eq!(settle(up), settle(x));
            assert_eq!(settle(down), settle(x));
            assert!((settle(x) - x).abs() <= x * 2f64.powi(-31));
        }
        assert_eq!(settle(0.0), 0.0);
    }
}
