//! Binary RIB (RISpec C.1), binary/ASCII interleaving, and gzip input.

use std::io::Write;

use arbor::diag::{Diagnostics, SourceMap};
use arbor::rib::{parse_bytes, Request, Value};

fn parse(bytes: &[u8]) -> (Vec<Request>, Diagnostics, SourceMap) {
    let sm = SourceMap::new();
    let d = Diagnostics::new();
    let r = parse_bytes("bin.rib", bytes, &sm, &d);
    (r, d, sm)
}

fn values(r: &Request) -> Vec<Value> {
    r.args.iter().map(|a| a.value.clone()).collect()
}

/// A binary stream built by hand from the C.1 table, with ASCII interleaved.
fn sample() -> Vec<u8> {
    let mut b = Vec::new();
    // 0314 1 "Sphere" (short string 0220+6), then 0246 1 calls it.
    b.extend_from_slice(&[0o314, 1, 0o226]);
    b.extend_from_slice(b"Sphere");
    b.extend_from_slice(&[0o246, 1]);
    // 0200: 1-byte int 1; 0200 0377: -1; 0244: float32 0.5; 0201: 2-byte int 360.
    b.extend_from_slice(&[0o200, 1, 0o200, 0xFF, 0o244]);
    b.extend_from_slice(&0.5f32.to_be_bytes());
    b.extend_from_slice(&[0o201, 0x01, 0x68]);
    // ASCII request with binary arguments mixed in.
    b.extend_from_slice(b"\nColor ");
    b.extend_from_slice(&[0o310, 3]); // 0310: float array, 1-byte count 3
    for f in [1.0f32, 0.25, -2.0] {
        b.extend_from_slice(&f.to_be_bytes());
    }
    // 0315 0 "plastic": define string token 0; 0317 0 uses it.
    b.extend_from_slice(&[0o315, 0, 0o227]);
    b.extend_from_slice(b"plastic");
    b.extend_from_slice(b"\nSurface ");
    b.extend_from_slice(&[0o317, 0]);
    // 0240: long string with a 1-byte length; 0245: float64; 0206: 3-byte fixed point b.bb? no:
    // 0205 = d=1, w=1: two bytes, one after the point: 0x0280 = 2.5.
    let long = "a string longer than fifteen bytes";
    b.extend_from_slice(&[0o240, long.len() as u8]);
    b.extend_from_slice(long.as_bytes());
    b.push(0o245);
    b.extend_from_slice(&0.125f64.to_be_bytes());
    b.extend_from_slice(&[0o205, 0x02, 0x80]);
    // An ASCII array of binary numbers, and a string holding a byte >= 0200 as text.
    b.extend_from_slice(b" [");
    b.extend_from_slice(&[0o200, 7, 0o200, 8]);
    b.extend_from_slice("] \"caf\u{e9}\"\nWorldEnd\n".as_bytes());
    b
}

#[test]
fn binary_tokens_decode_to_requests() {
    let (r, d, sm) = parse(&sample());
    assert!(!d.has_errors(), "{}", d.render_plain(&sm));
    let names: Vec<&str> = r.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(names, ["Sphere", "Color", "Surface", "WorldEnd"]);
    assert_eq!(
        values(&r[0]),
        [
            Value::Int(1),
            Value::Int(-1),
            Value::Float(0.5),
            Value::Int(360)
        ]
    );
    assert_eq!(values(&r[1]), [Value::FloatArray(vec![1.0, 0.25, -2.0])]);
    assert_eq!(
        values(&r[2]),
        [
            Value::Str("plastic".into()),
            Value::Str("a string longer than fifteen bytes".into()),
            Value::Float(0.125),
            Value::Float(2.5),
            Value::IntArray(vec![7, 8]),
            Value::Str("café".into()),
        ]
    );
    // Spans point into the registered (decoded) text.
    assert_eq!(sm.snippet(r[1].span), "Color");
}

#[test]
fn undefined_code_loses_one_request() {
    let mut b = b"A 1\n".to_vec();
    b.extend_from_slice(&[0o246, 9, 0o200, 1]);
    b.extend_from_slice(b"\nB 2\n");
    let (r, d, sm) = parse(&b);
    let names: Vec<&str> = r.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(names, ["A", "B"]);
    assert_eq!(d.error_count(), 1, "{}", d.render_plain(&sm));
    let diags = d.snapshot();
    assert_eq!(diags[0].0.code, "rib::binary");
    assert!(diags[0].0.message.contains("never defined"));
}

#[test]
fn reserved_byte_and_truncation_are_errors() {
    let (_, d, _) = parse(&[b'A', b' ', 0o250, b'\n', b'B', b' ', 0o244, 0x3F]);
    let msgs: Vec<String> = d.snapshot().iter().map(|x| x.0.message.clone()).collect();
    assert_eq!(msgs.len(), 2, "{msgs:?}");
    assert!(msgs[0].contains("reserved"));
    assert!(msgs[1].contains("ends inside"));
}

fn gzip(data: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(data).unwrap();
    e.finish().unwrap()
}

#[test]
fn gzip_ascii_and_binary() {
    let ascii = b"WorldBegin\nSphere 1 -1 1 360\nWorldEnd\n";
    let (plain, _, _) = parse(ascii);
    let (zipped, d, _) = parse(&gzip(ascii));
    assert!(!d.has_errors());
    assert_eq!(plain, zipped);
    let (zb, d, _) = parse(&gzip(&sample()));
    assert!(!d.has_errors());
    assert_eq!(zb.len(), 4);
}

#[test]
fn corrupt_gzip_is_an_error() {
    let mut z = gzip(b"WorldBegin\n");
    z.truncate(12);
    let (r, d, _) = parse(&z);
    assert!(r.is_empty());
    assert_eq!(d.snapshot()[0].0.code, "rib::gzip");
}

#[test]
fn binary_diagnostics_snapshot() {
    let mut b = b"WorldBegin\n".to_vec();
    b.extend_from_slice(&[0o246, 9, 0o200, 1, b'\n']);
    b.extend_from_slice(b"Sphere 1 ");
    b.extend_from_slice(&[0o317, 4]);
    b.extend_from_slice(b"\nWorldEnd\n");
    let (r, d, sm) = parse(&b);
    let names: Vec<&str> = r.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(names, ["WorldBegin", "WorldEnd"]);
    assert_eq!(d.error_count(), 2);
    insta::assert_snapshot!(d.render_plain(&sm));
}
