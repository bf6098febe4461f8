//! Sparse-lane execution: when few of a grid's points are running (a march whose points leave
//! its loop at different steps), pointwise instructions compute just the running points. The
//! results must be exactly those of computing every point: the same bits in every output, for
//! shaders that take derivatives, index arrays, break, continue and return inside divergent
//! loops, for every built-in, and for whole renders with marching atmospheres and lights.
//! The same holds for compacted loops (a loop whose points are pointwise computations goes on
//! over its running points gathered into a smaller grid once few run).

mod common;

use arbor::diag::{Diagnostics, SourceMap};
use arbor::render::driver::RenderOptions;
use arbor::shade::exec::{Env, Exec, COMPACT_LOOPS, SPARSE_LANES};
use arbor::shade::value::Slot;
use arbor::sl::ir::Program;
use arbor::sl::library::{compile_source, CompileOptions};
use glam::{Mat4, Vec3};

const NU: usize = 24;
const NV: usize = 16;

fn compile(text: &str) -> Program {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let mut progs = compile_source(
        "test.sl",
        text,
        None,
        &sources,
        &diags,
        &CompileOptions::default(),
    );
    assert!(!diags.has_errors(), "{}", diags.render_plain(&sources));
    assert_eq!(progs.len(), 1, "{}", diags.render_plain(&sources));
    progs.remove(0)
}

/// Runs a surface program over an NU×NV grid (a gently curved patch facing the eye) with
/// sparse lanes on or off (and compacted loops when `sparse`); returns the bits of Ci and Oi
/// at every point, how many instructions ran over listed points only and how many loops
/// were compacted.
fn run(prog: &Program, sparse: bool) -> (Vec<[u32; 6]>, u64, u64) {
    let n = NU * NV;
    let diags = Diagnostics::new();
    let spaces = |_: &str| Some(Mat4::from_translation(Vec3::new(0.1, 0.2, 0.3)));
    let info = |_: &str, _: &str| None;
    let env = Env {
        nu: NU,
        nv: NV,
        spaces: &spaces,
        lights: &[],
        flip_normals: false,
        near: 0.1,
        far: 100.0,
        shader_name: "test",
        diags: &diags,
        info: &info,
        textures: None,
        seed: 7,
        rays: None,
        cones: None,
        displacement_outputs: &[],
        surface_params: &[],
        atmosphere_params: &[],
    };
    let mut ex = Exec::new(prog, n, &env);
    ex.sparse = sparse;
    ex.compact = sparse;
    ex.run_init();
    let (du, dv) = (1.0 / (NU - 1) as f32, 1.0 / (NV - 1) as f32);
    let u: Vec<f32> = (0..n).map(|k| (k % NU) as f32 * du).collect();
    let v: Vec<f32> = (0..n).map(|k| (k / NU) as f32 * dv).collect();
    let p: Vec<Vec3> = (0..n)
        .map(|k| {
            Vec3::new(
                u[k] - 0.5,
                v[k] - 0.5,
                2.0 + 0.3 * (u[k] * 3.0).sin() * v[k],
            )
        })
        .collect();
    let binds: [(&str, Slot); 11] = [
        ("s", Slot::VF(u.clone())),
        ("t", Slot::VF(v.clone())),
        ("u", Slot::VF(u.clone())),
        ("v", Slot::VF(v.clone())),
        ("du", Slot::F(du)),
        ("dv", Slot::F(dv)),
        ("P", Slot::VT(p.clone())),
        ("N", Slot::VT(vec![-Vec3::Z; n])),
        ("Ng", Slot::VT(vec![-Vec3::Z; n])),
        ("I", Slot::VT(p)),
        ("Cs", Slot::VT(vec![Vec3::new(0.8, 0.5, 0.2); n])),
    ];
    for (name, val) in binds {
        if let Some(g) = prog.global(name) {
            ex.set(g.reg, val);
        }
    }
    ex.run_body();
    let get = |name: &str| -> Vec<Vec3> {
        match prog.global(name) {
            Some(g) => (0..n).map(|i| ex.regs[g.reg as usize].t().at(i)).collect(),
            None => vec![Vec3::ZERO; n],
        }
    };
    let (ci, oi) = (get("Ci"), get("Oi"));
    let bits = (0..n)
        .map(|i| {
            let (c, o) = (ci[i], oi[i]);
            [c.x, c.y, c.z, o.x, o.y, o.z].map(f32::to_bits)
        })
        .collect();
    (bits, ex.sparse_ops, ex.compactions)
}

