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

/// A counter written by every render thread, alone in its cache lines: counters next to
/// each other would make each thread's increments evict the line the other thread is
/// writing (false sharing), a cost paid per grid and per bucket. 128 bytes, since x86
/// fetches lines in adjacent pairs. Used as an `AtomicU64` (it dereferences to one).
#[derive(Debug, Default)]
#[repr(align(128))]
pub struct Counter(AtomicU64);

impl std::ops::Deref for Counter {
    type Target = AtomicU64;
    fn deref(&self) -> &AtomicU64 {
        &self.0
    }
}

#[derive(Debug, Default)]
pub struct Stats {
    pub primitives: AtomicU64,
    pub surfaces: AtomicU64,
    pub culled: Counter,
    pub splits: Counter,
    /// Grids diced, and their micropolygons.
    pub grids: Counter,
    pub micropolygons: Counter,
    /// Points surface-shaded (grids are shaded only when a bucket may see them).
    pub shaded_points: Counter,
    /// Grids diced but never surface-shaded: every bucket they overlap culled them before
    /// shading (behind every opaque sample).
    pub grids_unshaded: Counter,
    pub samples_tested: Counter,
    pub samples_hit: Counter,
    /// Grids a bucket skipped whole: behind every sample's opaque front.
    pub grids_occluded: Counter,
    /// Times a bucket asked for a grid another thread was shading, and the nanoseconds
    /// buckets then waited with no other work to do meanwhile (see `driver::LazyGrid`).
    pub grid_waits: Counter,
    pub grid_wait_ns: Counter,
    pub buckets: Counter,
    /// Nanoseconds per [`Stage`].
    pub stage_ns: [Counter; 5],
    /// Wall-clock time of the whole frame.
    pub wall_ns: AtomicU64,
    /// Bytes held now / at most by the film, shaded grids and sample buffers.
    pub live_bytes: Counter,
    pub peak_bytes: Counter,
    /// Render threads, for the idle time of the [`Phase`]s (the output phase has one).
    pub threads: AtomicU64,
    /// Per [`Phase`]: wall-clock nanoseconds, and the nanoseconds the process's threads
    /// ran and waited for a CPU in it (summed over threads; see [`PhaseClock`]).
    pub phase_wall: [AtomicU64; PHASES],
    pub phase_run: [AtomicU64; PHASES],
    pub phase_wait: [AtomicU64; PHASES],
    /// Per render thread: nanoseconds it ran and waited for a CPU during the frame (an
    /// uneven split is work one thread did alone; see [`ThreadClock`]).
    pub thread_times: std::sync::Mutex<Vec<[u64; 2]>>,
}

/// The parts of a frame's wall time, in order, for `--stats`: how busy the threads were in
/// each (what one thread does alone shows as idle time of the others).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Frame set-up and placing the surfaces in their first bucket rows.
    Setup = 0,
    /// The film's allocation alongside the first bucket row's surfaces.
    FirstRow = 1,
    /// Every bucket row after the first row's surfaces: making rows, hiding buckets,
    /// filtering tiles and putting finished rows into the film, overlapped without a barrier
    /// between rows (`driver::Flow`).
    Rows = 2,
    /// What is left of the film's rows after the rows' dataflow (nothing, normally).
    Filter = 3,
    /// The end of the frame.
    Other = 4,
    /// Imager, quantising and writing the displays (after the render; the thread that
    /// writes).
    Output = 5,
}

const PHASES: usize = 6;
const PHASE_NAMES: [&str; PHASES] = [
    "set-up",
    "first row",
    "hide rows",
    "filter rows",
    "other",
    "output",
];

/// The start of a [`Phase`]: the wall clock and the CPU time so far of the threads doing
/// the phase's work (Linux `/proc/self/task/TID/schedstat`: time run and time waiting for a
/// CPU — the waiting shows how much other processes took). Reading it costs a few system
/// calls per thread, so the driver makes one only under `--stats`.
#[derive(Clone, Debug)]
pub struct PhaseClock {
    wall: Instant,
    tids: std::sync::Arc<Vec<u32>>,
    run: u64,
    wait: u64,
}

impl PhaseClock {
    /// Now, for the threads `tids` (see [`pool_threads`], [`this_thread`]).
    pub fn now(tids: std::sync::Arc<Vec<u32>>) -> PhaseClock {
        let (run, wait) = sched_times(&tids);
        PhaseClock {
            wall: Instant::now(),
            tids,
            run,
            wait,
        }
    }
    /// The threads this clock times.
    pub fn tids(&self) -> std::sync::Arc<Vec<u32>> {
        self.tids.clone()
    }
}

/// The CPU time of each render thread since the start of a frame (`--stats` only).
#[derive(Clone, Debug)]
pub struct ThreadClock {
    tids: std::sync::Arc<Vec<u32>>,
    start: Vec<[u64; 2]>,
}

