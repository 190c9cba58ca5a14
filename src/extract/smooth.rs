//! Stage 3: smoothing of projected edge points (Daniels 2007, section 3.4).
//!
//! Each edge point moves onto the principal axis of its neighbourhood among the edge points,
//! grown adaptively (nearest first) until the neighbourhood is clearly linear, and never past
//! the nearest corner, where it would start to take in another feature. Linearity is measured
//! rotation-invariantly as (l0 - l1) / (l0 + l1) of the covariance eigenvalues (the paper's
//! correlation coefficient is zero by construction in the PCA frame).

use super::fit::Pca;
use crate::spatial::Index;
use glam::DVec3;
use rayon::prelude::*;

/// Smoothing parameters.
#[derive(Clone, Copy, Debug)]
pub struct SmoothParams {
    /// Grow until (l0 - l1) / (l0 + l1) reaches this.
    pub linearity: f64,
    /// Largest neighbourhood radius.
    pub max_radius: f64,
}

/// Smallest and largest neighbourhood sizes tried.
const MIN_K: usize = 8;
const MAX_K: usize = 64;

/// Smoothed positions of `points`; `corners` cap the neighbourhoods.
pub fn smooth(points: &[DVec3], corners: &[DVec3], p: &SmoothParams) -> Vec<DVec3> {
    if points.len() < MIN_K {
        return points.to_vec();
    }
    // (The f32 copy is only the tree's input: the edge cloud grows with the whole scan.)
    let index = Index::new(&points.iter().map(|q| q.as_vec3().to_array()).collect::<Vec<_>>());
    let corner_index = (!corners.is_empty()).then(|| Index::new(&corners.iter().map(|q| q.as_vec3().to_array()).collect::<Vec<_>>()));
    (0..points.len())
        .into_par_iter()
        .map_init(Vec::new, |nn, i| {
            let x = points[i];
            let xf = x.as_vec3().to_array();
            let cap = corner_index.as_ref().map_or(f64::INFINITY, |ci| {
                let mut c = Vec::new();
                ci.nearest_n(&xf, 1, &mut c);
                corners[c[0].0 as usize].distance(x)
            });
            let radius = p.max_radius.min(cap);
            nn.clear();
            index.nearest_n(&xf, MAX_K.min(points.len()), nn);
            let mut k = MIN_K;
            let mut best: Option<Pca> = None;
            while k <= nn.len() {
                if (nn[k - 1].1 as f64).sqrt() > radius {
                    break;
                }
                let pca = Pca::of(nn[..k].iter().map(|&(j, _)| (points[j as usize], 1.0)));
                if let Some(pca) = pca {
                    best = Some(pca);
                    if pca.line_measure() >= p.linearity {
                        break;
                    }
                }
                k += 4;
            }
            match best {
                Some(pca) => pca.mean + pca.axis() * (x - pca.mean).dot(pca.axis()),
                None => x,
            }
        })
        .collect()
}
