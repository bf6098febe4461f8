//! `arbor lsp` driven over stdio as an editor drives it: initialize, open, edit, ask, shut down.
//! Every answer is checked, including a diagnostic that appears when a typo is made and goes
//! when it is fixed, and the server surviving malformed messages and documents.

mod common;

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::time::Duration;

use serde_json::{json, Value};

struct Client {
    child: Child,
    stdin: ChildStdin,
    rx: Receiver<Value>,
    next_id: i64,
    /// Notifications received while waiting for responses.
    notes: Vec<Value>,
}

fn read_one(r: &mut impl BufRead) -> Option<Value> {
    let mut len = 0usize;
    loop {
        let mut line = String::new();
        if r.read_line(&mut line).ok()? == 0 {
            return None;
        }
        let l = line.trim_end();
        if l.is_empty() {
            break;
        }
        if let Some(v) = l.strip_prefix("Content-Length:") {
            len = v.trim().parse().ok()?;
        }
    }
    let mut body = vec![0; len];
    r.read_exact(&mut body).ok()?;
    serde_json::from_slice(&body).ok()
}

impl Client {
    fn start(dir: &Path) -> Client {
        let mut child = Command::new(env!("CARGO_BIN_EXE_arbor"))
            .arg("lsp")
            .current_dir(dir)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let stdin = child.stdin.take().unwrap();
        let stdout = child.stdout.take().unwrap();
        let (tx, rx) = channel();
        std::thread::spawn(move || {
            let mut r = BufReader::new(stdout);
            while let Some(v) = read_one(&mut r) {
                if tx.send(v).is_err() {
                    break;
                }
            }
        });
        Client {
            child,
            stdin,
            rx,
            next_id: 1,
            notes: Vec::new(),
        }
    }

    fn raw(&mut self, body: &[u8]) {
        write!(self.stdin, "Content-Length: {}\r\n\r\n", body.len()).unwrap();
        self.stdin.write_all(body).unwrap();
        self.stdin.flush().unwrap();
    }

    fn send(&mut self, v: Value) {
        self.raw(v.to_string().as_bytes());
    }

    fn notify(&mut self, method: &str, params: Value) {
        self.send(json!({"jsonrpc": "2.0", "method": method, "params": params}));
    }

    /// The next message; a hang guard only (the server answers in milliseconds).
    fn recv(&mut self) -> Value {
        self.rx
            .recv_timeout(Duration::from_secs(60))
            .expect("the server stopped answering")
    }

    /// Sends a request and returns its response (notifications on the way are kept).
    fn request(&mut self, method: &str, params: Value) -> Value {
        let id = self.next_id;
        self.next_id += 1;
        self.send(json!({"jsonrpc": "2.0", "id": id, "method": method, "params": params}));
        self.response(json!(id))
    }

    fn response(&mut self, id: Value) -> Value {
        loop {
            let m = self.recv();
            if m.get("id") == Some(&id) && m.get("method").is_none() {
                return m;
            }
            self.notes.push(m);
        }
    }

    /// The next diagnostics published for `uri` (earlier ones already received first).
    fn diagnostics(&mut self, uri: &str) -> Vec<Value> {
        if let Some(i) = self.notes.iter().position(|n| is_diag_for(n, uri)) {
            let n = self.notes.remove(i);
            return n["params"]["diagnostics"].as_array().unwrap().clone();
        }
        loop {
            let m = self.recv();
            if is_diag_for(&m, uri) {
                return m["params"]["diagnostics"].as_array().unwrap().clone();
            }
            self.notes.push(m);
        }
    }

    /// Drops every diagnostics notification for `uri` received so far.
    fn forget(&mut self, uri: &str) {
        self.notes.retain(|n| !is_diag_for(n, uri));
    }
}

fn is_diag_for(n: &Value, uri: &str) -> bool {
    n["method"] == "textDocument/publishDiagnostics" && n["params"]["uri"] == uri
}

/// A scratch folder (removed when the guard drops) and its canonical path, which the server
/// reports in URIs.
fn tmpdir(name: &str) -> (common::Scratch, PathBuf) {
    let guard = common::scratch(&format!("lsp-{name}"));
    let path = guard.canonicalize().unwrap();
    (guard, path)
}

