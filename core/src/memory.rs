//! Memory checked before it is spent (docs/robustness.md, "Limits"): how much memory this
//! process may still use, and the refusal of a setting whose estimated peak would not fit,
//! with the estimate and the largest setting that would.
//!
//! The memory available is the smallest of what the system says is available
//! (`MemAvailable` in `/proc/meminfo`) and what the process's cgroup still allows (cgroup v2
//! `memory.max − memory.current`, or v1 `memory.limit_in_bytes − memory.usage_in_bytes`), so a
//! container's limit counts. `PHOTOMAT_MEMORY_LIMIT` (bytes, or with a `K`, `M` or `G`
//! suffix) replaces it, for tests and for users who want a margin. Where none of these can be
//! read (not Linux), nothing is refused.

use crate::{Error, Result};

/// The environment variable that replaces the memory available.
pub const LIMIT_VARIABLE: &str = "PHOTOMAT_MEMORY_LIMIT";

/// Bytes as text with one decimal in the largest unit that keeps it above 1 (`19.3 GB`).
pub fn format_bytes(bytes: u64) -> String {
    let b = bytes as f64;
    let (value, unit) = if b >= 1e9 {
        (b / 1e9, "GB")
    } else if b >= 1e6 {
        (b / 1e6, "MB")
    } else {
        (b / 1e3, "kB")
    };
    format!("{value:.1} {unit}")
}

/// `16G`, `512M`, `1024` (bytes) → bytes.
fn parse_bytes(text: &str) -> Option<u64> {
    let text = text.trim();
    let (number, factor) = match text.chars().last()? {
        'k' | 'K' => (&text[..text.len() - 1], 1u64 << 10),
        'm' | 'M' => (&text[..text.len() - 1], 1 << 20),
        'g' | 'G' => (&text[..text.len() - 1], 1 << 30),
        _ => (text, 1),
    };
    number
        .trim()
        .parse::<f64>()
        .ok()
        .map(|v| (v * factor as f64) as u64)
}

/// The first number of the line of `text` that starts with `key` (`MemAvailable:  123 kB`).
fn meminfo_value(text: &str, key: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(key))?;
    line[key.len()..].split_whitespace().next()?.parse().ok()
}

/// What the process's cgroup still allows, when it has a limit.
fn cgroup_headroom() -> Option<u64> {
    let read = |p: &str| std::fs::read_to_string(p).ok();
    let number = |t: Option<String>| t.and_then(|t| t.trim().parse::<u64>().ok());
    // cgroup v2: the process's own group, relative to the unified hierarchy's mount.
    if let Some(group) = read("/proc/self/cgroup").and_then(|t| {
        t.lines()
            .find_map(|l| l.strip_prefix("0::").map(str::to_string))
    }) {
        let dir = format!("/sys/fs/cgroup{}", group.trim_end_matches('/'));
        if let Some(max) = number(read(&format!("{dir}/memory.max"))) {
            let current = number(read(&format!("{dir}/memory.current"))).unwrap_or(0);
            return Some(max.saturating_sub(current));
        }
    }
    // cgroup v1: "no limit" is a huge number, which min() below ignores.
    let limit = number(read("/sys/fs/cgroup/memory/memory.limit_in_bytes"))?;
    let usage = number(read("/sys/fs/cgroup/memory/memory.usage_in_bytes")).unwrap_or(0);
    Some(limit.saturating_sub(usage))
}

/// Bytes this process may still allocate (module docs), and where the figure came from;
/// `None` when nothing says.
pub fn available() -> Option<(u64, &'static str)> {
    if let Ok(text) = std::env::var(LIMIT_VARIABLE) {
        return parse_bytes(&text).map(|b| (b, LIMIT_VARIABLE));
    }
    let system = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|t| meminfo_value(&t, "MemAvailable:"))
        .map(|kb| kb * 1024);
    match (system, cgroup_headroom()) {
        (Some(s), Some(c)) if c < s => Some((c, "the cgroup's memory limit")),
        (Some(s), _) => Some((s, "MemAvailable in /proc/meminfo")),
        (None, Some(c)) => Some((c, "the cgroup's memory limit")),
        (None, None) => None,
    }
}

/// Refuses a setting whose estimated peak `needed` bytes exceeds what is [`available`]:
/// `setting` names it (`--size 4096`), `smaller` proposes what fits (`use --size 2048 (about
/// 4.8 GB) or less`), called only when refusing.
pub fn check(needed: u64, setting: &str, smaller: impl FnOnce(u64) -> String) -> Result<()> {
    let Some((available, source)) = available() else {
        return Ok(());
    };
    if needed <= available {
        return Ok(());
    }
    Err(Error::Invalid(format!(
        "{setting} needs about {} of memory at its peak (estimated from the shapes), and {} is \
         available ({source}); {}",
        format_bytes(needed),
        format_bytes(available),
        smaller(available)
    )))
}

/// The largest of `candidates` (in increasing order) whose `estimate` fits in `available`
/// bytes, with its estimate.
pub fn largest_fitting<T: Copy>(
    candidates: impl IntoIterator<Item = T>,
    estimate: impl Fn(T) -> u64,
    available: u64,
) -> Option<(T, u64)> {
    candidates
        .into_iter()
        .map(|c| (c, estimate(c)))
        .take_while(|(_, bytes)| *bytes <= available)
        .last()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_and_meminfo_lines_parse() {
        assert_eq!(parse_bytes("6G"), Some(6 << 30));
        assert_eq!(parse_bytes("512 m"), Some(512 << 20));
        assert_eq!(parse_bytes("lots"), None);
        assert_eq!(parse_bytes("1024"), Some(1024));
        let info = "MemTotal:       24000000 kB\nMemAvailable:   20000000 kB\n";
        assert_eq!(meminfo_value(info, "MemAvailable:"), Some(20_000_000));
        assert_eq!(format_bytes(19_300_000_000), "19.3 GB");
    }

    #[test]
    fn the_largest_fitting_candidate_is_the_last_under_the_budget() {
        let estimate = |side: u64| side * side * 1000;
        assert_eq!(
            largest_fitting([256u64, 512, 1024, 2048], estimate, 300_000_000),
            Some((512, 262_144_000))
        );
        assert_eq!(largest_fitting([256u64], estimate, 1), None);
    }
}
