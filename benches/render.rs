//! Whole renders: the showcase scene at 640×480 with one thread and with every core.
//! The ratio of the two is the parallel scaling (target ≥ 1.8× on 2 cores).

use criterion::{criterion_group, criterion_main, Criterion};

use arbor::diag::{Diagnostics, SourceMap};
use arbor::pipeline::{render_text, Settings};

fn bench(c: &mut Criterion) {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/showcase.rib"
    ))
    .expect("examples/showcase.rib");
    let cores = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1);
    let mut group = c.benchmark_group("showcase_640x480");
    group.sample_size(10);
    for threads in [1, cores] {
        let settings = Settings {
            resolution: Some((640, 480)),
            threads,
            ..Settings::default()
        };
        group.bench_function(format!("{threads}_threads"), |b| {
            b.iter(|| {
                let (sources, diags) = (SourceMap::new(), Diagnostics::new());
                render_text(&text, &settings, &sources, &diags)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
