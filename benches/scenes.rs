//! One benchmark per scene shape (issue 14), each also a plain RIB under `examples/bench/`:
//! the three-primitive hiding-bound scene, the full-frame fBm marble (shading-bound), many
//! small polygons (geometry-bound, generated here like `examples/bench/gen_polys.py`) and a
//! camera pan (motion-blur hiding). Run at
//! reduced resolutions so `cargo bench --bench scenes` takes about a minute; the full-size
//! numbers come from `arbor render --stats --threads 2 examples/bench/<scene>.rib`.

use std::fmt::Write as _;

use criterion::{criterion_group, criterion_main, Criterion};

use arbor::diag::{Diagnostics, SourceMap};
use arbor::pipeline::{render_text, Settings};

const DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/bench");

/// `n` small quads (each its own Polygon) over an orthographic frame, as gen_polys.py writes.
fn polygons(n: usize) -> String {
    let (xres, yres) = (320usize, 240usize);
    let side = ((n * xres / yres) as f64).sqrt() as usize;
    let rows = n / side;
    let (w, h) = (4.0f64, 3.0f64);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Format {xres} {yres} 1\nPixelSamples 4 4\nPixelFilter \"gaussian\" 2 2\n\
         Projection \"orthographic\"\nScreenWindow -2 2 -1.5 1.5\nTranslate 0 0 5\nWorldBegin\n\
         LightSource \"ambientlight\" 1 \"intensity\" [0.2]\n\
         LightSource \"distantlight\" 2 \"intensity\" [0.8] \"from\" [-1 1 -2] \"to\" [0 0 0]\n\
         Surface \"plastic\""
    );
    let (dx, dy) = (w / side as f64, h / rows as f64);
    for j in 0..rows {
        for i in 0..side {
            let (x0, y0) = (-w / 2.0 + i as f64 * dx, -h / 2.0 + j as f64 * dy);
            let z = 0.3 * (3.1 * x0 + 1.7 * y0).sin();
            let (x1, y1) = (x0 + dx * 1.2, y0 + dy * 1.2);
            let _ = writeln!(
                s,
                "Color [{:.3} {:.3} 0.5]\nPolygon \"P\" [{x0:.5} {y0:.5} {z:.4} {x1:.5} {y0:.5} {z:.4} \
                 {x1:.5} {y1:.5} {z:.4} {x0:.5} {y1:.5} {z:.4}]",
                0.5 + 0.5 * (1.3 * i as f64).sin(),
                0.5 + 0.5 * (0.7 * j as f64).sin()
            );
        }
    }
    s.push_str("WorldEnd\n");
    s
}

fn bench(c: &mut Criterion) {
    let read = |name: &str| {
        std::fs::read_to_string(format!("{DIR}/{name}")).expect("examples/bench scene")
    };
    let scenes = [
        ("hiding_320x240", read("hiding.rib"), Some((320, 240))),
        ("marble_160x120", read("marble.rib"), Some((160, 120))),
        ("polygons_20000", polygons(20_000), None),
        ("motion_160x100", read("motion.rib"), Some((160, 100))),
    ];
    let mut group = c.benchmark_group("scenes");
    group.sample_size(10);
    for (name, text, resolution) in &scenes {
        let settings = Settings {
            resolution: *resolution,
            threads: 1,
            shader_paths: vec![DIR.to_string()],
            ..Settings::default()
        };
        group.bench_function(*name, |b| {
            b.iter(|| {
                let (sources, diags) = (SourceMap::new(), Diagnostics::new());
                render_text(text, &settings, &sources, &diags)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
