//! Process memory figures (Linux `/proc`), for reports and benchmarks.

/// Peak resident set size of this process in bytes (VmHWM), or 0 where unavailable.
pub fn peak_rss() -> u64 {
    status_kib("VmHWM:") * 1024
}

/// The peak resident set size of a stretch of work, sampled every few milliseconds by a thread
/// of its own. (The kernel's own peak could be started again instead, but then tools that read
/// it for the whole process, such as `time -v`, would see only the last stretch.)
pub(crate) struct PeakSampler {
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: Option<std::thread::JoinHandle<u64>>,
}

impl PeakSampler {
    /// Starts sampling.
    pub(crate) fn start() -> PeakSampler {
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let flag = stop.clone();
        let thread = std::thread::Builder::new()
            .name("crease-rss".into())
            .spawn(move || {
                let mut peak = current_rss();
                while !flag.load(std::sync::atomic::Ordering::Relaxed) {
                    std::thread::sleep(std::time::Duration::from_millis(5));
                    peak = peak.max(current_rss());
                }
                peak
            })
            .ok();
        PeakSampler { stop, thread }
    }

    /// Stops sampling; the largest resident set size seen, bytes (0 where unavailable).
    pub(crate) fn finish(mut self) -> u64 {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        let last = current_rss();
        self.thread.take().and_then(|t| t.join().ok()).unwrap_or(0).max(last)
    }
}

impl Drop for PeakSampler {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
    }
}

/// `work`'s result and the peak resident set size while it ran, bytes (see [`PeakSampler`]).
pub(crate) fn sampled<T>(work: impl FnOnce() -> T) -> (T, u64) {
    let sampler = PeakSampler::start();
    let out = work();
    (out, sampler.finish())
}

/// Current resident set size in bytes (VmRSS), or 0 where unavailable.
pub(crate) fn current_rss() -> u64 {
    status_kib("VmRSS:") * 1024
}

/// Physical memory of the machine in bytes (MemTotal), or 0 where unavailable.
pub(crate) fn total_memory() -> u64 {
    std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("MemTotal:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok()))
        .unwrap_or(0)
        * 1024
}

fn status_kib(key: &str) -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with(key)).and_then(|l| l.split_whitespace().nth(1)?.parse().ok()))
        .unwrap_or(0)
}

/// Makes the allocator give every block of 1 MiB or more its own mapping, returned to the
/// operating system when freed. glibc does so by default only up to a threshold it raises to
/// the largest block freed so far (up to 32 MiB), so a tile's buffers, freed and allocated
/// again for the next tile, end up in the heaps, fragmented, and are never returned. Measured
/// on a 10 M-point run with `--memory 1G`: peak RSS 551-589 MB before, 405-422 MB after, at
/// the same speed. Process-wide, so the command-line tool calls it, not the library.
pub fn map_large_blocks_apart() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes a tuning parameter of the allocator.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 1 << 20);
    }
}

/// Hands memory freed by finished work back to the operating system where the allocator would
/// keep it (glibc keeps the freed blocks of every thread's arena mapped). Called between the
/// tile passes and the curve stage, so that the memory the tile passes used is not counted a
/// second time, under a memory limit, on top of the curve stage's.
pub(crate) fn release_free_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only releases free pages of the allocator's own heaps.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// Parses sizes such as 1G, 512M, 2.5GB, 1000000 (bytes), as `--memory` takes them (and the
/// Python binding's `memory=`).
///
/// ```
/// assert_eq!(crease::mem::parse_size("512M"), Ok(512 << 20));
/// assert!(crease::mem::parse_size("lots").is_err());
/// ```
pub fn parse_size(s: &str) -> Result<u64, String> {
    let t = s.trim().to_ascii_uppercase();
    let t = t.strip_suffix('B').unwrap_or(&t);
    let (num, mul) = match t.chars().last() {
        Some('K') => (&t[..t.len() - 1], 1u64 << 10),
        Some('M') => (&t[..t.len() - 1], 1 << 20),
        Some('G') => (&t[..t.len() - 1], 1 << 30),
        Some('T') => (&t[..t.len() - 1], 1 << 40),
        _ => (t, 1),
    };
    let v: f64 = num.parse().map_err(|_| format!("'{s}' is not a size (e.g. 1G, 512M)"))?;
    if v.is_nan() || v <= 0.0 {
        return Err(format!("'{s}' must be positive"));
    }
    Ok((v * mul as f64) as u64)
}
