//! Shading throughput: `plastic` with an ambient and two distant lights over grids of
//! 16×16, 32×32 and 64×64 points, on one thread. Reports points per second.

use criterion::{criterion_group, BenchmarkId, Criterion, Throughput};
use glam::Vec3;

use arbor::diag::{Diagnostics, SourceMap};
use arbor::render::Camera;
use arbor::scene::{build_scenes, BuildContext};
use arbor::shade::system::ShadeSystem;
use arbor::shade::Grid;
use arbor::sl::{CompileOptions, ShaderLibrary};

const SCENE: &str = r#"
Projection "perspective" "fov" [40]
Translate 0 0 5
WorldBegin
LightSource "ambientlight" 1 "intensity" [0.1]
LightSource "distantlight" 2 "from" [-1 1 -1] "to" [0 0 0]
LightSource "distantlight" 3 "from" [1 1 -1] "to" [0 0 0] "intensity" [0.5]
Surface "plastic" "Ks" [0.6]
Sphere 1 -1 1 360
WorldEnd
"#;

fn grid(n: usize) -> Grid {
    let mut g = Grid::with_size(n, n);
    for j in 0..n {
        for i in 0..n {
            let k = j * n + i;
            let (u, v) = (i as f32 / (n - 1) as f32, j as f32 / (n - 1) as f32);
            let th = u * std::f32::consts::PI;
            let ph = (v - 0.5) * std::f32::consts::PI;
            let nrm = Vec3::new(th.cos() * ph.cos(), ph.sin(), -th.sin() * ph.cos());
            g.p[k] = nrm + Vec3::new(0.0, 0.0, 5.0);
            g.n[k] = nrm;
            g.ng[k] = nrm;
            g.i[k] = g.p[k];
            g.u[k] = u;
            g.v[k] = v;
            g.s[k] = u;
            g.t[k] = v;
            g.dpdu[k] = Vec3::X;
            g.dpdv[k] = Vec3::Y;
        }
    }
    g.du = 1.0 / (n - 1) as f32;
    g.dv = g.du;
    g
}

fn fixed_iterations(iters: usize) {
    let (sources, diags) = (SourceMap::new(), Diagnostics::new());
    let scene = build(&sources, &diags);
    let camera = Camera::new(&scene);
    let lib = ShaderLibrary::new(CompileOptions::default());
    let sys = ShadeSystem {
        library: &lib,
        sources: &sources,
        diags: &diags,
        textures: None,
        aovs: vec![],
        rays: Default::default(),
    };
    let mut g = grid(32);
    for _ in 0..iters {
        sys.shade(&scene, &camera, 0, &mut g);
    }
    println!("{:?}", g.ci[500]);
}

fn build(sources: &SourceMap, diags: &Diagnostics) -> arbor::scene::Scene {
    let reqs = arbor::rib::parse_bytes("bench.rib", SCENE.as_bytes(), sources, diags);
    let ctx = BuildContext {
        sources,
        diags,
        shader_paths: vec![],
        texture_paths: vec![],
        archive_paths: vec![],
        base_dir: None,
        frames: None,
        procedurals: Default::default(),
    };
    build_scenes(reqs, &ctx).remove(0)
}

fn bench(c: &mut Criterion) {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let reqs = arbor::rib::parse_bytes("bench.rib", SCENE.as_bytes(), &sources, &diags);
    let ctx = BuildContext::new(&sources, &diags);
    let scenes = build_scenes(reqs, &ctx);
    let scene = &scenes[0];
    let camera = Camera::new(scene);
    let lib = ShaderLibrary::new(CompileOptions::default());
    let sys = ShadeSystem {
        library: &lib,
        sources: &sources,
        diags: &diags,
        textures: None,
        aovs: vec![],
        rays: Default::default(),
    };
    let mut group = c.benchmark_group("plastic_3_lights");
    for n in [16usize, 32, 64] {
        let mut g0 = grid(n);
        group.throughput(Throughput::Elements((n * n) as u64));
        group.bench_with_input(
            BenchmarkId::from_parameter(format!("{n}x{n}")),
            &n,
            |b, _| b.iter(|| sys.shade(scene, &camera, 0, &mut g0)),
        );
    }
    group.finish();
}

criterion_group!(benches, bench);

/// `ARBOR_SHADE_ITERS=N` runs N shades of a 32×32 grid and exits: a fixed amount of work
/// for instruction counting under callgrind.
fn main() {
    if let Some(n) = std::env::var("ARBOR_SHADE_ITERS")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
    {
        fixed_iterations(n);
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
