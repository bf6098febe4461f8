//! Rendered diagnostics (plain text, fixed width) of malformed scenes: each mistake gives one
//! clear diagnostic with file, line, column, a label and a help line.

use arbor::diag::{Diagnostics, SourceMap};
use arbor::rib::parse_bytes;
use arbor::scene::{build_scenes, BuildContext};

fn render(text: &str) -> String {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let reqs = parse_bytes("scene.rib", text.as_bytes(), &sources, &diags);
    let ctx = BuildContext::new(&sources, &diags);
    let _ = build_scenes(reqs, &ctx);
    diags.render_plain(&sources)
}

#[test]
fn unknown_request() {
    insta::assert_snapshot!(render(
        "WorldBegin\n  AttributeBegin\n    Sphree 1 -1 1 360\n  AttributeEnd\nWorldEnd\n"
    ));
}

#[test]
fn wrong_positional_arguments() {
    insta::assert_snapshot!(render("WorldBegin\nCylinder 1 0 \"tall\" 360\nWorldEnd\n"));
}

#[test]
fn undeclared_primitive_variable() {
    insta::assert_snapshot!(render(
        "WorldBegin\nSphere 1 -1 1 360 \"temperature\" [1 2 3 4]\nWorldEnd\n"
    ));
}

#[test]
fn wrong_value_count() {
    insta::assert_snapshot!(render(
        "WorldBegin\nPolygon \"P\" [0 0 0  1 0 0  1 1 0  0 1 0]\n        \"Cs\" [1 0 0  0 1 0  0 0 1]\nWorldEnd\n"
    ));
}

#[test]
fn unbalanced_blocks() {
    insta::assert_snapshot!(render(
        "WorldBegin\nAttributeBegin\n  TransformBegin\n    Sphere 1 -1 1 360\nAttributeEnd\nAttributeEnd\nWorldEnd\n"
    ));
}

#[test]
fn unclosed_block() {
    insta::assert_snapshot!(render("WorldBegin\nAttributeBegin\nSphere 1 -1 1 360\n"));
}

#[test]
fn unimplemented_request_warns_once() {
    insta::assert_snapshot!(render(
        "WorldBegin\nGeometricRepresentation \"lines\"\nGeometricRepresentation \"points\"\nWorldEnd\n"
    ));
}

#[test]
fn light_without_handle() {
    insta::assert_snapshot!(render(
        "WorldBegin\nLightSource \"pointlight\" \"intensity\" 5\nWorldEnd\n"
    ));
}

#[test]
fn a_very_long_line_is_quoted_as_a_window_around_the_label() {
    // Exporters write a request's sixty parameters on one line; a report shows the part
    // around its label, with the file's own line and column.
    let pad: String = (0..80).map(|i| format!("\"float p{i}\" [{i}] ")).collect();
    let line = format!("Sphere 1 -1 1 360 {pad}\"temperature\" [1 2 3 4] {pad}");
    let col = line.find("\"temperature\"").unwrap() + 1;
    let out = render(&format!("WorldBegin\n{line}\nWorldEnd\n"));
    assert!(out.contains(&format!("scene.rib:2:{col}")), "{out}");
    assert!(out.contains("\"temperature\" [1 2 3 4]"), "{out}");
    assert!(out.contains('…'), "{out}");
    assert!(
        out.contains(" 1 │ WorldBegin") && out.contains(" 3 │ WorldEnd"),
        "{out}"
    );
    let widest = out.lines().map(|l| l.chars().count()).max().unwrap_or(0);
    assert!(widest < 200, "a line of {widest} characters:\n{out}");
}

// Found by fuzzing (fuzz3): thousands of `AttributeBegin`s without their ends gave an error
// each (5000 took half a minute to print). The innermost eight are reported one by one, the
// rest together at the outermost.
#[test]
fn many_blocks_closed_at_once() {
    let text = format!(
        "WorldBegin\n{}Sphere 1 -1 1 360\nWorldEnd\n",
        "AttributeBegin\n".repeat(11) + "TransformBegin\n"
    );
    insta::assert_snapshot!(render(&text));
}

#[test]
fn many_blocks_never_closed() {
    let text = format!(
        "WorldBegin\n{}Sphere 1 -1 1 360\n",
        "AttributeBegin\nTransformBegin\n".repeat(6)
    );
    insta::assert_snapshot!(render(&text));
}

#[test]
fn an_absurd_area_light_sample_count_is_held_with_a_warning() {
    // Found by fuzzing (fuzz3): 2^31 samples, silently held at 4096, took minutes at 64x48.
    let out = render(
        "WorldBegin\nAttribute \"light\" \"nsamples\" [2147483648]\n\
         AreaLightSource \"arealight\" 1\nSphere 1 -1 1 360\nWorldEnd\n",
    );
    assert!(out.contains("is held at 1024"), "{out}");
    assert!(out.contains("scene.rib:3:1"), "{out}");
}
