//! Noise benchmarks (issue 5): `noise(point)` and 6-octave turbulence over 64×64 grids.
//! Throughput is reported in elements (noise evaluations / turbulence lookups) per second.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
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

criterion_group!(benches, bench);
criterion_main!(benches);
