//! A heavy volume shader at grid speed: `benches/atmosphere/marchfog.rib`, a ray-marched fog
//! (`marchfog.sl`, `illuminance` at every step) lit by two spotlights over a floor, a wall and
//! a sphere, 320×240 at 2×2 samples, on one thread and on every core. Each march step runs
//! both spotlights once over the whole grid at the step's positions.

use criterion::{criterion_group, criterion_main, Criterion};

use arbor::diag::{Diagnostics, SourceMap};
use arbor::pipeline::{render_text, Settings};

fn bench(c: &mut Criterion) {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/atmosphere");
    let text = std::fs::read_to_string(format!("{dir}/marchfog.rib")).expect("marchfog.rib");
    let cores = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1);
    let mut group = c.benchmark_group("atmosphere_320x240");
    group.sample_size(10);
    for threads in [1, cores] {
        let settings = Settings {
            shader_paths: vec![dir.to_string()],
            threads,
            ..Settings::default()
        };
        group.bench_function(format!("{threads}_threads"), |b| {
            b.iter(|| {
                let (sources, diags) = (SourceMap::new(), Diagnostics::new());
                let films = render_text(&text, &settings, &sources, &diags);
                assert!(!diags.has_errors(), "{}", diags.render_plain(&sources));
                films
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