fn uri(p: &Path) -> String {
    format!("file://{}", p.display())
}

fn pos(line: u32, character: u32) -> Value {
    json!({"line": line, "character": character})
}

fn at(uri: &str, line: u32, character: u32) -> Value {
    json!({"textDocument": {"uri": uri}, "position": pos(line, character)})
}

const UTIL_H: &str = "\
/* Distance to the nearest stripe centre. */
float stripe_distance(float x; float freq) {
    float f = mod(x * freq, 1);
    return abs(f - 0.5);
}
";

const STRIPES_SL: &str = "\
#include \"util.h\"

// Stripes along s, blended with noise.
surface stripes(float freq = 4; color stripecolor = color(1, 0, 0)) {
    float d = stripe_distance(s, freq);
    float n = noise(P * 2);
    Ci = Cs * mix(color 1, stripecolor, step(0.25, d)) * n;
    Oi = Os;
}
";

const SCENE_RIB: &str = "\
Display \"out.png\" \"png\" \"rgb\"
Format 64 48 1
Projection \"perspective\" \"fov\" 40
WorldBegin
# the only object
AttributeBegin
Surface \"stripes\" \"freq\" 8
Translate 0 0 5
Sphere 1 -1 1 360
AttributeEnd
WorldEnd
";

fn messages(diags: &[Value]) -> String {
    diags
        .iter()
        .map(|d| d["message"].as_str().unwrap_or("").to_string())
        .collect::<Vec<_>>()
        .join(" | ")
}

