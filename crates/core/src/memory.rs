//! The memory a solve really took, measured by the operating system: on Linux the
//! process's peak resident set (`VmHWM` in `/proc/self/status`), reset before the solve by
//! writing 5 to `/proc/self/clear_refs`. It is the whole process's peak, so work running
//! beside the solve in other threads counts too; elsewhere nothing is measured.

use std::fs;

/// A running measurement of the peak resident memory above a baseline.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PeakMeter {
    baseline: u64,
}

fn status_kib(field: &str) -> Option<u64> {
    let status = fs::read_to_string("/proc/self/status").ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix(field))
        .and_then(|rest| rest.trim().trim_end_matches("kB").trim().parse().ok())
}

impl PeakMeter {
    /// Resets the process's peak to its current resident set and starts measuring from
    /// there; `None` where the system cannot (not Linux, no `/proc`).
    pub fn start() -> Option<Self> {
        fs::write("/proc/self/clear_refs", "5").ok()?;
        Some(Self {
            baseline: status_kib("VmRSS:")? * 1024,
        })
    }

    /// Bytes of resident memory at the peak since [`PeakMeter::start`], above what was
    /// resident then.
    pub fn peak_bytes(&self) -> Option<u64> {
        Some((status_kib("VmHWM:")? * 1024).saturating_sub(self.baseline))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_large_allocation_shows_in_the_peak() {
        let Some(meter) = PeakMeter::start() else {
            return; // Not Linux: nothing to measure.
        };
        let block = vec![1u8; 64 << 20];
        std::hint::black_box(&block);
        let peak = meter.peak_bytes().unwrap();
        // Other tests run in this process at the same time, so only a lower bound holds.
        assert!(peak >= 60 << 20, "{peak}");
    }
}
