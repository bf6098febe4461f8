//! Blobby implicit surfaces through the whole pipeline: a lone blob is the sphere of radius
//! ½ in its matrix's space, two blobs merge with a filled neck, a subtract operator carves,
//! and bad code arrays are diagnosed.

mod common;

use arbor::film::Film;

const N: usize = 60;
const PIX: f32 = 3.0 / N as f32;

fn render_report(world: &str) -> (Vec<Film>, String, bool) {
    let text = format!(
        "Format {N} {N} 1\nPixelSamples 4 4\nPixelFilter \"box\" 1 1\nProjection \"orthographic\"\n\
         ScreenWindow -1.5 1.5 -1.5 1.5\nTranslate 0 0 5\nWorldBegin\nSurface \"constant\"\n{world}WorldEnd\n"
    );
    common::render_text_report(&text)
}

fn render(world: &str) -> Film {
    let (f, report, errors) = render_report(world);
    assert!(!errors, "{report}");
    assert!(!report.contains("not implemented"), "{report}");
    f.into_iter().next().expect("one film")
}

fn centre(i: usize, j: usize) -> (f32, f32) {
    (-1.5 + (i as f32 + 0.5) * PIX, 1.5 - (j as f32 + 0.5) * PIX)
}

/// A blob's matrix: uniform scale `s` about (x, y, z), as RIB writes it.
fn blob(s: f32, x: f32, y: f32, z: f32) -> String {
    format!("{s} 0 0 0 0 {s} 0 0 0 0 {s} 0 {x} {y} {z} 1 ")
}

/// Covered pixels lie within one pixel of where `sdf` < 0, empty ones within one pixel of
/// where it is > 0.
fn check_silhouette(f: &Film, sdf: impl Fn(f32, f32) -> f32) {
    let mut inside = 0;
    for j in 0..N {
        for i in 0..N {
            let (x, y) = centre(i, j);
            let d = sdf(x, y);
            let a = f.pixel(i, j)[3];
            if d < -PIX {
                assert!(
                    a > 0.99,
                    "pixel ({i},{j}) at ({x:.3},{y:.3}) should be covered: {a}"
                );
                inside += 1;
            } else if d > PIX {
                assert!(
                    a < 0.01,
                    "pixel ({i},{j}) at ({x:.3},{y:.3}) should be empty: {a}"
                );
            }
        }
    }
    assert!(inside > 50);
}

#[test]
fn a_lone_blob_matches_a_sphere() {
    let f = render(&format!(
        "Blobby 1 [1001 0] [{}] [\"\"]\n",
        blob(2.0, 0.1, -0.2, 0.0)
    ));
    check_silhouette(&f, |x, y| {
        ((x - 0.1).powi(2) + (y + 0.2).powi(2)).sqrt() - 1.0
    });
    // The same as Sphere 1 there, pixel for pixel, up to the silhouette's pixels.
    let s = render("Translate 0.1 -0.2 0\nSphere 1 -1 1 360\n");
    let mut differ = 0;
    for j in 0..N {
        for i in 0..N {
            let (a, b) = (f.pixel(i, j)[3], s.pixel(i, j)[3]);
            if (a - b).abs() > 0.15 {
                differ += 1;
            }
        }
    }
    assert!(
        differ <= 4,
        "{differ} pixels differ from the sphere's coverage"
    );
    // Depth at the centre: the sphere's front, 5 − 1.
    let z = f.pixel(N / 2 + 2, N / 2 + 4)[4];
    assert!((z - 4.0).abs() < 0.03, "{z}");
}

#[test]
fn two_blobs_merge_with_a_filled_neck() {
    let f = render(&format!(
        "Blobby 2 [1001 0 1001 16 0 2 0 1] [{}{}] [\"\"]\n",
        blob(2.0, -0.6, 0.0, 0.0),
        blob(2.0, 0.6, 0.0, 0.0)
    ));
    // Field on the plane z = 0: the sum of (1 − r²/4)³ of the two; the neck at x = 0 has
    // half-width y with 2(1 − (0.36 + y²)/4)³ = 27/64.
    let t = 0.421875f32;
    let neck = (4.0 * (1.0 - (t / 2.0).cbrt()) - 0.36).sqrt();
    assert!((neck - 1.12).abs() < 0.01);
    // Silhouette (orthographic along z): where the field's maximum over z exceeds t, which
    // for two equal blobs in the z = 0 plane is at z = 0.
    let field = |x: f32, y: f32| {
        let f1 = (1.0 - ((x + 0.6).powi(2) + y * y) / 4.0).max(0.0).powi(3);
        let f2 = (1.0 - ((x - 0.6).powi(2) + y * y) / 4.0).max(0.0).powi(3);
        f1 + f2
    };
    // Signed distance approximated by the field's slope (about 1.0 per unit near the surface).
    let sdf = |x: f32, y: f32| {
        let (d, h) = (field(x, y) - t, 1e-3);
        let g = ((field(x + h, y) - field(x - h, y)).powi(2)
            + (field(x, y + h) - field(x, y - h)).powi(2))
        .sqrt()
            / (2.0 * h);
        -d / g.max(1e-3)
    };
    check_silhouette(&f, sdf);
    let (i, j) = (N / 2, ((1.5 - 0.95 * neck) / PIX) as usize);
    assert!(
        f.pixel(i, j)[3] > 0.99,
        "the neck is filled at y = {}",
        0.95 * neck
    );
}