impl ThreadClock {
    pub fn now(tids: std::sync::Arc<Vec<u32>>) -> ThreadClock {
        let start = tids.iter().map(|t| sched_time(*t)).collect();
        ThreadClock { tids, start }
    }
    /// Stores each thread's time run and waited since [`ThreadClock::now`] in `stats`.
    pub fn stop(&self, stats: &Stats) {
        let times = self
            .tids
            .iter()
            .zip(&self.start)
            .map(|(t, s)| {
                let n = sched_time(*t);
                [n[0].saturating_sub(s[0]), n[1].saturating_sub(s[1])]
            })
            .collect();
        if let Ok(mut v) = stats.thread_times.lock() {
            *v = times;
        }
    }
}

/// The calling thread's id (None where `/proc/thread-self` does not exist).
pub fn this_thread() -> Option<u32> {
    let link = std::fs::read_link("/proc/thread-self").ok()?;
    link.file_name()?.to_str()?.parse().ok()
}

/// The ids of the current rayon pool's threads (one call on each).
pub fn pool_threads() -> Vec<u32> {
    let mut tids: Vec<u32> = rayon::broadcast(|_| this_thread())
        .into_iter()
        .flatten()
        .collect();
    tids.sort_unstable();
    tids
}

/// Nanoseconds run and waited for a CPU by the threads `tids` (a thread that has ended
/// counts nothing).
fn sched_times(tids: &[u32]) -> (u64, u64) {
    tids.iter()
        .map(|t| sched_time(*t))
        .fold((0, 0), |(r, w), [a, b]| (r + a, w + b))
}

/// Nanoseconds run and waited for a CPU by thread `tid` (zeros where unknown).
fn sched_time(tid: u32) -> [u64; 2] {
    let Ok(text) = std::fs::read_to_string(format!("/proc/self/task/{tid}/schedstat")) else {
        return [0, 0];
    };
    let mut f = text
        .split_whitespace()
        .map(|v| v.parse::<u64>().unwrap_or(0));
    [f.next().unwrap_or(0), f.next().unwrap_or(0)]
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
    pub fn add_time(&self, stage: Stage, ns: u64) {
        self.stage_ns[stage as usize].fetch_add(ns, Relaxed);
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
    /// Ends `phase` begun at `since` (when timing phases at all) and returns the clock
    /// that starts the next one.
    pub fn phase(&self, phase: Phase, since: Option<PhaseClock>) -> Option<PhaseClock> {
        let since = since?;
        let now = PhaseClock::now(since.tids.clone());
        let i = phase as usize;
        let wall = now.wall.duration_since(since.wall).as_nanos() as u64;
        self.phase_wall[i].fetch_add(wall, Relaxed);
        self.phase_run[i].fetch_add(now.run.saturating_sub(since.run), Relaxed);
        self.phase_wait[i].fetch_add(now.wait.saturating_sub(since.wait), Relaxed);
        Some(now)
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
        writeln!(f, "  grids unshaded   {:>12}", g(&self.grids_unshaded))?;
        writeln!(
            f,
            "  grid waits       {:>12} ({:.3} s idle: no other work meanwhile)",
            g(&self.grid_waits),
            g(&self.grid_wait_ns) as f64 * 1e-9
        )?;
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
        )?;
        let times = self
            .thread_times
            .lock()
            .map(|v| v.clone())
            .unwrap_or_default();
        if !times.is_empty() {
            let list = |k: usize| {
                times
                    .iter()
                    .map(|t| format!("{:.3}", t[k] as f64 * 1e-9))
                    .collect::<Vec<_>>()
                    .join(" ")
            };
            write!(
                f,
                "\n  render threads   run {} s, waiting for a CPU {} s",
                list(0),
                list(1)
            )?;
        }
        let threads = g(&self.threads);
        if threads > 0 && self.phase_wall.iter().any(|w| g(w) > 0) {
            write!(
                f,
                "\n  phases ({threads} threads; CPU-seconds run, waiting for a CPU, idle of threads × wall)"
            )?;
            let sec = |ns: u64| ns as f64 * 1e-9;
            for (i, name) in PHASE_NAMES.iter().enumerate() {
                let (w, r, q) = (
                    g(&self.phase_wall[i]),
                    g(&self.phase_run[i]),
                    g(&self.phase_wait[i]),
                );
                let n = if i == Phase::Output as usize {
                    1
                } else {
                    threads
                };
                let idle = (n * w).saturating_sub(r + q);
                write!(
                    f,
                    "\n    {name:<11} wall {:>7.3} s  run {:>7.3}  wait {:>7.3}  idle {:>7.3}",
                    sec(w),
                    sec(r),
                    sec(q),
                    sec(idle)
                )?;
            }
        }
        Ok(())
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
        *s.thread_times.lock().unwrap() = vec![[1_250_000_000, 10_000_000], [500_000_000, 0]];
        let text = s.to_string();
        assert!(text.contains("grids"));
        assert!(text
            .lines()
            .any(|l| l.contains("grids") && l.trim_end().ends_with('3')));
        assert!(text
            .lines()
            .any(|l| l.trim()
                == "render threads   run 1.250 0.500 s, waiting for a CPU 0.010 0.000 s"));
    }
}
