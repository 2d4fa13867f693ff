//! Process memory figures for reports and the memory budget: peak and current resident set
//! size, and the machine's physical memory.
//!
//! On Linux they come from `/proc/self/status` (`VmHWM` is the peak resident set size, `VmRSS`
//! the current one) and `/proc/meminfo` (`MemTotal`). Elsewhere every function returns `None` /
//! `false`: a report then says the figure is unknown rather than guessing.

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

/// Bytes as a short human figure (MB or GB).
pub fn format_bytes(bytes: u64) -> String {
    let mb = bytes as f64 / (1024.0 * 1024.0);
    if mb >= 1024.0 {
        format!("{:.2} GB", mb / 1024.0)
    } else {
        format!("{mb:.1} MB")
    }
}
