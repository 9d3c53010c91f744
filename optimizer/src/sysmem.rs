//! The machine's memory as `/proc` reports it: what a run may grow into
//! and what this process holds. Used where input could ask for more memory
//! than there is (a placement's rebuilt impostor lists, a job's predicted
//! peak), so that it is refused with a message instead of killed.

/// The memory this run may grow into, bytes: what the machine has
/// available now (`MemAvailable`, which other processes' use lowers) and
/// what this process already holds, never more than the machine's
/// (`MemTotal`); `u64::MAX` when unknown.
pub fn machine_memory_bytes() -> u64 {
    let total = meminfo_kb("/proc/meminfo", "MemTotal:").map_or(u64::MAX, |kb| kb * 1024);
    meminfo_kb("/proc/meminfo", "MemAvailable:").map_or(total, |kb| {
        (kb * 1024).saturating_add(current_rss_bytes()).min(total)
    })
}

/// Resident set size of this process now (VmRSS), bytes; 0 when unknown.
pub fn current_rss_bytes() -> u64 {
    meminfo_kb("/proc/self/status", "VmRSS:").map_or(0, |kb| kb * 1024)
}

/// The kB value of line `key` of a `/proc` file.
fn meminfo_kb(path: &str, key: &str) -> Option<u64> {
    std::fs::read_to_string(path)
        .ok()?
        .lines()
        .find_map(|l| l.strip_prefix(key))?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// Peak resident set size of this process (VmHWM), bytes; 0 when unknown.
pub fn peak_rss_bytes() -> u64 {
    meminfo_kb("/proc/self/status", "VmHWM:").map_or(0, |kb| kb * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The default limit is the memory available to this run: at least
    /// what it holds, at most the machine's, and below the machine's by
    /// what other processes hold (here, at least the kernel's own).
    #[test]
    fn the_memory_limit_is_what_is_available() {
        let total = meminfo_kb("/proc/meminfo", "MemTotal:").expect("MemTotal") * 1024;
        let limit = machine_memory_bytes();
        assert!(limit >= current_rss_bytes(), "{limit}");
        assert!(limit < total, "{limit} of {total}");
    }
}
