//! Property test: any sequence of known requests with arbitrary arguments builds without
//! panicking (bad input only ever yields diagnostics).

use arbor::diag::{Diagnostics, SourceMap, Span};
use arbor::rib::{Arg, Request, Value};
use arbor::scene::{build_scenes, table, BuildContext};
use proptest::prelude::*;

fn value() -> impl Strategy<Value = Value> {
    prop_oneof![
        (-5i64..400).prop_map(Value::Int),
        (-3.0f32..400.0).prop_map(Value::Float),
        prop::sample::select(vec![
            "P",
            "Cs",
            "st",
            "varying float x",
            "uniform color Kd",
            "bicubic",
            "periodic",
            "catmull-clark",
            "bezier",
            "outside",
            "$Frame == 1",
            "foo",
            "float[2] q",
            "",
        ])
        .prop_map(|s| Value::Str(s.to_string())),
        prop::collection::vec(-2i64..6, 0..20).prop_map(Value::IntArray),
        prop::collection::vec(-2.0f32..6.0, 0..40).prop_map(Value::FloatArray),
        prop::collection::vec(Just("hole".to_string()), 0..3).prop_map(Value::StrArray),
    ]
}

fn request() -> impl Strategy<Value = Request> {
    let names: Vec<&'static str> = table::names().collect();
    (
        prop::sample::select(names),
        prop::collection::vec(value(), 0..8),
    )
        .prop_map(|(n, vals)| Request {
            name: n.to_string(),
            span: Span::new(0, 0, 1),
            args: vals
                .into_iter()
                .map(|value| Arg {
                    value,
                    span: Span::new(0, 0, 1),
                })
                .collect(),
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]
    #[test]
    fn arbitrary_requests_never_panic(mut reqs in prop::collection::vec(request(), 0..40)) {
        // Put most of them inside a world block so geometry paths run.
        let world = |n: &str| Request { name: n.into(), span: Span::new(0, 0, 1), args: vec![] };
        reqs.insert(0, world("WorldBegin"));
        reqs.push(world("WorldEnd"));
        let sources = SourceMap::new();
        sources.add("p.rib", "x");
        let diags = Diagnostics::new();
        let ctx = BuildContext::new(&sources, &diags);
        let scenes = build_scenes(reqs, &ctx);
        prop_assert!(scenes.len() <= 41);
        let _ = diags.render_plain(&sources);
    }
}
