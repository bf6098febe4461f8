//! Level of detail (RISpec §4.2.9): of a model's representations, the one whose
//! `DetailRange` holds the raster area of its `Detail` box is drawn, and only that one
//! (Aqsis's `levelofdetail/detail.rib` drew all three spheres on top of each other).

mod common;

use arbor::film::Film;

/// A unit-radius model at distance `z` in front of a 90° camera on a 100×100 picture, drawn
/// red, green or blue depending on its detail, as Aqsis's example writes the ranges.
fn render(z: f32, relative: f32) -> (Film, String) {
    let text = format!(
        "Format 100 100 1\nPixelSamples 2 2\nProjection \"perspective\" \"fov\" 90\n\
         RelativeDetail {relative}\nWorldBegin\nSurface \"constant\"\nTranslate 0 0 {z}\n\
         AttributeBegin\nDetail [-1 1 -1 1 -1 1]\n\
         DetailRange [0 0 20 30]\nColor [0 0 1]\nSphere 1 -1 1 360\n\
         DetailRange [20 30 500 600]\nColor [0 1 0]\nSphere 1 -1 1 360\n\
         DetailRange [500 600 1e+38 1e+38]\nColor [1 0 0]\nSphere 1 -1 1 360\n\
         AttributeEnd\nWorldEnd\n"
    );
    let (films, report, errors) = common::render_text_report(&text);
    assert!(!errors, "{report}");
    (films.into_iter().next().expect("a film"), report)
}

/// Which channel the centre pixel shows; the others must be exactly 0 (only one
/// representation drawn).
fn centre(f: &Film) -> usize {
    let p = f.pixel(f.width / 2, f.height / 2);
    let lit: Vec<usize> = (0..3).filter(|&c| p[c] > 0.0).collect();
    assert_eq!(lit.len(), 1, "{:?}", &p[..3]);
    assert!(p[lit[0]] > 0.2, "{:?}", &p[..3]);
    lit[0]
}

#[test]
fn the_representation_in_range_is_the_only_one_drawn() {
    // The box's front face (z - 1 from the eye) spans 2 / (z - 1) of the screen's half-width
    // (1 at 90°): 100 · (1 / (z - 1)) pixels wide, so its area is about (100 / (z - 1))².
    // z = 3: ~2500 px, above 600 → red, alone (no green or blue mixed in).
    let (f, report) = render(3.0, 1.0);
    assert!(!report.contains("not implemented"), "{report}");
    assert_eq!(centre(&f), 0);
    // z = 11: ~100 px → green.
    assert_eq!(centre(&render(11.0, 1.0).0), 1);
    // z = 41: ~6 px → blue.
    assert_eq!(centre(&render(41.0, 1.0).0), 2);
    // RelativeDetail scales the detail: z = 11 at 1/10 (~10 px) is blue.
    assert_eq!(centre(&render(11.0, 0.1).0), 2);
}