/// Compiles and runs `src` both ways; the outputs must be the same bits, and (when
/// `expect_sparse`) some instructions must really have run sparse.
fn same_both_ways(src: &str, expect_sparse: bool) {
    same_both_ways_c(src, expect_sparse, false)
}

/// [`same_both_ways`]; with `expect_compact`, some loop must have been compacted.
fn same_both_ways_c(src: &str, expect_sparse: bool, expect_compact: bool) {
    let prog = compile(src);
    let (dense, none, no_compactions) = run(&prog, false);
    let (sparse, used, compactions) = run(&prog, true);
    assert_eq!((none, no_compactions), (0, 0));
    if expect_sparse {
        assert!(used > 0, "no instruction ran sparse in:\n{src}");
    }
    if expect_compact {
        assert!(compactions > 0, "no loop was compacted in:\n{src}");
    }
    for (k, (a, b)) in dense.iter().zip(&sparse).enumerate() {
        assert_eq!(
            a,
            b,
            "point {k} ({}, {}) differs: dense {:?} sparse {:?}\n{src}",
            k % NU,
            k / NU,
            a.map(f32::from_bits),
            b.map(f32::from_bits)
        );
    }
}

/// A loop whose points leave at very different steps, with derivatives (of variables and of
/// expressions), arrays indexed by the step, break, continue, a function with early returns,
/// noise, random numbers and the built-ins a march uses.
const MARCH: &str = r#"
float bump(float x) {
    if (x > 0.5)
        return x * x;
    return -x;
}
surface march(float k = 3;) {
    float i = 0, acc = 0, r = 0;
    float steps = floor(s * 37 + t * 11) + 1;
    point p = P;
    color c = 0;
    float arr[4] = {1, 2, 3, 4};
    while (i < steps) {
        i += 1;
        if (mod(i, 7) == 3)
            continue;
        float e = exp(-i * t * k) + pow(abs(sin(i * s)), 1.5);
        acc += e * bump(s) + clamp(i / steps, 0.1, 0.9) + smoothstep(0.2, 0.8, t) * mix(1, 2, s);
        p += normalize(N + vector(i, s, t)) * 0.01;
        r = random();
        acc += length(p) * noise(p * 3) + float cellnoise(p * 2) + 0.001 * r;
        arr[mod(i, 4)] += acc * 0.01;
        acc += arr[mod(i + 1, 4)] * 0.1;
        c += color(acc > 10 ? 1 : 0, min(acc, 3, i), max(e, 0.5)) * 0.01;
        c += Du(acc * i + sin(s * i)) * 0.001 + Deriv(acc, s) * 0.0001 + Dv(p) * 0.01;
        acc += 0.01 * filterstep(0.5, s * i) + 0.001 * area(p);
        if (acc > 40 + 30 * t)
            break;
    }
    Ci = c + color(acc, i, length(p)) * 0.01;
    Oi = color(xcomp(p), ycomp(calculatenormal(p)), zcomp(p) + r);
}
"#;

#[test]
fn a_divergent_march_gives_the_same_bits_sparse_or_not() {
    same_both_ways(MARCH, true);
}

/// An execution leaves its mask buffers to the next one on the thread (a light run at every
/// step of a march); whatever an earlier run left in them, the next run's bits are the same.
#[test]
fn mask_buffers_left_by_earlier_runs_change_nothing() {
    let march = compile(MARCH);
    let first = run(&march, true);
    assert!(arbor::shade::exec::spare_mask_buffers() > 0);
    let other = compile(
        r#"
surface other() {
    float i = 0;
    while (i < 5 + 20 * t) {
        if (s > 0.5) { i += 2; continue; }
        i += 1;
    }
    Ci = color(i, s, t);
}
"#,
    );
    run(&other, false);
    run(&other, true);
    assert_eq!(run(&march, true), first);
    assert_eq!(run(&march, false).0, first.0);
}

