//! Parse throughput of a generated ~50 MB RIB, mostly `PointsPolygons` number arrays
//! (`cargo bench --bench rib_parse -- --sample-size 10`).

use std::fmt::Write;
use std::time::Duration;

use arbor::diag::{Diagnostics, SourceMap};
use arbor::rib::parse_bytes;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

/// Deterministic scene text of about `target` bytes: a Companion-style header, then meshes
/// of 2000 quads each (nverts, vertex indices, "P" and "st" arrays), with small requests
/// between them.
fn generate(target: usize) -> String {
    let mut s = String::with_capacity(target + (1 << 20));
    s.push_str("##RenderMan RIB-Structure 1.1\nversion 3.03\nFormat 640 480 1\n");
    s.push_str("Projection \"perspective\" \"fov\" [40]\nWorldBegin\n");
    let mut seed: u64 = 0x2545F4914F6CDD1D;
    let mut rnd = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut mesh = 0;
    while s.len() < target {
        let quads = 2000;
        let nv = quads + 1 + 1;
        let _ = writeln!(
            s,
            "AttributeBegin\nAttribute \"identifier\" \"name\" [\"mesh{mesh}\"]"
        );
        let _ = writeln!(
            s,
            "Surface \"plastic\" \"uniform float Kd\" [0.8] \"Ks\" .5"
        );
        s.push_str("PointsPolygons [");
        for _ in 0..quads {
            s.push_str("4 ");
        }
        s.push_str("]\n [");
        for q in 0..quads {
            let _ = write!(s, "{} {} {} {} ", q, q + 1, q + nv + 1, q + nv);
        }
        s.push_str("]\n \"P\" [");
        for _ in 0..2 * nv {
            let _ = write!(
                s,
                "{:.6} {:.6} {:.6}\n",
                rnd() * 20.0 - 10.0,
                rnd() * 20.0 - 10.0,
                rnd() * 20.0 - 10.0
            );
        }
        s.push_str("] \"st\" [");
        for _ in 0..2 * nv {
            let _ = write!(s, "{:.4} {:.4} ", rnd(), rnd());
        }
        s.push_str("]\nAttributeEnd\n");
        mesh += 1;
    }
    s.push_str("WorldEnd\n");
    s
}

fn bench(c: &mut Criterion) {
    let text = generate(50 << 20);
    let mut g = c.benchmark_group("rib_parse");
    g.throughput(Throughput::Bytes(text.len() as u64));
    g.sample_size(10);
    g.measurement_time(Duration::from_secs(10));
    g.bench_function("points_polygons_50mb", |b| {
        b.iter(|| {
            let sm = SourceMap::new();
            let d = Diagnostics::new();
            let r = parse_bytes("bench.rib", text.as_bytes(), &sm, &d);
            assert!(!d.has_errors());
            r.len()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
