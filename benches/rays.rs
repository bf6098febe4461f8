//! Ray throughput: incoherent rays through a scene of about a million ray micropolygons
//! (a 32 × 32 field of spheres under a matte shader and a distant light), each hit shaded
//! by its surface shader in batches, on one thread. Reports rays per second.
//!
//! `ARBOR_RAYS_ITERS=N` runs N batches without criterion (for callgrind or `perf`), reporting
//! rays per second of wall time and of this thread's CPU time (the machine may be shared).
//! `ARBOR_RAYS_FIELD=K` makes the field K × K spheres (default 32: about 1.06 M micropolygons;
//! 16: 0.30 M). `ARBOR_RAYS_SHADOW=1` times shadow rays instead (`transmission` along
//! segments K long from the same origins in the same directions: any-hit walks that stop at
//! the first opaque blocker, no shading).

use criterion::{criterion_group, Criterion, Throughput};
use glam::Vec3;

use arbor::diag::{Diagnostics, SourceMap};
use arbor::render::Camera;
use arbor::scene::{build_scenes, BuildContext, Scene};
use arbor::shade::exec::RayTracer;
use arbor::shade::rays::Tracer;
use arbor::shade::system::ShadeSystem;
use arbor::sl::{CompileOptions, ShaderLibrary};

fn field() -> usize {
    std::env::var("ARBOR_RAYS_FIELD")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
        .filter(|k| (1..=256).contains(k))
        .unwrap_or(32)
}

/// This thread's CPU time in seconds (Linux: /proc/thread-self/schedstat), if readable.
fn thread_cpu() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: f64 = s.split_whitespace().next()?.parse().ok()?;
    Some(ns * 1e-9)
}

fn scene_rib() -> String {
    let mut s = String::from(
        "Format 640 480 1\nProjection \"perspective\" \"fov\" [50]\nTranslate 0 0 20\n\
         WorldBegin\nLightSource \"distantlight\" 1 \"from\" [1 1 -1] \"to\" [0 0 0]\n\
         Surface \"matte\"\nShadingRate 0.02\n",
    );
    let k = field();
    let half = k as f32 / 2.0 - 0.5;
    for j in 0..k {
        for i in 0..k {
            s.push_str(&format!(
                "AttributeBegin\nTranslate {} {} {}\nSphere 0.45 -0.45 0.45 360\nAttributeEnd\n",
                i as f32 - half,
                j as f32 - half,
                ((i * 7 + j * 3) % 5) as f32
            ));
        }
    }
    s.push_str("WorldEnd\n");
    s
}

struct Rig {
    sources: SourceMap,
    diags: Diagnostics,
    scene: Scene,
    library: ShaderLibrary,
}

fn rig() -> Rig {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let rib = scene_rib();
    let reqs = arbor::rib::parse_bytes("<bench>", rib.as_bytes(), &sources, &diags);
    let ctx = BuildContext::new(&sources, &diags);
    let scene = build_scenes(reqs, &ctx).remove(0);
    let library = ShaderLibrary::new(CompileOptions::default());
    Rig {
        sources,
        diags,
        scene,
        library,
    }
}

/// A batch of incoherent rays: origins scattered through the field, directions uniform.
fn rays(count: usize, seed: u32) -> (Vec<Vec3>, Vec<Vec3>) {
    let half = field() as f32 / 2.0;
    let mut h = seed;
    let mut rnd = || {
        h = arbor::pattern::hash::hash_u32(h.wrapping_add(0x9e37_79b9));
        arbor::ray::unit(h) * 2.0 - 1.0
    };
    let mut o = Vec::with_capacity(count);
    let mut d = Vec::with_capacity(count);
    for _ in 0..count {
        // Camera space: the field spans x, y in [−K/2, K/2] around z = 20…24.
        o.push(Vec3::new(rnd() * half, rnd() * half, 22.0 + rnd() * 3.0));
        d.push(Vec3::new(rnd(), rnd(), rnd()).normalize_or(Vec3::Z));
    }
    (o, d)
}

const BATCH: usize = 4096;

