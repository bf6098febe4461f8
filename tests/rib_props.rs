//! Property tests: `parse(format(x)) == x`, and no input makes the reader panic.

use arbor::diag::{Diagnostics, SourceMap, Span};
use arbor::rib::{format_requests, parse_bytes, Arg, Request, Value};
use proptest::prelude::*;

fn float() -> impl Strategy<Value = f32> {
    use proptest::num::f32;
    f32::NORMAL | f32::SUBNORMAL | f32::ZERO | f32::INFINITE
}

fn value() -> impl Strategy<Value = Value> {
    prop_oneof![
        any::<i64>().prop_map(Value::Int),
        float().prop_map(Value::Float),
        any::<String>().prop_map(Value::Str),
        proptest::collection::vec(any::<i64>(), 0..8).prop_map(Value::IntArray),
        proptest::collection::vec(float(), 1..8).prop_map(Value::FloatArray),
        proptest::collection::vec(any::<String>(), 1..4).prop_map(Value::StrArray),
    ]
}

fn request() -> impl Strategy<Value = Request> {
    (
        // `nan`, `inf` and `infinity` (any case) are numbers in RIB (C's printf of values that
        // are not finite), not request names.
        "[A-Za-z_][A-Za-z0-9_]{0,12}".prop_filter("a number word", |n| {
            !matches!(n.to_ascii_lowercase().as_str(), "nan" | "inf" | "infinity")
        }),
        proptest::collection::vec(value(), 0..6),
    )
        .prop_map(|(name, vals)| Request {
            name,
            span: Span::default(),
            args: vals
                .into_iter()
                .map(|value| Arg {
                    value,
                    span: Span::default(),
                })
                .collect(),
        })
}

fn read(bytes: &[u8]) -> (Vec<Request>, Diagnostics, SourceMap) {
    let sm = SourceMap::new();
    let d = Diagnostics::new();
    let r = parse_bytes("p.rib", bytes, &sm, &d);
    (r, d, sm)
}

fn strip(r: &[Request]) -> Vec<(String, Vec<Value>)> {
    r.iter()
        .map(|r| {
            (
                r.name.clone(),
                r.args.iter().map(|a| a.value.clone()).collect(),
            )
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn format_then_parse_is_identity(reqs in proptest::collection::vec(request(), 0..12)) {
        let text = format_requests(&reqs);
        let (back, d, sm) = read(text.as_bytes());
        prop_assert!(!d.has_errors(), "{}\n{}", text, d.render_plain(&sm));
        prop_assert_eq!(strip(&back), strip(&reqs));
    }

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        let (r, d, sm) = read(&bytes);
        let len = sm.get(0).map(|f| f.text.len()).unwrap_or(0) as u32;
        for q in &r {
            prop_assert!(q.full_span().end <= len);
        }
        let _ = d.render_plain(&sm);
    }

    #[test]
    fn random_rib_like_text_never_panics(text in "[A-Za-z0-9 \"\\\\\\[\\]#.+eE\n-]{0,300}") {
        let (r, d, sm) = read(text.as_bytes());
        for q in &r {
            prop_assert!(q.full_span().end as usize <= text.len());
        }
        let _ = d.render_plain(&sm);
    }
}
