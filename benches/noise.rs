//! Noise benchmarks (issue 5): `noise(point)` and 6-octave turbulence over 64×64 grids.
//! Throughput is reported in elements (noise evaluations / turbulence lookups) per second of
//! wall time by criterion, and afterwards per CPU-second of this thread (read from
//! /proc/thread-self/schedstat, Linux), which is the per-core rate even on a busy machine.

use criterion::{black_box, criterion_group, Criterion, Throughput};
use glam::Vec3;

use arbor::pattern::{noise3, noise3_slice, turbulence3_slice, vnoise3_slice, Octaves};

/// A 64×64 grid of points on a slanted plane, spanning ~12 noise cells per side.
fn grid() -> Vec<Vec3> {
    let mut p = Vec::with_capacity(64 * 64);
    for j in 0..64 {
        for i in 0..64 {
            let (u, v) = (i as f32 * 0.19 + 0.013, j as f32 * 0.17 - 3.7);
            p.push(Vec3::new(u, v, 0.31 * u - 0.23 * v + 5.5));
        }
    }
    p
}

fn bench(c: &mut Criterion) {
    let pts = grid();
    let mut out = vec![0.0f32; pts.len()];
    let mut vout = vec![Vec3::ZERO; pts.len()];
    let fw = vec![0.0f32; pts.len()];
    let oct = Octaves::new(6.0, 2.0, 0.5);

    let mut g = c.benchmark_group("noise_64x64");
    g.throughput(Throughput::Elements(pts.len() as u64));
    g.bench_function("noise3_slice", |b| {
        b.iter(|| noise3_slice(black_box(&pts), &mut out))
    });
    g.bench_function("noise3_scalar", |b| {
        b.iter(|| {
            let mut s = 0.0f32;
            for &p in black_box(&pts) {
                s += noise3(p);
            }
            s
        })
    });
    g.bench_function("vnoise3_slice", |b| {
        b.iter(|| vnoise3_slice(black_box(&pts), &mut vout))
    });
    g.bench_function("turbulence3_6oct_slice", |b| {
        b.iter(|| turbulence3_slice(black_box(&pts), &fw, &oct, &mut out))
    });
    g.finish();
}

/// CPU time consumed by this thread so far, in nanoseconds (None off Linux).
fn thread_cpu_ns() -> Option<u64> {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// Run `f` (which evaluates `per_call` elements) for about one CPU-second; print the rate.
fn cpu_rate(name: &str, per_call: usize, mut f: impl FnMut()) {
    let Some(start) = thread_cpu_ns() else {
        println!("{name}: per-CPU-second rate unavailable (no /proc/thread-self/schedstat)");
        return;
    };
    let mut calls = 0u64;
    let mut now = start;
    while now - start < 1_000_000_000 {
        for _ in 0..50 {
            f();
        }
        calls += 50;
        now = thread_cpu_ns().unwrap_or(u64::MAX / 2);
    }
    let secs = (now - start) as f64 * 1e-9;
    println!(
        "{name}: {:.1} million elements per CPU-second ({calls} calls of {per_call})",
        calls as f64 * per_call as f64 / secs * 1e-6
    );
}

fn cpu_time_report() {
    let pts = grid();
    let mut out = vec![0.0f32; pts.len()];
    let fw = vec![0.0f32; pts.len()];
    let oct = Octaves::new(6.0, 2.0, 0.5);
    cpu_rate("noise3_slice 64x64", pts.len(), || {
        noise3_slice(black_box(&pts), &mut out)
    });
    let mut sink = 0.0f32;
    cpu_rate("noise3 scalar 64x64", pts.len(), || {
        for &p in black_box(&pts) {
            sink += noise3(p);
        }
    });
    black_box(sink);
    cpu_rate("turbulence3_slice 6 octaves 64x64", pts.len(), || {
        turbulence3_slice(black_box(&pts), &fw, &oct, &mut out)
    });
}

criterion_group!(benches, bench);

fn main() {
    benches();
    Criterion::default().configure_from_args().final_summary();
    cpu_time_report();
}