/// Registers bound from pooled buffers hold exactly their source, whatever the pool held.
#[test]
fn pooled_copies_hold_their_source() {
    use arbor::shade::value::{pooled_vf, pooled_vt, recycle};
    recycle([
        Slot::VT(vec![Vec3::splat(9.0); 40]),
        Slot::VF(vec![9.0; 40]),
    ]);
    let t = [Vec3::new(1.0, 2.0, 3.0), Vec3::ZERO, Vec3::X];
    assert_eq!(pooled_vt(&t), t.to_vec());
    assert_eq!(pooled_vf(&[4.0, 5.0]), vec![4.0, 5.0]);
    // Nothing asked, nothing taken from the pool.
    assert_eq!(pooled_vt(&[]).capacity(), 0);
    assert_eq!(pooled_vf(&[]).capacity(), 0);
}

/// Loops of pointwise computations are compacted: a march whose points leave at very
/// different steps (nested loops, break, continue, an inlined function with early returns,
/// random numbers, noise, a variable made varying inside the loop, temporaries read after
/// it) gives the same bits as running over the whole grid.
#[test]
fn compacted_loops_give_the_same_bits() {
    same_both_ways_c(
        r#"
float bend(float x) {
    if (x > 0.7)
        return x * 0.5;
    if (x < 0.1)
        return 1 - x;
    return x * x;
}
surface compact(float k = 3;) {
    float i = 0, acc = 0, r = 0, late = 1;
    float steps = floor(s * 57 + t * 13) + 1;
    point p = P;
    color c = 0;
    uniform float u = 0;
    while (i < steps) {
        i += 1;
        if (mod(i, 5) == 2)
            continue;
        float e = exp(-i * t * k) + pow(abs(sin(i * s)), 1.5);
        acc += e * bend(s) + clamp(i / steps, 0.1, 0.9) + smoothstep(0.2, 0.8, t);
        p += normalize(N + vector(i, s, t)) * 0.01;
        r = random();
        color rc = color random();
        float j = 0;
        while (j < mod(i, 4)) {
            j += 1;
            acc += 0.01 * noise(p * j) + 0.001 * float cellnoise(p * 2);
            if (acc > 30 + 20 * s)
                break;
        }
        late = i;
        c += color(acc > 10 ? 1 : 0, min(acc, 3, i), max(e, 0.5)) * 0.01 + rc * 0.001;
        u += 1;
        if (acc > 40 + 30 * t)
            break;
    }
    Ci = c + color(acc, i, length(p)) * 0.01 + late * 0.001;
    Oi = color(xcomp(p), u * 0.001 + r, zcomp(p));
}
"#,
        false,
        true,
    );
}

/// Nested loops, a temporary computed before a loop and read inside it, a derivative of a
/// temporary taken after the loop it was computed in, and a loop condition of several parts.
#[test]
fn nested_loops_and_temporaries_across_blocks() {
    same_both_ways(
        r#"
surface nest(float k = 2;) {
    float a = 0, j = 0;
    float lim = floor(s * 30) + 1;
    float w = sin(s * 10) * cos(t * 7);
    for (j = 0; j < lim && a < 25; j += 1) {
        float m = 0;
        while (m < j * t * 3) {
            m += 1;
            a += w * 0.1 + exp(-m) + sqrt(m) * 0.01;
            if (a > 12 + 8 * s) {
                a -= 0.5;
                break;
            }
        }
        a += atan(j, w) + log(1 + j) * 0.1 + (j > 3 ? 1 : 0);
    }
    float d = Du(a) + Dv(a * w);
    Ci = color(a, j, d);
    Oi = color(w, lim, 1);
}
"#,
        true,
    );
}