#[test]
fn an_editor_session_over_stdio() {
    let (_guard, dir) = tmpdir("session");
    std::fs::write(dir.join("util.h"), UTIL_H).unwrap();
    std::fs::write(dir.join("stripes.sl"), STRIPES_SL).unwrap();
    std::fs::write(dir.join("scene.rib"), SCENE_RIB).unwrap();
    let sl = uri(&dir.join("stripes.sl"));
    let rib = uri(&dir.join("scene.rib"));
    let util = uri(&dir.join("util.h"));
    let mut c = Client::start(&dir);

    // --- initialize
    let init = c.request(
        "initialize",
        json!({"processId": null, "rootUri": uri(&dir), "capabilities": {}}),
    );
    let caps = &init["result"]["capabilities"];
    assert_eq!(caps["hoverProvider"], true, "{init}");
    assert_eq!(
        caps["textDocumentSync"]["change"], 2,
        "incremental sync: {init}"
    );
    assert_eq!(caps["documentFormattingProvider"], true);
    assert_eq!(init["result"]["serverInfo"]["name"], "arbor");
    c.notify("initialized", json!({}));

    // --- open a clean shader: no diagnostics
    c.notify(
        "textDocument/didOpen",
        json!({"textDocument": {"uri": sl, "languageId": "rsl", "version": 1, "text": STRIPES_SL}}),
    );
    let d = c.diagnostics(&sl);
    assert!(d.is_empty(), "clean shader: {}", messages(&d));

    // --- a typo appears (incremental edit of `noise` → `nosie` on line 5) …
    let col = STRIPES_SL.lines().nth(5).unwrap().find("noise").unwrap() as u32;
    c.notify(
        "textDocument/didChange",
        json!({"textDocument": {"uri": sl, "version": 2}, "contentChanges": [
            {"range": {"start": pos(5, col), "end": pos(5, col + 5)}, "text": "nosie"}]}),
    );
    let d = c.diagnostics(&sl);
    assert_eq!(d.len(), 1, "{}", messages(&d));
    let m = d[0]["message"].as_str().unwrap();
    assert!(m.contains("unknown function `nosie`"), "{m}");
    assert!(m.contains("noise"), "did-you-mean help: {m}");
    assert_eq!(d[0]["severity"], 1);
    assert_eq!(d[0]["source"], "arbor");
    assert_eq!(d[0]["range"]["start"], pos(5, col), "{}", d[0]);
    assert_eq!(d[0]["range"]["end"], pos(5, col + 5), "{}", d[0]);

    // … and disappears when fixed.
    c.notify(
        "textDocument/didChange",
        json!({"textDocument": {"uri": sl, "version": 3}, "contentChanges": [
            {"range": {"start": pos(5, col), "end": pos(5, col + 5)}, "text": "noise"}]}),
    );
    let d = c.diagnostics(&sl);
    assert!(d.is_empty(), "fixed: {}", messages(&d));

    // --- hover: a built-in, a global, a user function (from the header), a parameter
    let h = c.request("textDocument/hover", at(&sl, 5, col + 2));
    let v = h["result"]["contents"]["value"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(
        v.contains("float noise(point)") && v.contains("Perlin"),
        "{v}"
    );
    let cs = STRIPES_SL.lines().nth(6).unwrap().find("Cs").unwrap() as u32;
    let h = c.request("textDocument/hover", at(&sl, 6, cs));
    let v = h["result"]["contents"]["value"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(v.contains("varying color Cs"), "{v}");
    let sd = STRIPES_SL
        .lines()
        .nth(4)
        .unwrap()
        .find("stripe_distance")
        .unwrap() as u32;
    let h = c.request("textDocument/hover", at(&sl, 4, sd + 3));
    let v = h["result"]["contents"]["value"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(
        v.contains("float stripe_distance(float x; float freq)"),
        "{v}"
    );
    assert!(
        v.contains("Distance to the nearest stripe centre."),
        "doc comment: {v}"
    );
    let fq = STRIPES_SL.lines().nth(4).unwrap().rfind("freq").unwrap() as u32;
    let h = c.request("textDocument/hover", at(&sl, 4, fq + 1));
    let v = h["result"]["contents"]["value"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(
        v.contains("float freq = 4") && v.contains("shader parameter"),
        "{v}"
    );
    // Nothing to say about whitespace.
    let h = c.request("textDocument/hover", at(&sl, 1, 0));
    assert!(h["result"].is_null(), "{h}");

    // --- completion inside the shader body: locals, parameters, functions, built-ins, globals
    let comp = c.request("textDocument/completion", at(&sl, 7, 4));
    let labels: Vec<&str> = comp["result"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| i["label"].as_str().unwrap())
        .collect();
    for want in [
        "d",
        "n",
        "freq",
        "stripecolor",
        "stripe_distance",
        "noise",
        "smoothstep",
        "Cs",
        "illuminance",
    ] {
        assert!(labels.contains(&want), "completion lacks `{want}`");
    }
    let noise = comp["result"]
        .as_array()
        .unwrap()
        .iter()
        .find(|i| i["label"] == "noise")
        .unwrap();
    assert!(
        noise["detail"].as_str().unwrap().contains("noise("),
        "{noise}"
    );

    // --- go to definition: a function in the included header, the #include itself, a local
    let def = c.request("textDocument/definition", at(&sl, 4, sd + 1));
    assert_eq!(def["result"]["uri"], util, "{def}");
    assert_eq!(def["result"]["range"]["start"], pos(1, 6), "{def}");
    let def = c.request("textDocument/definition", at(&sl, 0, 12));
    assert_eq!(def["result"]["uri"], util, "{def}");
    let dcol = STRIPES_SL
        .lines()
        .nth(6)
        .unwrap()
        .find("step(0.25, d)")
        .unwrap() as u32
        + 11;
    let def = c.request("textDocument/definition", at(&sl, 6, dcol));
    assert_eq!(def["result"]["uri"], sl, "{def}");
    assert_eq!(def["result"]["range"]["start"], pos(4, 10), "{def}");

    // --- document symbols: the shader with its parameters and locals
    let syms = c.request(
        "textDocument/documentSymbol",
        json!({"textDocument": {"uri": sl}}),
    );
    let top = syms["result"].as_array().unwrap();
    assert_eq!(top.len(), 1, "only this file's declarations: {syms}");
    assert_eq!(top[0]["name"], "stripes");
    let kids: Vec<&str> = top[0]["children"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k["name"].as_str().unwrap())
        .collect();
    assert_eq!(kids, ["freq", "stripecolor", "d", "n"]);

    // --- an error in the included header shows in the header and at the #include line
    c.notify(
        "textDocument/didOpen",
        json!({"textDocument": {"uri": util, "languageId": "rsl", "version": 1, "text": UTIL_H}}),
    );
    let d = c.diagnostics(&util);
    assert!(
        d.is_empty(),
        "a header alone defines no shader, fine: {}",
        messages(&d)
    );
    let broken = UTIL_H.replace("return abs(f - 0.5);", "return abs(f - 0.5)");
    c.forget(&sl);
    c.notify(
        "textDocument/didChange",
        json!({"textDocument": {"uri": util, "version": 2}, "contentChanges": [{"text": broken}]}),
    );
    let d = c.diagnostics(&sl);
    assert!(!d.is_empty(), "the includer sees the header's error");
    assert_eq!(
        d[0]["range"]["start"]["line"], 0,
        "at the #include: {}",
        d[0]
    );
    assert!(
        d[0]["message"].as_str().unwrap().contains("util.h"),
        "{}",
        d[0]
    );
    c.notify(
        "textDocument/didChange",
        json!({"textDocument": {"uri": util, "version": 3}, "contentChanges": [{"text": UTIL_H}]}),
    );
    loop {
        let d = c.diagnostics(&sl);
        if d.is_empty() {
            break;
        }
    }

    // --- RIB: open, hover, completion of shader parameters, definition, symbols, format
    c.notify(
        "textDocument/didOpen",
        json!({"textDocument": {"uri": rib, "languageId": "rib", "version": 1, "text": SCENE_RIB}}),
    );
    let d = c.diagnostics(&rib);
    assert!(d.is_empty(), "clean scene: {}", messages(&d));
    let h = c.request("textDocument/hover", at(&rib, 8, 2));
    let v = h["result"]["contents"]["value"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(v.contains("Sphere radius zmin zmax thetamax"), "{v}");
    let h = c.request("textDocument/hover", at(&rib, 6, 10));
    let v = h["result"]["contents"]["value"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(
        v.contains("surface stripes(") && v.contains("uniform float freq"),
        "{v}"
    );
    // Completion of request names at the start of a line.
    let comp = c.request("textDocument/completion", at(&rib, 7, 0));
    let labels: Vec<String> = comp["result"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| i["label"].as_str().unwrap().to_string())
        .collect();
    assert!(labels.iter().any(|l| l == "Sphere") && labels.iter().any(|l| l == "LightSource"));
    // Typing a new parameter name for the surface: the shader's own parameters.
    let line6 = "Surface \"stripes\" \"freq\" 8 \"";
    c.notify(
        "textDocument/didChange",
        json!({"textDocument": {"uri": rib, "version": 2}, "contentChanges": [
            {"range": {"start": pos(6, 0), "end": pos(6, 26)}, "text": line6}]}),
    );
    let comp = c.request("textDocument/completion", at(&rib, 6, line6.len() as u32));
    let labels: Vec<String> = comp["result"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| i["label"].as_str().unwrap().to_string())
        .collect();
    assert!(labels.contains(&"stripecolor".to_string()), "{labels:?}");
    c.notify(
        "textDocument/didChange",
        json!({"textDocument": {"uri": rib, "version": 3}, "contentChanges": [{"text": SCENE_RIB}]}),
    );
    // Definition of a shader name: its source file.
    let def = c.request("textDocument/definition", at(&rib, 6, 11));
    assert_eq!(def["result"]["uri"], sl, "{def}");
    // A standard shader opens the library's source, written out read-only.
    let plastic = SCENE_RIB.replace("Surface \"stripes\" \"freq\" 8", "Surface \"plastic\"");
    c.notify(
        "textDocument/didChange",
        json!({"textDocument": {"uri": rib, "version": 4}, "contentChanges": [{"text": plastic}]}),
    );
    let def = c.request("textDocument/definition", at(&rib, 6, 11));
    let target = def["result"]["uri"].as_str().unwrap().to_string();
    assert!(target.ends_with("/shaders/plastic.sl"), "{def}");
    let on_disk = std::fs::read_to_string(target.trim_start_matches("file://")).unwrap();
    assert!(on_disk.contains("surface plastic"), "{on_disk}");
    // Outline: the world block holds the attribute block holding the sphere.
    let syms = c.request(
        "textDocument/documentSymbol",
        json!({"textDocument": {"uri": rib}}),
    );
    let s = syms["result"].to_string();
    assert!(
        s.contains("\"World\"") && s.contains("Sphere 1") && s.contains("Surface \\\"plastic\\\""),
        "{s}"
    );
    // Formatting: indentation by block, the comment kept.
    let f = c.request(
        "textDocument/formatting",
        json!({"textDocument": {"uri": rib}, "options": {"tabSize": 2, "insertSpaces": true}}),
    );
    let new_text = f["result"][0]["newText"].as_str().unwrap().to_string();
    assert!(
        new_text.contains(
            "WorldBegin\n  # the only object\n  AttributeBegin\n    Surface \"plastic\"\n"
        ),
        "{new_text}"
    );

    // --- a RIB typo: did you mean
    let typo = plastic.replace("Sphere 1", "Sphre 1");
    c.forget(&rib);
    c.notify(
        "textDocument/didChange",
        json!({"textDocument": {"uri": rib, "version": 5}, "contentChanges": [{"text": typo}]}),
    );
    let d = c.diagnostics(&rib);
    let m = messages(&d);
    let typo_diag = d
        .iter()
        .find(|d| {
            d["message"]
                .as_str()
                .unwrap()
                .contains("unknown request `Sphre`")
        })
        .unwrap_or_else(|| panic!("{m}"));
    assert!(m.contains("did you mean `Sphere`?"), "{m}");
    assert_eq!(typo_diag["range"]["start"], pos(8, 0));
    assert_eq!(typo_diag["range"]["end"], pos(8, 5));
    // Formatting refuses a RIB that does not parse? (it parses: an unknown name is a request)
    let f = c.request(
        "textDocument/formatting",
        json!({"textDocument": {"uri": rib}, "options": {"tabSize": 2, "insertSpaces": true}}),
    );
    assert!(f["result"].is_array(), "{f}");

    // --- a missing include: an error at the #include line
    let missing = uri(&dir.join("missing.sl"));
    let text = "#include \"nothere.h\"\nsurface m() { Ci = Cs; }\n";
    c.notify(
        "textDocument/didOpen",
        json!({"textDocument": {"uri": missing, "languageId": "rsl", "version": 1, "text": text}}),
    );
    let d = c.diagnostics(&missing);
    assert_eq!(d.len(), 1, "{}", messages(&d));
    assert!(d[0]["message"].as_str().unwrap().contains("nothere.h"));
    assert_eq!(d[0]["range"]["start"]["line"], 0);

    // --- shut down cleanly
    let r = c.request("shutdown", Value::Null);
    assert!(r["result"].is_null() && r.get("error").is_none(), "{r}");
    c.notify("exit", Value::Null);
    let status = c.child.wait().unwrap();
    assert_eq!(status.code(), Some(0));
}

#[test]
fn malformed_requests_and_documents_never_crash_the_server() {
    let (_guard, dir) = tmpdir("malformed");
    let mut c = Client::start(&dir);
    // Before initialize: an error, not a crash.
    let r = c.request("textDocument/hover", at("file:///x.sl", 0, 0));
    assert_eq!(r["error"]["code"], -32002, "{r}");
    c.request("initialize", json!({"capabilities": {}}));
    // Not JSON at all: a parse error with a null id.
    c.raw(b"{this is not json");
    let m = c.recv();
    assert_eq!(m["error"]["code"], -32700, "{m}");
    assert!(m["id"].is_null());
    // A header that is not a header, then a message after it still works.
    c.stdin.write_all(b"Garbage-Without-Colon\r\n\r\n").unwrap();
    // Wrong params, an unknown method, no method.
    let r = c.request("textDocument/hover", json!("nonsense"));
    assert_eq!(r["error"]["code"], -32602, "{r}");
    let r = c.request("textDocument/frobnicate", json!({}));
    assert_eq!(r["error"]["code"], -32601, "{r}");
    c.send(json!({"jsonrpc": "2.0", "id": 99}));
    let r = c.response(json!(99));
    assert_eq!(r["error"]["code"], -32600, "{r}");
    // Malformed notifications are ignored.
    c.notify("textDocument/didOpen", json!({"textDocument": 5}));
    c.notify("textDocument/didChange", json!([1, 2, 3]));

    // Hostile documents: binary bytes, deep nesting, unterminated everything, huge numbers.
    let docs = [
        ("a.sl", "\u{0}\u{1}surface \u{ff}(".to_string()),
        ("b.sl", format!("surface b() {{ Ci = {}1{}; }}", "(".repeat(5000), ")".repeat(5000))),
        ("c.sl", "#define A A A\n#define B(x) B(x) B(x)\nsurface c() { Ci = A + B(B(1)); }\n#if\n#include\n".to_string()),
        ("d.rib", "WorldBegin ]]] \"unterminated\nSphere [ 1e999999 ] [[[[\n\u{1F600}".to_string()),
        ("e.rib", "Surface \"x\" \"uniform float\" [".to_string()),
        ("f.sl", "surface f() { Ci = é\u{1F600} ; /* unterminated".to_string()),
    ];
    for (k, (name, text)) in docs.iter().enumerate() {
        let u = uri(&dir.join(name));
        c.notify(
            "textDocument/didOpen",
            json!({"textDocument": {"uri": u, "languageId": "", "version": 1, "text": text}}),
        );
        let d = c.diagnostics(&u);
        assert!(!d.is_empty(), "{name}: bad input is reported");
        // Positions anywhere, ranges reversed and past the end.
        c.notify(
            "textDocument/didChange",
            json!({"textDocument": {"uri": u, "version": 2}, "contentChanges": [
                {"range": {"start": pos(99, 99), "end": pos(0, 1)}, "text": "\u{1F600}x"},
                {"range": {"start": pos(0, 1), "end": pos(0, 2)}, "text": ""}]}),
        );
        for (line, ch) in [(0, 0), (0, 1), (0, 2), (999, 999), (0, u32::MAX)] {
            for m in [
                "textDocument/hover",
                "textDocument/completion",
                "textDocument/definition",
            ] {
                let r = c.request(m, at(&u, line, ch));
                assert!(
                    r.get("error").is_none(),
                    "{name} {m} {line}:{ch} (#{k}): {r}"
                );
            }
        }
        let r = c.request(
            "textDocument/documentSymbol",
            json!({"textDocument": {"uri": u}}),
        );
        assert!(r.get("error").is_none(), "{r}");
        let r = c.request(
            "textDocument/formatting",
            json!({"textDocument": {"uri": u}, "options": {"tabSize": 2, "insertSpaces": true}}),
        );
        assert!(
            r.get("result").is_some() || r["error"]["code"] == -32803,
            "{r}"
        );
        c.notify("textDocument/didClose", json!({"textDocument": {"uri": u}}));
    }
    // Requests on documents never opened.
    let r = c.request("textDocument/hover", at("file:///nowhere/x.sl", 0, 0));
    assert!(r["result"].is_null(), "{r}");
    // Still alive and answering.
    let r = c.request("shutdown", Value::Null);
    assert!(r.get("error").is_none(), "{r}");
    let r = c.request("textDocument/hover", at("file:///x.sl", 0, 0));
    assert_eq!(r["error"]["code"], -32600, "after shutdown: {r}");
    c.notify("exit", Value::Null);
    assert_eq!(c.child.wait().unwrap().code(), Some(0));
}

#[test]
fn end_of_input_without_exit_ends_the_server() {
    let (_guard, dir) = tmpdir("eof");
    let mut c = Client::start(&dir);
    c.request("initialize", json!({"capabilities": {}}));
    drop(c.stdin);
    assert_eq!(c.child.wait().unwrap().code(), Some(1));
}