fn bench(c: &mut Criterion) {
    let r = rig();
    let camera = Camera::new(&r.scene);
    let sys = ShadeSystem {
        library: &r.library,
        sources: &r.sources,
        diags: &r.diags,
        textures: None,
        aovs: vec![],
        rays: Default::default(),
    };
    let tracer = Tracer {
        sys: &sys,
        scene: &r.scene,
        camera: &camera,
        depth: 0,
        skip_light: None,
    };
    let t0 = std::time::Instant::now();
    let rs = tracer.geometry().expect("ray geometry");
    eprintln!(
        "ray geometry: {} micropolygons in {} grids, built in {:.2} s; tree {:.1} MB",
        rs.micropolygons,
        rs.grids.len(),
        t0.elapsed().as_secs_f64(),
        rs.bvh.bytes() as f64 / (1 << 20) as f64
    );
    let active = vec![true; BATCH];
    let mut ci = vec![Vec3::ZERO; BATCH];
    let mut dist = vec![0f32; BATCH];
    let batches: Vec<(Vec<Vec3>, Vec<Vec3>)> = (0..16).map(|k| rays(BATCH, k)).collect();
    let hits = {
        tracer.trace(
            &batches[0].0,
            &batches[0].1,
            &[],
            &active,
            &mut ci,
            &mut dist,
        );
        dist.iter().filter(|d| d.is_finite()).count()
    };
    eprintln!("hit fraction: {:.2}", hits as f64 / BATCH as f64);
    // What the walks of one batch do (counted apart from the timed runs), from the origins
    // at the bias `trace` steps off (the directions are unit).
    let mut st = arbor::ray::bvh::WalkStats::default();
    let mut found = vec![None; BATCH];
    let tmin = vec![arbor::shade::rays::bias(&r.scene); BATCH];
    rs.bvh.closest_many_counted(
        &batches[0].0,
        &batches[0].1,
        &tmin,
        f32::INFINITY,
        &mut found,
        &mut st,
    );
    let per = |x: u64| x as f64 / st.rays.max(1) as f64;
    eprintln!(
        "per ray: {:.1} nodes, {:.2} leaves ({:.1} quads, {:.0} bytes), {:.1} pushed, {:.1} \
         skipped",
        per(st.nodes),
        per(st.leaves),
        per(st.quads),
        per(st.leaf_bytes),
        per(st.pushes),
        per(st.skipped)
    );
    // Shadow segments: from each origin K along its direction (across the field).
    let reach = field() as f32;
    let ends: Vec<Vec<Vec3>> = batches
        .iter()
        .map(|(o, d)| o.iter().zip(d).map(|(o, d)| *o + *d * reach).collect())
        .collect();
    let mut trans = vec![Vec3::ONE; BATCH];
    tracer.transmission(&batches[0].0, &ends[0], &active, &mut trans);
    eprintln!(
        "shadow segments blocked: {:.2}",
        trans.iter().filter(|t| t.max_element() == 0.0).count() as f64 / BATCH as f64
    );
    let shadow = std::env::var("ARBOR_RAYS_SHADOW").is_ok_and(|v| v == "1");
    if let Some(n) = std::env::var("ARBOR_RAYS_ITERS")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
    {
        let t = std::time::Instant::now();
        let c0 = thread_cpu();
        for k in 0..n {
            let (o, d) = &batches[k % batches.len()];
            if shadow {
                tracer.transmission(o, &ends[k % batches.len()], &active, &mut trans);
            } else {
                tracer.trace(o, d, &[], &active, &mut ci, &mut dist);
            }
        }
        let s = t.elapsed().as_secs_f64();
        let cpu = thread_cpu().zip(c0).map(|(b, a)| b - a);
        let rays = (n * BATCH) as f64;
        eprintln!(
            "{} {}rays in {:.3} s: {:.2} M rays/s wall{}",
            n * BATCH,
            if shadow { "shadow " } else { "" },
            s,
            rays / s / 1e6,
            cpu.map(|c| format!(", {:.2} M rays/s of CPU time ({c:.3} s)", rays / c / 1e6))
                .unwrap_or_default()
        );
        return;
    }
    let mut g = c.benchmark_group("rays");
    g.throughput(Throughput::Elements(BATCH as u64));
    g.sample_size(20);
    let mut k = 0;
    g.bench_function("incoherent_shaded", |b| {
        b.iter(|| {
            let (o, d) = &batches[k % batches.len()];
            k += 1;
            tracer.trace(o, d, &[], &active, &mut ci, &mut dist);
        })
    });
    let mut k = 0;
    g.bench_function("incoherent_shadow", |b| {
        b.iter(|| {
            let j = k % batches.len();
            k += 1;
            tracer.transmission(&batches[j].0, &ends[j], &active, &mut trans);
        })
    });
    g.finish();
}

criterion_group!(benches, bench);

fn main() {
    // One thread: the figure is rays per second per core.
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build_global()
        .ok();
    benches();
    Criterion::default().configure_from_args().final_summary();
}