/// Each pointwise built-in (and some that are not) in a divergent loop: the loop's points run
/// sparse for most of its steps.
#[test]
fn every_builtin_in_a_divergent_loop() {
    let exprs = [
        "radians(x * 90)",
        "degrees(x)",
        "sin(x)",
        "cos(x)",
        "tan(x)",
        "asin(x - 1)",
        "acos(x - 1)",
        "atan(x)",
        "atan(x, 0.5)",
        "pow(x, 2.5)",
        "exp(-x * 40)",
        "sqrt(x)",
        "inversesqrt(x)",
        "log(x)",
        "log(x, 3)",
        "mod(x * 10, 3)",
        "abs(x - 1)",
        "sign(x - 1)",
        "floor(x * 5)",
        "ceil(x * 5)",
        "round(x * 5)",
        "min(x, 1.2)",
        "max(x, 1.2, s)",
        "clamp(x, 0.3, 1.1)",
        "mix(0, 2, x)",
        "step(1, x)",
        "smoothstep(0.5, 1.5, x)",
        "filterstep(1, x)",
        "spline(x * 0.5, 0, 1, 4, 2, 3, 1)",
        "Du(x)",
        "Dv(x * x)",
        "Deriv(x * t, s)",
        "noise(x * 3)",
        "noise(x, t)",
        "noise(point(x, t, s))",
        "noise(point(x, t, s), x)",
        "pnoise(x * 7, 4)",
        "pnoise(point(x, t, s) * 5, point(2, 2, 2))",
        "float cellnoise(point(x, t, s) * 4)",
        "xcomp(color noise(x * 3))",
        "ycomp(vector noise(point(x, t, s)))",
        "length(point(x, t, 1))",
        "xcomp(normalize(vector(x, t, 1)))",
        "distance(point(x, 0, 0), point(0, t, 1))",
        "ptlined(point(x, t, 0), point(0, 0, 0), point(1, 1, 0))",
        "ycomp(rotate(point(x, t, 0), 0.3, point(0, 0, 0), point(0, 0, 1)))",
        "area(point(x, t, 1))",
        "zcomp(faceforward(normal(x, t, -1), vector(0, 0, 1)))",
        "xcomp(reflect(vector(x, t, 1), normal(0, 0, 1)))",
        "xcomp(refract(normalize(vector(x, t, 1)), normal(0, 0, -1), 0.7))",
        "depth(point(x, t, 5))",
        "comp(color(x, t, s), 1)",
        "xcomp(calculatenormal(point(x, t, x * t)))",
        "zcomp(transform(\"shader\", point(x, t, 1)))",
        "xcomp(vector(x, t, 1) ^ vector(t, 1, x))",
        "vector(x, t, 1) . vector(t, 1, x)",
        "(x > 1 && t < 0.5) ? x : -x",
        "color(x, t, 1) == color(x, t, 1) ? 1 : 0",
        "xcomp(min(color(x, 0.5, 1), color(1, x, 0)))",
        "ycomp(max(point(x, 0.5, 1), point(1, x, 0)))",
        "zcomp(clamp(color(x, t, s), color(0.2), color(0.9)))",
        "xcomp(mix(color(0), color(x, 1, 2), t))",
        "ycomp(mix(color(0), color(x, 1, 2), color(t, s, x)))",
        "xcomp(color(x) / color(t, 0, 2))",
        "x / (t - 0.5)",
    ];
    for e in exprs {
        let src = format!(
            "surface b() {{
    float i = 0, x = s + t;
    color c = 0;
    float steps = floor(s * 20 + t * 9) + 1;
    while (i < steps) {{
        i += 1;
        c += color({e}, x, i);
        x = s + t + i * 0.013;
    }}
    Ci = c;
    Oi = 1;
}}"
        );
        same_both_ways(&src, true);
    }
}

