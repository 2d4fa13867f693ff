//! Process memory figures for reports and the memory budget: peak and current resident set
//! size, and the machine's physical memory; and [`release_freed`], which hands memory freed in
//! small blocks back to the system between the solver's stages.
//!
//! On Linux they come from `/proc/self/status` (`VmHWM` is the peak resident set size, `VmRSS`
//! the current one) and `/proc/meminfo` (`MemTotal`). Elsewhere every function returns `None` /
//! `false`: a report then says the figure is unknown rather than guessing.

use crate::error::Error;

/// Peak resident set size of this process so far, in bytes (`VmHWM`); `None` off Linux or when
/// `/proc` cannot be read.
pub fn peak_rss_bytes() -> Option<u64> {
    status_field("VmHWM")
}

/// Current resident set size of this process, in bytes (`VmRSS`); `None` off Linux or when
/// `/proc` cannot be read.
pub fn current_rss_bytes() -> Option<u64> {
    status_field("VmRSS")
}

/// Physical memory of the machine, in bytes (`MemTotal` of `/proc/meminfo`); `None` off Linux
/// or when `/proc` cannot be read.
pub fn physical_memory_bytes() -> Option<u64> {
    #[cfg(target_os = "linux")]
    {
        let text = std::fs::read_to_string("/proc/meminfo").ok()?;
        parse_status_field(&text, "MemTotal")
    }
    #[cfg(not(target_os = "linux"))]
    {
        None
    }
}

/// Resets the peak resident set size to the current one, so that the peak of a later stage can
/// be measured on its own (Linux: writes `5` to `/proc/self/clear_refs`). Returns false when
/// the reset is not available; the peak then keeps counting from process start.
pub fn reset_peak_rss() -> bool {
    #[cfg(target_os = "linux")]
    {
        std::fs::write("/proc/self/clear_refs", "5").is_ok()
    }
    #[cfg(not(target_os = "linux"))]
    {
        false
    }
}

/// True where [`release_freed`] hands freed memory back (glibc's allocator on Linux).
pub const RELEASES_FREED: bool = cfg!(all(target_os = "linux", target_env = "gnu"));

/// Hands the memory the allocator holds free back to the system, so that what a finished stage
/// freed in small blocks (the exact couplings' rows, one small vector per receiver) does not stay
/// resident beside the next stage's large arrays. With glibc's allocator (`malloc_trim`, which
/// also releases the free pages inside its heaps); elsewhere it does nothing. Returns true when
/// some memory was released.
pub fn release_freed() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        extern "C" {
            fn malloc_trim(pad: usize) -> i32;
        }
        // SAFETY: `malloc_trim` only walks the allocator's own free lists (under its locks) and
        // returns their pages to the kernel; it touches no memory in use.
        unsafe { malloc_trim(0) != 0 }
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        false
    }
}

/// Reads one `Name:  <n> kB` field of `/proc/self/status`, in bytes.
fn status_field(name: &str) -> Option<u64> {
    #[cfg(target_os = "linux")]
    {
        let text = std::fs::read_to_string("/proc/self/status").ok()?;
        parse_status_field(&text, name)
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = name;
        None
    }
}

/// Parses the field `name` (e.g. `VmHWM`) of a `/proc/<pid>/status` or `/proc/meminfo` text into
/// bytes. The kernel writes these fields as `VmHWM:\t  123456 kB`; a value without a unit is
/// taken as bytes.
pub fn parse_status_field(text: &str, name: &str) -> Option<u64> {
    text.lines().find_map(|line| {
        let rest = line.strip_prefix(name)?.strip_prefix(':')?;
        let mut words = rest.split_whitespace();
        let value: u64 = words.next()?.parse().ok()?;
        match words.next() {
            None => Some(value),
            Some(unit) if unit.eq_ignore_ascii_case("kB") => value.checked_mul(1024),
            Some(_) => None,
        }
    })
}

/// Bytes as a short human figure (MB or GB).
pub fn format_bytes(bytes: u64) -> String {
    let mb = bytes as f64 / (1024.0 * 1024.0);
    if mb >= 1024.0 {
        format!("{:.2} GB", mb / 1024.0)
    } else {
        format!("{mb:.1} MB")
    }
}

