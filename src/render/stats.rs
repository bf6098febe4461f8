//! Render statistics for `--stats`: counters and stage times shared by every worker thread.
//!
//! Input: increments from the driver, dicer and hider (batched per grid or bucket, so the
//! atomics are not contended in hot loops). Output: an `impl Display` report.
//! Invariants: counters only grow; stage times are summed over threads (CPU time, not wall).

use std::fmt;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::time::{Duration, Instant};

/// The pipeline stages that are timed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Bounding, culling, split/dice decisions and dicing.
    Dice = 0,
    Displace = 1,
    Shade = 2,
    /// Sampling micropolygons and resolving visible-point lists.
    Hide = 3,
    Filter = 4,
}

const STAGE_NAMES: [&str; 5] = ["dice", "displace", "shade", "hide", "filter"];

#[derive(Debug, Default)]
pub struct Stats {
    pub primitives: AtomicU64,
    pub surfaces: AtomicU64,
    pub culled: AtomicU64,
    pub splits: AtomicU64,
    pub grids: AtomicU64,
    pub micropolygons: AtomicU64,
    pub shaded_points: AtomicU64,
    pub samples_tested: AtomicU64,
    pub samples_hit: AtomicU64,
    /// Grids a bucket skipped whole: behind every sample's opaque front.
    pub grids_occluded: AtomicU64,
    pub buckets: AtomicU64,
    /// Nanoseconds per [`Stage`].
    pub stage_ns: [AtomicU64; 5],
    /// Wall-clock time of the whole frame.
    pub wall_ns: AtomicU64,
    /// Bytes held now / at most by the film, shaded grids and sample buffers.
    pub live_bytes: AtomicU64,
    pub peak_bytes: AtomicU64,
}

impl Stats {
    pub fn new() -> Stats {
        Stats::default()
    }
    pub fn add(counter: &AtomicU64, n: u64) {
        counter.fetch_add(n, Relaxed);
    }
    pub fn time(&self, stage: Stage, since: Instant) {
        self.stage_ns[stage as usize].fetch_add(since.elapsed().as_nanos() as u64, Relaxed);
    }
    pub fn stage_time(&self, stage: Stage) -> Duration {
        Duration::from_nanos(self.stage_ns[stage as usize].load(Relaxed))
    }
    pub fn alloc(&self, bytes: usize) {
        let now = self.live_bytes.fetch_add(bytes as u64, Relaxed) + bytes as u64;
        self.peak_bytes.fetch_max(now, Relaxed);
    }
    pub fn free(&self, bytes: usize) {
        self.live_bytes.fetch_sub(bytes as u64, Relaxed);
    }
    pub fn get(counter: &AtomicU64) -> u64 {
        counter.load(Relaxed)
    }
}

impl fmt::Display for Stats {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let g = |c: &AtomicU64| c.load(Relaxed);
        writeln!(f, "render statistics")?;
        writeln!(f, "  primitives       {:>12}", g(&self.primitives))?;
        writeln!(f, "  surfaces         {:>12}", g(&self.surfaces))?;
        writeln!(f, "  culled           {:>12}", g(&self.culled))?;
        writeln!(f, "  splits           {:>12}", g(&self.splits))?;
        writeln!(f, "  grids            {:>12}", g(&self.grids))?;
        writeln!(f, "  micropolygons    {:>12}", g(&self.micropolygons))?;
        writeln!(f, "  shaded points    {:>12}", g(&self.shaded_points))?;
        writeln!(f, "  samples tested   {:>12}", g(&self.samples_tested))?;
        writeln!(f, "  samples hit      {:>12}", g(&self.samples_hit))?;
        writeln!(f, "  grids occluded   {:>12}", g(&self.grids_occluded))?;
        writeln!(f, "  buckets          {:>12}", g(&self.buckets))?;
        writeln!(
            f,
            "  peak memory      {:>9.1} MiB (renderer: film, shaded grids and sample buffers)",
            g(&self.peak_bytes) as f64 / (1024.0 * 1024.0)
        )?;
        if let Some(rss) = peak_rss() {
            writeln!(
                f,
                "  peak resident    {:>9.1} MiB (whole process so far: scene, source text, film, buffers; VmHWM)",
                rss as f64 / (1024.0 * 1024.0)
            )?;
        }
        writeln!(f, "  time (summed over threads)")?;
        for (i, name) in STAGE_NAMES.iter().enumerate() {
            let s = self.stage_ns[i].load(Relaxed) as f64 * 1e-9;
            writeln!(f, "    {name:<10} {s:>10.3} s")?;
        }
        write!(
            f,
            "  wall time        {:>10.3} s",
            g(&self.wall_ns) as f64 * 1e-9
        )
    }
}

/// The process's peak resident set size in bytes (`VmHWM`), where the system reports it.
pub fn peak_rss() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peak_tracks_the_maximum_live_bytes() {
        let s = Stats::new();
        s.alloc(100);
        s.alloc(50);
        s.free(120);
        s.alloc(10);
        assert_eq!(Stats::get(&s.live_bytes), 40);
        assert_eq!(Stats::get(&s.peak_bytes), 150);
        Stats::add(&s.grids, 3);
        let text = s.to_string();
        assert!(text.contains("grids"));
        assert!(text
            .lines()
            .any(|l| l.contains("grids") && l.trim_end().ends_with('3')));
    }
}
