//! `arbor lsp` latency: one keystroke in a 2 000-line shader (or a RIB scene) and the re-check
//! that follows, as the server runs it (incremental edit applied, preprocess, parse, type
//! check and compile, diagnostics converted and published). Target: under 50 ms.

use criterion::{criterion_group, criterion_main, Criterion};
use serde_json::json;

use arbor::lsp::Server;
use arbor::pipeline::Settings;

/// A 2 000-line surface shader: 120 helper functions, a shader body calling a third of them.
fn big_shader() -> String {
    let mut s = String::from("// Generated for the benchmark.\n#include \"noises.h\"\n\n");
    let mut k = 0;
    while s.lines().count() < 1_700 {
        s.push_str(&format!(
            "/* Helper {k}: layered noise. */\nfloat layer{k}(point p; float scale) {{\n    float sum = 0, amp = 1;\n    point q = p * scale;\n    uniform float i;\n    for (i = 0; i < 3; i += 1) {{\n        sum += amp * (2 * noise(q) - 1);\n        amp *= 0.5;\n        q *= 2.03;\n    }}\n    return sum * {}.5;\n}}\n\n",
            k % 7
        ));
        k += 1;
    }
    s.push_str("surface big(float Ka = 1, Kd = 0.8, Ks = 0.3, roughness = 0.1;\n           color tint = color(0.8, 0.6, 0.4)) {\n    normal Nf = faceforward(normalize(N), I);\n    vector V = -normalize(I);\n    point PP = transform(\"shader\", P);\n    float acc = 0;\n");
    let mut j = 0;
    while s.lines().count() < 1_996 {
        s.push_str(&format!(
            "    acc += layer{}(PP, {}.0) * smoothstep(0, 1, s + t);\n",
            (j * 3) % k,
            1 + j % 5
        ));
        j += 1;
    }
    s.push_str("    color c = mix(Cs, tint, clamp(acc, 0, 1));\n    Oi = Os;\n    Ci = Oi * (c * (Ka * ambient() + Kd * diffuse(Nf)) + Ks * specular(Nf, V, roughness));\n}\n");
    s
}

fn scene_rib() -> String {
    let mut s = String::from("Display \"b.png\" \"png\" \"rgb\"\nFormat 320 240 1\nProjection \"perspective\" \"fov\" 40\nWorldBegin\nLightSource \"distantlight\" 1\n");
    for i in 0..400 {
        s.push_str(&format!(
            "AttributeBegin\n  Color [{} 0.5 0.5]\n  Surface \"plastic\" \"Ks\" 0.{}\n  Translate {} 0 10\n  Sphere 0.5 -0.5 0.5 360\nAttributeEnd\n",
            (i % 10) as f32 / 10.0,
            i % 9,
            i % 20
        ));
    }
    s.push_str("WorldEnd\n");
    s
}

fn open(server: &mut Server, uri: &str, text: &str) {
    server.handle_body(
        json!({"jsonrpc": "2.0", "id": 1, "method": "initialize", "params": {"capabilities": {}}})
            .to_string()
            .as_bytes(),
    );
    server.handle_body(
        json!({"jsonrpc": "2.0", "method": "textDocument/didOpen", "params": {"textDocument":
            {"uri": uri, "languageId": "", "version": 1, "text": text}}})
        .to_string()
        .as_bytes(),
    );
    server.check_dirty();
}

/// A keystroke: one character of line `line` replaced (alternately by `a` and `b`).
fn keystroke(server: &mut Server, uri: &str, line: u32, col: u32, version: i32) {
    let ch = if version % 2 == 0 { "3" } else { "4" };
    server.handle_body(
        json!({"jsonrpc": "2.0", "method": "textDocument/didChange", "params": {
            "textDocument": {"uri": uri, "version": version},
            "contentChanges": [{"range": {"start": {"line": line, "character": col},
                "end": {"line": line, "character": col + 1}}, "text": ch}]}})
        .to_string()
        .as_bytes(),
    );
    server.check_dirty();
}

/// This thread's CPU time (user + system) in seconds, from /proc (Linux; None elsewhere).
/// Criterion reports wall time, which on a shared machine includes waiting for a core.
fn thread_cpu_seconds() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/stat").ok()?;
    let after = &s[s.rfind(')')? + 2..];
    let f: Vec<&str> = after.split_whitespace().collect();
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

fn report_cpu(name: &str, n: i32, mut f: impl FnMut(i32)) {
    let (Some(a), t) = (thread_cpu_seconds(), std::time::Instant::now()) else {
        return;
    };
    for i in 0..n {
        f(i);
    }
    if let Some(b) = thread_cpu_seconds() {
        eprintln!(
            "{name}: {:.1} ms CPU per keystroke (wall {:.1} ms), {n} keystrokes",
            (b - a) * 1e3 / n as f64,
            t.elapsed().as_secs_f64() * 1e3 / n as f64
        );
    }
}

fn bench(c: &mut Criterion) {
    let shader = big_shader();
    assert!(
        shader.lines().count() >= 2_000,
        "{}",
        shader.lines().count()
    );
    // The digit of the last `acc += layerN(PP, D.0)` line's scale.
    let last = shader.lines().count() as u32 - 5;
    let col = shader
        .lines()
        .nth(last as usize)
        .unwrap()
        .find(".0)")
        .unwrap() as u32
        - 1;
    let mut server = Server::new(Settings::default(), Box::new(std::io::sink()));
    let uri = "file:///bench/big.sl";
    open(&mut server, uri, &shader);
    let mut version = 1;
    c.bench_function("lsp/keystroke_recheck_2000_line_shader", |b| {
        b.iter(|| {
            version += 1;
            keystroke(&mut server, uri, last, col, version);
        })
    });
    report_cpu("lsp/keystroke_recheck_2000_line_shader", 40, |i| {
        keystroke(&mut server, uri, last, col, version + 1 + i)
    });

    let rib = scene_rib();
    let mut server = Server::new(Settings::default(), Box::new(std::io::sink()));
    let uri = "file:///bench/scene.rib";
    open(&mut server, uri, &rib);
    let mut version = 1;
    c.bench_function("lsp/keystroke_recheck_2400_line_rib", |b| {
        b.iter(|| {
            version += 1;
            // The Ks digit of the first Surface line.
            keystroke(&mut server, uri, 7, 25, version);
        })
    });
    report_cpu("lsp/keystroke_recheck_2400_line_rib", 40, |i| {
        keystroke(&mut server, uri, 7, 25, version + 1 + i)
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
