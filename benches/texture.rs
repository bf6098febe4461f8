//! Texture lookups per second: a 512×512 checker texture read over a 64×64 grid of
//! footprints, with the trilinear ("box"), the EWA ("gaussian") and the summed-area-table
//! ("sat") filters.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};

use arbor::diag::Diagnostics;
use arbor::shade::exec::{TextureLookup, TextureParams};
use arbor::texture::make::{make_texture, MakeOptions};
use arbor::texture::TextureSystem;

fn bench(c: &mut Criterion) {
    let dir = std::env::temp_dir().join(format!("arbor-texbench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let png = dir.join("checker.png");
    let img = image::RgbImage::from_fn(512, 512, |x, y| {
        if ((x / 32) + (y / 32)) % 2 == 0 {
            image::Rgb([230, 230, 230])
        } else {
            image::Rgb([20, 20, 20])
        }
    });
    img.save(&png).unwrap();
    let tex = dir.join("checker.tex");
    make_texture(&png, &tex, &MakeOptions::default()).unwrap();
    let diags = Diagnostics::new();
    let system = TextureSystem::new(vec![dir.clone()], 64 * 1024, &diags);
    let name = tex.display().to_string();
    // A receding plane: footprints grow and stretch with distance (oblique views).
    let n = 64usize;
    let st: Vec<[f32; 8]> = (0..n * n)
        .map(|k| {
            let (i, j) = ((k % n) as f32 / n as f32, (k / n) as f32 / n as f32);
            let depth = 1.0 + 8.0 * j;
            let (s, t) = (i * depth, depth * 2.0);
            let (ds, dt) = (0.02 * depth, 0.08 * depth);
            [s, t, s + ds, t, s, t + dt, s + ds, t + dt]
        })
        .collect();
    let mut out = vec![0f32; n * n * 3];
    let mut group = c.benchmark_group("texture_lookups");
    group.throughput(Throughput::Elements((n * n) as u64));
    for (filter, label) in [("box", "trilinear"), ("gaussian", "ewa"), ("sat", "sat")] {
        // Widths 1 as the shading language passes them (0 would collapse every footprint).
        let params = TextureParams {
            filter: filter.to_string(),
            swidth: 1.0,
            twidth: 1.0,
            ..TextureParams::default()
        };
        // The summed-area table is built on the first lookup: not part of the rate.
        system.texture(&name, 0, 3, &st, &params, &mut out);
        group.bench_function(label, |b| {
            b.iter(|| system.texture(&name, 0, 3, &st, &params, &mut out))
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
