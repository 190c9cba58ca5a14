//! Process memory figures (Linux `/proc`), for reports and benchmarks.

/// Peak resident set size of this process in bytes (VmHWM), or 0 where unavailable.
pub fn peak_rss() -> u64 {
    status_kib("VmHWM:") * 1024
}

/// Current resident set size in bytes (VmRSS), or 0 where unavailable.
pub fn current_rss() -> u64 {
    status_kib("VmRSS:") * 1024
}

/// Physical memory of the machine in bytes (MemTotal), or 0 where unavailable.
pub fn total_memory() -> u64 {
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