/// The memory limit where the machine's physical memory is unknown (off Linux): 4 GiB.
pub const FALLBACK_MEMORY_LIMIT: u64 = 4 << 30;
/// Share of an estimate added for what it does not count (allocator slack, thread stacks and
/// per-thread buffers, small arrays): an estimate `e` must fit as `e + e / SLACK_DIVISOR +
/// SLACK_BYTES`.
const SLACK_DIVISOR: u64 = 8;
/// Bytes added to every estimate (see `SLACK_DIVISOR`).
const SLACK_BYTES: u64 = 16 << 20;
/// The default memory limit: half the machine's physical memory (`MemTotal` of `/proc/meminfo`
/// on Linux), [`FALLBACK_MEMORY_LIMIT`] where that is unknown.
pub fn default_memory_limit() -> u64 {
    physical_memory_bytes().map_or(FALLBACK_MEMORY_LIMIT, |m| m / 2)
}
/// Parses a size in bytes: a whole number of bytes (`1000000`), or a number with a suffix `K`,
/// `M`, `G` or `T` (powers of 1024, optionally followed by `B` or `iB`, any case: `512M`, `4G`,
/// `4GB`, `1.5G`, `64KiB`). The size must be at least 1 byte and below 2^64.
pub fn parse_size(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let bad =
        || format!("'{text}' is not a size (bytes, or a number with K, M, G or T: 512M, 4G, 1.5G)");
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (number, suffix) = t.split_at(split);
    let suffix = suffix.trim().to_ascii_uppercase();
    let unit = suffix
        .strip_suffix("IB")
        .or_else(|| suffix.strip_suffix('B'))
        .unwrap_or(&suffix);
    let multiplier: u64 = match unit {
        "" => 1,
        "K" => 1 << 10,
        "M" => 1 << 20,
        "G" => 1 << 30,
        "T" => 1 << 40,
        _ => return Err(bad()),
    };
    // "iB" alone is no unit.
    if unit.is_empty() && suffix.contains('I') {
        return Err(bad());
    }
    if number.is_empty() || number.matches('.').count() > 1 {
        return Err(bad());
    }
    let bytes = if multiplier == 1 {
        number
            .parse::<u64>()
            .map_err(|_| format!("'{text}': a size in bytes must be a whole number"))?
    } else {
        let x: f64 = number.parse().map_err(|_| bad())?;
        let bytes = x * multiplier as f64;
        if !(bytes.is_finite() && bytes < u64::MAX as f64) {
            return Err(format!("'{text}' is too large"));
        }
        bytes as u64
    };
    if bytes == 0 {
        return Err(format!("'{text}': the size must be at least 1 byte"));
    }
    Ok(bytes)
}
/// What one solve may allocate: the limit on the process's resident memory, less what the
/// process already holds when the solve starts (the scene and its patches).
#[derive(Clone, Copy, Debug)]
pub struct Budget {
    /// The limit on the process's resident memory, bytes.
    pub limit: u64,
    /// Resident memory when the solve started, bytes (0 where it cannot be measured).
    pub base: u64,
}

impl Budget {
    /// The budget of a solve starting now under `limit` bytes.
    pub fn start(limit: u64) -> Budget {
        Budget {
            limit,
            base: current_rss_bytes().unwrap_or(0),
        }
    }

    /// Bytes the solve may allocate (the limit less the resident memory at the start).
    pub fn available(&self) -> u64 {
        self.limit.saturating_sub(self.base)
    }

    /// True when an estimate of `bytes` fits, with the slack estimates need (see
    /// `SLACK_DIVISOR`).
    pub fn fits(&self, bytes: u64) -> bool {
        with_slack(bytes) <= self.available()
    }

    /// Bytes left for optional arrays (pair cache, acceleration history) once `committed`
    /// bytes are estimated: the most `x` for which `committed + x` still [`Budget::fits`], the
    /// slack of `x` included.
    pub fn spare(&self, committed: u64) -> u64 {
        let most =
            self.available().saturating_sub(SLACK_BYTES) / (SLACK_DIVISOR + 1) * SLACK_DIVISOR;
        most.saturating_sub(committed)
    }

    /// The one-line error for `what` whose estimate reached `bytes` (slack not included; a
    /// refinement stopped early counts what it had recorded) and does not fit, with `advice`
    /// (what to change) at the end.
    pub fn does_not_fit(&self, what: &str, bytes: u64, advice: &str) -> Error {
        let fmt = crate::memory::format_bytes;
        let used = if self.base > 0 {
            format!(" beside the {} the process already holds", fmt(self.base))
        } else {
            String::new()
        };
        Error::Memory(format!(
            "does not fit the memory limit of {} (SolverOptions::memory_limit_bytes): {what} reached an estimated {}{used}; {advice}",
            fmt(self.limit),
            fmt(with_slack(bytes)),
        ))
    }
}

/// An estimate with its slack (see `SLACK_DIVISOR`).
pub(crate) fn with_slack(bytes: u64) -> u64 {
    bytes
        .saturating_add(bytes / SLACK_DIVISOR)
        .saturating_add(SLACK_BYTES)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_kernel_format() {
        let text =
            "Name:\tantiradiance\nVmPeak:\t  300000 kB\nVmHWM:\t    2048 kB\nVmRSS:\t    1024 kB\n";
        assert_eq!(parse_status_field(text, "VmHWM"), Some(2048 * 1024));
        assert_eq!(parse_status_field(text, "VmRSS"), Some(1024 * 1024));
        assert_eq!(parse_status_field(text, "VmSwap"), None);
        assert_eq!(parse_status_field("VmHWM: x kB\n", "VmHWM"), None);
        let meminfo = "MemTotal:       24576000 kB\nMemFree:         1000 kB\n";
        assert_eq!(
            parse_status_field(meminfo, "MemTotal"),
            Some(24576000 * 1024)
        );
    }

    /// What `spare` leaves fits with its own slack, and a byte more than it would not (within
    /// the rounding of the slack's division).
    #[test]
    fn the_spare_fits_with_its_slack() {
        for (limit, base, committed) in [
            (2u64 << 30, 22 << 20, 1_500_000_000u64),
            (85_233_356, 0, 39_445_627),
            (1 << 40, 1 << 20, 0),
            (100 << 20, 0, 90 << 20),
        ] {
            let budget = Budget { limit, base };
            let spare = budget.spare(committed);
            if budget.fits(committed) {
                assert!(
                    budget.fits(committed + spare),
                    "{limit} {committed} {spare}"
                );
                assert!(
                    !budget.fits(committed + spare + 16),
                    "{limit} {committed} {spare}"
                );
            } else {
                assert_eq!(spare, 0);
            }
        }
    }

    #[test]
    fn reads_own_process_on_linux() {
        if cfg!(target_os = "linux") {
            // Current first: other tests' threads may grow the process in between, and the
            // peak read later is at least any resident size seen before it.
            let now = current_rss_bytes().expect("VmRSS on Linux");
            let peak = peak_rss_bytes().expect("VmHWM on Linux");
            assert!(peak >= now && now > 0, "peak {peak} current {now}");
        } else {
            assert_eq!(peak_rss_bytes(), None);
        }
    }
}
