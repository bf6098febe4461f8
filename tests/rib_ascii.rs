//! ASCII RIB reader: snapshot of a RenderMan-Companion-style scene, number forms, escapes,
//! and diagnostics for malformed input.

use arbor::diag::{Diagnostics, SourceMap};
use arbor::rib::{parse_bytes, Request, Value};

fn parse(text: &str) -> (Vec<Request>, Diagnostics, SourceMap) {
    let sm = SourceMap::new();
    let d = Diagnostics::new();
    let r = parse_bytes("scene.rib", text.as_bytes(), &sm, &d);
    (r, d, sm)
}

/// One line per request: name, then each argument's value and its `line:col`.
fn dump(reqs: &[Request], sm: &SourceMap) -> String {
    let mut s = String::new();
    for r in reqs {
        let (l, c) = sm.line_col(r.span);
        s.push_str(&format!("{l}:{c} {}", r.name));
        for a in &r.args {
            s.push_str(&format!(" {:?}", a.value));
        }
        s.push('\n');
    }
    s
}

const COMPANION: &str = r#"##RenderMan RIB-Structure 1.1
##Scene "Companion teapot"
##Creator hand
##CapabilitiesNeeded ShadingLanguage
version 3.03
Declare "Kd" "uniform float"
Declare "txname" "uniform string"
Option "searchpath" "shader" [".:&"]
Display "teapot.tif" "file" "rgba"
Format 320 240 -1
PixelSamples 2 2
Projection "perspective" "fov" [45]
FrameBegin 1
  Translate 0 -.5 5.
  Rotate -110 1 0 0
  WorldBegin
    LightSource "ambientlight" 1 "intensity" [0.2]
    LightSource "distantlight" 2 "intensity" 1.2 "from" [0 0 -6] "to" [0 0 0]
    AttributeBegin
      Color [1 .5 .25]
      Surface "plastic" "uniform float Kd" [.8] "Ks" 1e-1 "txname" "wood\101\ttab\"q\"\\"
      Polygon "P" [0 0 0  1 0 0  1 1 0  0 1 0] "varying color Cs" [1 0 0 0 1 0 0 0 1 1 1 1]
      PointsPolygons [3 3] [0 1 2 0 2 3] "P" [-2.5E+4 0 0 1 0 0 1 1 0 0 1 0]
      Attribute "identifier" "name" ["teapot"] # trailing comment
      Sphere 1 -1 1 360
    AttributeEnd
  WorldEnd
FrameEnd
"#;

#[test]
fn companion_scene_snapshot() {
    let (r, d, sm) = parse(COMPANION);
    assert!(!d.has_errors(), "{}", d.render_plain(&sm));
    assert_eq!(r.len(), 24);
    insta::assert_snapshot!(dump(&r, &sm));
}

#[test]
fn every_number_form() {
    let (r, d, _) = parse("N 1 -1 +1 .5 -.5 1. 1e-3 -2.5E+4 1.5e2 0 007");
    assert!(!d.has_errors());
    let v: Vec<Value> = r[0].args.iter().map(|a| a.value.clone()).collect();
    assert_eq!(
        v,
        [
            Value::Int(1),
            Value::Int(-1),
            Value::Int(1),
            Value::Float(0.5),
            Value::Float(-0.5),
            Value::Float(1.0),
            Value::Float(1e-3),
            Value::Float(-2.5e4),
            Value::Float(150.0),
            Value::Int(0),
            Value::Int(7),
        ]
    );
    // An array with any real is a float array; integers alone stay integers.
    let (r, _, _) = parse("A [1 2 3] [1 2. 3] [1e0] []");
    assert_eq!(r[0].args[0].value, Value::IntArray(vec![1, 2, 3]));
    assert_eq!(r[0].args[1].value, Value::FloatArray(vec![1.0, 2.0, 3.0]));
    assert_eq!(r[0].args[2].value, Value::FloatArray(vec![1.0]));
    assert_eq!(r[0].args[3].value, Value::IntArray(vec![]));
}

#[test]
fn every_escape() {
    let text = "S \"n\\n r\\r t\\t b\\b f\\f bs\\\\ q\\\" o\\101\\60\\7 cont\\\nx other\\q\"";
    let (r, d, _) = parse(text);
    assert!(!d.has_errors());
    assert_eq!(
        r[0].args[0].value,
        Value::Str("n\n r\r t\t b\u{8} f\u{C} bs\\ q\" oA0\u{7} contx otherq".into())
    );
}

#[test]
fn structure_comments_are_comments() {
    let (r, d, _) =
        parse("##RenderMan RIB-Structure 1.1\n##Include foo\n# plain\nWorldBegin # x\n");
    assert!(!d.has_errors());
    assert_eq!(r.len(), 1);
    assert_eq!(r[0].name, "WorldBegin");
}

#[test]
fn malformed_input_diagnostics_snapshot() {
    // A bad token inside a request's arguments costs that request (and only it).
    let text = "WorldBegin\nSphere 1 -1 1 @ 360\nColor [1 0 0\nSurface \"plastic\" \"Kd\" [.5 \"x\"]\nCone 1 1 360\nDisk 0 1 360 \"unclosed\nAttributeBegin ]\nWorldEnd\n";
    let (r, d, sm) = parse(text);
    let names: Vec<&str> = r.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(names, ["WorldBegin", "Cone", "WorldEnd"]);
    assert_eq!(d.error_count(), 5);
    insta::assert_snapshot!(d.render_plain(&sm));
}

#[test]
fn never_panics_on_garbage() {
    let samples: [&[u8]; 8] = [
        b"\"",
        b"[",
        b"]]]]",
        b"\\",
        b"A [ \"",
        b"#",
        "é \"é\" [é] Zé".as_bytes(),
        b"A 1e 1e+ .e5 -. +",
    ];
    for s in samples {
        let sm = SourceMap::new();
        let d = Diagnostics::new();
        let _ = parse_bytes("g.rib", s, &sm, &d);
        let _ = d.render_plain(&sm);
    }
}