/// A marching light (through an opaque ball its steps become tiny, so points leave at very
/// different steps) seen by a marching atmosphere that calls illuminance at every step: the
/// same picture with sparse lanes on and off, on one thread and on two.
#[test]
fn marched_light_through_marched_fog_renders_the_same_bits() {
    const FOG: &str = r#"
volume stepfog(float density = 0.5; float stepsize = 0.2;) {
    point eye = P - I;
    vector dir = normalize(I);
    float len = min(length(I), 12);
    float d = 0.5 * stepsize * random(), trans = 1;
    color glow = 0;
    while (d < len && trans > 0.01) {
        float st = min(stepsize, len - d);
        point here = eye + (d + 0.5 * st) * dir;
        color arriving = 0;
        illuminance(here) {
            arriving += Cl;
        }
        float absorbed = 1 - exp(-density * st * (0.5 + noise(here * 2)));
        glow += trans * absorbed * arriving;
        trans *= 1 - absorbed;
        d += st;
    }
    Ci = glow + trans * Ci;
    Oi = (1 - trans) + trans * Oi;
}
"#;
    const SHADOWBALL: &str = r#"
light shadowball(float intensity = 1; point from = point "shader" (0, 4, 0);
                 point ball = point "shader" (0, 1, 1); float radius = 0.8;) {
    illuminate(from) {
        /* March from the lit point to the light; inside the ball the steps shrink. */
        float t = 0, tau = 0, len = length(L);
        vector dir = -L / len;
        while (t < len) {
            point q = Ps + t * dir;
            float inside = radius - distance(q, ball);
            float dens = inside > 0 ? exp(40 * inside) : 0;
            tau += dens * 0.01;
            t += clamp(1 / (1 + 20 * dens), 0.01, 0.5);
        }
        Cl = intensity * exp(-tau) / (L . L) * 9;
    }
}
"#;
    let dir = common::scratch_dir("sparse_lanes_fog");
    std::fs::write(dir.join("stepfog.sl"), FOG).unwrap();
    std::fs::write(dir.join("shadowball.sl"), SHADOWBALL).unwrap();
    let rib = r#"Format 48 36 1
PixelSamples 2 2
ShadingRate 2
Projection "perspective" "fov" [50]
Translate 0 -1 5
WorldBegin
LightSource "ambientlight" 1 "intensity" [0.05]
LightSource "shadowball" 2
Atmosphere "stepfog"
Surface "matte"
AttributeBegin
Translate 0 1 1
Sphere 0.8 -0.8 0.8 360
AttributeEnd
Polygon "P" [-6 0 -4  6 0 -4  6 0 6  -6 0 6]
Polygon "P" [-6 0 4  6 0 4  6 6 4  -6 6 4]
WorldEnd
"#;
    let render = |sparse: bool, threads: usize| {
        SPARSE_LANES.store(sparse, std::sync::atomic::Ordering::Relaxed);
        COMPACT_LOOPS.store(sparse, std::sync::atomic::Ordering::Relaxed);
        let opts = RenderOptions {
            threads,
            ..Default::default()
        };
        let (film, _, _) = common::render_rib_with(rib, &[dir.clone()], &opts);
        common::film_rgb(&film)
    };
    let dense = render(false, 1);
    let sparse1 = render(true, 1);
    let sparse2 = render(true, 2);
    SPARSE_LANES.store(true, std::sync::atomic::Ordering::Relaxed);
    COMPACT_LOOPS.store(true, std::sync::atomic::Ordering::Relaxed);
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert!(dense.iter().any(|&x| x > 0.01), "the fog is lit");
    assert_eq!(
        bits(&dense),
        bits(&sparse1),
        "sparse lanes changed the picture"
    );
    assert_eq!(
        bits(&sparse1),
        bits(&sparse2),
        "thread count changed the picture"
    );
}

/// Which loops may run compacted: pointwise code only; a derivative, an illuminance, an
/// array element, or a `break` that leaves the loop keeps the loop over the whole grid.
#[test]
fn compactable_loops_are_the_pointwise_ones() {
    use arbor::sl::ir::Instr;
    fn loops(code: &[Instr], out: &mut Vec<bool>) {
        for i in code {
            match i {
                Instr::Loop {
                    cond_code,
                    body,
                    step,
                    compact,
                    ..
                } => {
                    out.push(compact.is_some());
                    loops(cond_code, out);
                    loops(body, out);
                    loops(step, out);
                }
                Instr::If {
                    then, otherwise, ..
                } => {
                    loops(then, out);
                    loops(otherwise, out);
                }
                Instr::Function { body }
                | Instr::Illuminance { body, .. }
                | Instr::Illuminate { body, .. }
                | Instr::Solar { body, .. } => loops(body, out),
                _ => {}
            }
        }
    }
    let marks = |body: &str| {
        let prog = compile(&format!(
            "surface m() {{ float a = 0, i = 0; float arr[3] = {{1, 2, 3}}; color c = 0; {body} Ci = c + a; }}"
        ));
        let mut out = Vec::new();
        loops(&prog.body, &mut out);
        out
    };
    assert_eq!(
        marks("while (i < s * 9) { i += 1; a += exp(-i) * noise(P * i); }"),
        [true]
    );
    assert_eq!(
        marks("while (i < s * 9) { i += 1; if (a > 3) break; a += sin(i); }"),
        [true]
    );
    assert_eq!(
        marks("while (i < s * 9) { i += 1; a += Du(a * i); }"),
        [false]
    );
    assert_eq!(
        marks("while (i < s * 9) { i += 1; illuminance(P) { c += Cl; } }"),
        [false]
    );
    assert_eq!(
        marks("while (i < s * 9) { i += 1; a += arr[mod(i, 3)]; }"),
        [false]
    );
    // Nested pointwise loops: both.
    assert_eq!(
        marks("while (i < 4) { i += 1; float j = 0; while (j < t * 9) { j += 1; a += j; } }"),
        [true, true]
    );
}