#[test]
fn a_subtract_operator_carves() {
    let floats = format!("{}{}", blob(2.0, 0.0, 0.0, 0.0), blob(1.4, 0.8, 0.0, 0.0));
    let whole = render(&format!(
        "Blobby 2 [1001 0 1001 16 0 1 0] [{floats}] [\"\"]\n"
    ));
    let carved = render(&format!(
        "Blobby 2 [1001 0 1001 16 4 0 1] [{floats}] [\"\"]\n"
    ));
    let px = |x: f32| (((x + 1.5) / PIX) as usize, N / 2);
    let (i, j) = px(0.8);
    assert!(whole.pixel(i, j)[3] > 0.99);
    assert!(carved.pixel(i, j)[3] < 0.01, "{:?}", carved.pixel(i, j));
    let (i, j) = px(-0.5);
    assert!(carved.pixel(i, j)[3] > 0.99);
}

#[test]
fn bad_code_arrays_are_diagnosed() {
    let (_, report, errors) = render_report(&format!(
        "Blobby 1 [1001 0 0 2 0 3] [{}] [\"\"]\n",
        blob(1.0, 0.0, 0.0, 0.0)
    ));
    assert!(errors);
    assert!(report.contains("not an earlier instruction"), "{report}");
    let (_, report, errors) = render_report("Blobby 1 [1001 4] [1 2 3] [\"\"]\n");
    assert!(errors);
    assert!(report.contains("reads 16 floats from index 4"), "{report}");
    let (_, report, _) = render_report(&format!(
        "Blobby 2 [1001 0 1003 0 16 0 2 0 1] [{} 1 1 1 1] [\"ground.zfile\"]\n",
        blob(2.0, 0.0, 0.0, 0.0)
    ));
    assert!(report.contains("ground.zfile"), "{report}");
}

#[test]
fn prman_application_note_blobs_render_as_written() {
    // Pixar's Blobby application-note scenes as Aqsis ships them (`check.rib`, `blend.rib`,
    // Air's `blobplane.rib`): `Imager` inside the world block, a per-blob "vertex mpoint
    // Pref", one `"color Cs"` for three blobs, and a field plug-in (opcode 9000) arbor cannot
    // load. All render, with warnings only.
    let world = format!(
        "Imager \"background\" \"color\" [1 1 1]\n\
         Blobby 3 [1001 0 1001 16 9000 2 0 32 0 3 0 1 2] [{} {} {}] [\"dbo_plane\"]\n\
         \"vertex mpoint Pref\" [{} {} {}]\n\
         \"color Cs\" [0.1 0.9 0.2]\n",
        blob(1.0, -0.3, 0.0, 0.0),
        blob(1.0, 0.3, 0.0, 0.0),
        blob(1.0, 5.0, 5.0, 0.0),
        blob(1.0, -0.3, 0.0, 0.0),
        blob(1.0, 0.3, 0.0, 0.0),
        blob(1.0, 0.0, 0.0, 0.0),
    );
    let (films, report, errors) = render_report(&world);
    assert!(!errors, "{report}");
    assert!(report.contains("`dbo_plane`"), "{report}");
    assert!(report.contains("read as constant"), "{report}");
    assert!(!report.contains("has no effect"), "{report}");
    let f = &films[0];
    // The blob is Cs (the background imager is applied when the display is written; see
    // scene_build's `an_imager_inside_the_world_sets_the_frames_imager`).
    let mid = f.pixel(N / 2, N / 2);
    for (got, want) in mid[..3].iter().zip([0.1, 0.9, 0.2]) {
        assert!((got - want).abs() < 1e-3, "{mid:?}");
    }
}
