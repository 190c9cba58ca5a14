//! A small cache of the records the curve stage read last, for neighbouring blocks that read
//! the same ones.

use crate::error::Result;
use crate::extract::polylines::SmoothedEdges;
use crate::extract::WorldEdge;
use rayon::prelude::*;

/// The last few records read (tiles' edge points, blocks' smoothed edge points), up to a number
/// of points in all, so that neighbouring blocks do not decode the same records again.
pub(super) struct Recent<T> {
    cap: u64,
    held: u64,
    items: std::collections::VecDeque<(u32, std::sync::Arc<T>, u64)>,
}

/// A record's size, in points.
pub(super) trait Points {
    fn points(&self) -> u64;
}

impl Points for Vec<WorldEdge> {
    fn points(&self) -> u64 {
        self.len() as u64
    }
}

impl Points for SmoothedEdges {
    fn points(&self) -> u64 {
        self.points.len() as u64
    }
}

impl<T: Points + Send + Sync> Recent<T> {
    pub(super) fn new(cap: u64) -> Recent<T> {
        Recent { cap, held: 0, items: Default::default() }
    }

    /// The records `ids`, those not held read by `read` (in parallel), in the order asked.
    pub(super) fn get(&mut self, ids: &[u32], read: impl Fn(u32) -> Result<T> + Sync) -> Result<Vec<std::sync::Arc<T>>> {
        let missing: Vec<u32> = ids.iter().copied().filter(|&k| !self.items.iter().any(|x| x.0 == k)).collect();
        let read = missing.par_iter().map(|&k| Ok((k, std::sync::Arc::new(read(k)?)))).collect::<Result<Vec<_>>>()?;
        let out: Vec<std::sync::Arc<T>> = ids
            .iter()
            .map(|&k| read.iter().find(|x| x.0 == k).map(|x| x.1.clone()).unwrap_or_else(|| self.items.iter().find(|x| x.0 == k).unwrap().1.clone()))
            .collect();
        for (k, item) in read {
            let n = item.points();
            self.items.push_back((k, item, n));
            self.held += n;
        }
        while self.held > self.cap {
            let Some((_, _, n)) = self.items.pop_front() else { break };
            self.held -= n;
        }
        Ok(out)
    }
}
