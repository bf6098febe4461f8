//! The camera: projection and the named coordinate systems of a frame.
//!
//! Input: a built [`crate::scene::Scene`]. Output: the transforms between camera space and
//! screen, NDC and raster space, and every named space shaders may ask for.
//! Invariants: camera space is RenderMan's left-handed space (+z into the screen); "current"
//! space, where grids are shaded, is camera space.

use std::collections::HashMap;

use glam::{Mat4, Vec3, Vec4};

use crate::diag::{Diag, Diagnostics};
use crate::scene::{Options, Projection, Scene};

/// The transforms of one frame. Matrices map column vectors (`m * p`), composed right to left.
#[derive(Clone, Debug)]
pub struct Camera {
    pub camera_from_world: Mat4,
    pub screen_from_camera: Mat4,
    pub ndc_from_screen: Mat4,
    pub raster_from_screen: Mat4,
    /// Perspective (true) or orthographic projection.
    pub perspective: bool,
    pub near: f32,
    pub far: f32,
    /// Image size in pixels.
    pub xres: u32,
    pub yres: u32,
    /// camera_from_named for every CoordinateSystem of the scene plus "world".
    pub named: HashMap<String, Mat4>,
    /// DepthOfField as a thin lens (None: a pinhole, including an infinite f-stop).
    pub dof: Option<Dof>,
}

/// A thin lens (RISpec §4.1.1 DepthOfField). Seen from lens point `L` (in the unit disk,
/// scaled by the aperture radius `R = focallength / (2 fstop)`), a point at camera depth `z`
/// appears in screen space at its pinhole position minus `R·L·(1/z − 1/focaldistance)`:
/// points on the focal plane stay put, the others spread over a circle of confusion whose
/// diameter, as an angle, is `(focallength / fstop)·|1/z − 1/focaldistance|`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dof {
    /// 1 / focaldistance.
    pub inv_focus: f32,
    /// Raster shift per unit of lens position per unit of (1/focaldistance − 1/z), in x and y
    /// (the aperture radius times raster pixels per unit of x/z).
    pub raster_k: [f32; 2],
    /// The same in screen units.
    pub screen_k: [f32; 2],
}

impl Dof {
    /// The circle-of-confusion radius factor |1/F − 1/z| for depths in [z0, z1] (infinite when
    /// the range reaches the eye).
    pub fn coc_factor(&self, z0: f32, z1: f32) -> f32 {
        if !(z0 > 0.0) {
            return f32::INFINITY;
        }
        let a = (self.inv_focus - 1.0 / z0).abs();
        let b = if z1.is_finite() {
            (self.inv_focus - 1.0 / z1).abs()
        } else {
            self.inv_focus
        };
        a.max(b)
    }
}

impl Camera {
    pub fn raster_from_camera(&self) -> Mat4 {
        self.raster_from_screen * self.screen_from_camera
    }
    /// camera_from_space for "camera"/"current" (and "eye"), "world", "screen", "NDC", "raster" and named
    /// coordinate systems ("object" and "shader" depend on the primitive and are handled by the
    /// shading context).
    pub fn camera_from_space(&self, name: &str) -> Option<Mat4> {
        match name {
            "camera" | "current" => Some(Mat4::IDENTITY),
            "world" => Some(self.camera_from_world),
            "screen" => Some(self.screen_from_camera.inverse()),
            "NDC" => Some((self.ndc_from_screen * self.screen_from_camera).inverse()),
            "raster" => Some(self.raster_from_camera().inverse()),
            // The RenderMan Companion's name for camera space (its slideprojector light and
            // the shaders built on it say `point "eye" (0,1,0)`); a scene's own "eye" wins.
            _ => self
                .named
                .get(name)
                .copied()
                .or_else(|| (name == "eye").then_some(Mat4::IDENTITY)),
        }
    }
}

/// A rectangle of whole pixels `[x0, x1) × [y0, y1)` in raster space.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PixelRect {
    pub x0: i32,
    pub y0: i32,
    pub x1: i32,
    pub y1: i32,
}

impl PixelRect {
    pub fn width(&self) -> usize {
        (self.x1 - self.x0).max(0) as usize
    }
    pub fn height(&self) -> usize {
        (self.y1 - self.y0).max(0) as usize
    }
    pub fn is_empty(&self) -> bool {
        self.x1 <= self.x0 || self.y1 <= self.y0
    }
    /// Grown by `mx`, `my` pixels on each side.
    pub fn grow(self, mx: i32, my: i32) -> PixelRect {
        PixelRect {
            x0: self.x0 - mx,
            y0: self.y0 - my,
            x1: self.x1 + mx,
            y1: self.y1 + my,
        }
    }
    pub fn intersect(self, o: PixelRect) -> PixelRect {
        PixelRect {
            x0: self.x0.max(o.x0),
            y0: self.y0.max(o.y0),
            x1: self.x1.min(o.x1),
            y1: self.y1.min(o.y1),
        }
    }
    pub fn contains(&self, x: i32, y: i32) -> bool {
        x >= self.x0 && x < self.x1 && y >= self.y0 && y < self.y1
    }
}

/// The pixels a crop window renders (RISpec §4.1.1): `xmin = clamp(ceil(xres·cxmin), 0, xres−1)`,
/// `xmax = clamp(ceil(xres·cxmax − 1), 0, xres−1)` (inclusive), likewise in y.
pub fn crop_region(xres: u32, yres: u32, crop: [f32; 4]) -> PixelRect {
    let clamp = |v: f32, res: u32| -> i32 { (v as i64).clamp(0, res.max(1) as i64 - 1) as i32 };
    let (xr, yr) = (xres as f32, yres as f32);
    let x0 = clamp((xr * crop[0]).ceil(), xres);
    let x1 = clamp((xr * crop[1] - 1.0).ceil(), xres);
    let y0 = clamp((yr * crop[2]).ceil(), yres);
    let y1 = clamp((yr * crop[3] - 1.0).ceil(), yres);
    PixelRect {
        x0,
        y0,
        x1: x1 + 1,
        y1: y1 + 1,
    }
}

impl Camera {
    /// The camera of a built scene (see [`Camera::from_options`]).
    pub fn new(scene: &Scene) -> Camera {
        Camera::from_options(
            &scene.options,
            scene.camera_from_world,
            &scene.coordinate_systems,
        )
    }

    /// Builds the frame's transforms from the options (RISpec §4.1.1):
    /// camera → screen by the projection (perspective: the image plane at z = 1 scaled so that
    /// `fov` spans [-1, 1], i.e. the shorter side of the default screen window), screen → NDC
    /// by the screen window ((0,0) top-left, y down), NDC → raster by the resolution.
    /// Degenerate values (fov outside (0°, 180°), an empty screen window) fall back to safe
    /// ones; [`check_options`] reports them.
    pub fn from_options(
        options: &Options,
        camera_from_world: Mat4,
        coordinate_systems: &HashMap<String, Mat4>,
    ) -> Camera {
        let near = if options.near > 0.0 {
            options.near
        } else {
            f32::EPSILON
        };
        let far = options.far.max(near);
        let (perspective, screen_from_camera) = match options.projection {
            Projection::Perspective { fov } => {
                let fov = if fov > 0.0 && fov < 180.0 { fov } else { 90.0 };
                let inv_t = 1.0 / (fov.to_radians() * 0.5).tan();
                // z_s = f (z − n) / ((f − n) z): 0 at the near plane, 1 at the far plane.
                let (a, b) = if far.is_finite() {
                    (
                        far / (far - near).max(f32::MIN_POSITIVE),
                        -far * near / (far - near).max(f32::MIN_POSITIVE),
                    )
                } else {
                    (1.0, -near)
                };
                let m = Mat4::from_cols(
                    Vec4::new(inv_t, 0.0, 0.0, 0.0),
                    Vec4::new(0.0, inv_t, 0.0, 0.0),
                    Vec4::new(0.0, 0.0, a, 1.0),
                    Vec4::new(0.0, 0.0, b, 0.0),
                );
                (true, m)
            }
            Projection::Orthographic => {
                let (a, b) = if far.is_finite() && far > near {
                    (1.0 / (far - near), -near / (far - near))
                } else {
                    (1.0, 0.0)
                };
                let m = Mat4::from_cols(
                    Vec4::new(1.0, 0.0, 0.0, 0.0),
                    Vec4::new(0.0, 1.0, 0.0, 0.0),
                    Vec4::new(0.0, 0.0, a, 0.0),
                    Vec4::new(0.0, 0.0, b, 1.0),
                );
                (false, m)
            }
        };
        let [l, r, bottom, top] = options.effective_screen_window();
        let w = if r != l { r - l } else { 1.0 };
        let h = if top != bottom { top - bottom } else { 1.0 };
        let ndc_from_screen = Mat4::from_cols(
            Vec4::new(1.0 / w, 0.0, 0.0, 0.0),
            Vec4::new(0.0, -1.0 / h, 0.0, 0.0),
            Vec4::new(0.0, 0.0, 1.0, 0.0),
            Vec4::new(-l / w, top / h, 0.0, 1.0),
        );
        let xres = options.xres.max(1);
        let yres = options.yres.max(1);
        let raster_from_ndc = Mat4::from_scale(Vec3::new(xres as f32, yres as f32, 1.0));
        let mut named: HashMap<String, Mat4> = coordinate_systems
            .iter()
            .map(|(k, world_from_named)| (k.clone(), camera_from_world * *world_from_named))
            .collect();
        named.insert("world".into(), camera_from_world);
        let raster_from_screen = raster_from_ndc * ndc_from_screen;
        let dof = match options.depth_of_field {
            Some([fstop, focallength, focaldistance])
                if perspective
                    && fstop.is_finite()
                    && fstop > 0.0
                    && focallength > 0.0
                    && focaldistance > 0.0 =>
            {
                let r = focallength / (2.0 * fstop);
                let screen_k = [
                    screen_from_camera.x_axis.x * r,
                    screen_from_camera.y_axis.y * r,
                ];
                let raster_k = [
                    raster_from_screen.x_axis.x * screen_k[0],
                    raster_from_screen.y_axis.y * screen_k[1],
                ];
                // Below a thousandth of a pixel at a thousand times the focal distance's
                // reciprocal the lens is a pinhole (`DepthOfField 1e38 …` in real scenes).
                let big = raster_k[0].abs().max(raster_k[1].abs()) * 1e3 / focaldistance;
                (big > 1e-3 && big.is_finite()).then_some(Dof {
                    inv_focus: 1.0 / focaldistance,
                    raster_k,
                    screen_k,
                })
            }
            _ => None,
        };
        Camera {
            camera_from_world,
            screen_from_camera,
            ndc_from_screen,
            raster_from_screen,
            perspective,
            near,
            far,
            xres,
            yres,
            named,
            dof,
        }
    }

    /// Raster x, y of a camera-space point and its camera-space depth z (meaningless for
    /// perspective points with z ≤ 0).
    pub fn project(&self, p: Vec3) -> Vec3 {
        let r = self.raster_from_camera().project_point3(p);
        Vec3::new(r.x, r.y, p.z)
    }
}

/// Reports camera options the renderer cannot honour as given (each once, as a warning).
pub fn check_options(options: &Options, diags: &Diagnostics) {
    if let Projection::Perspective { fov } = options.projection {
        if !(fov > 0.0 && fov < 180.0) {
            diags.report(
                Diag::warning(
                    "render::camera",
                    format!("perspective field of view {fov}° is outside (0°, 180°); using 90°"),
                )
                .help("`Projection \"perspective\" \"fov\" [45]` takes an angle in degrees"),
            );
        }
    }
    let [l, r, b, t] = options.effective_screen_window();
    if l == r || b == t {
        diags.report(Diag::warning(
            "render::camera",
            format!("ScreenWindow {l} {r} {b} {t} is empty; using a width/height of 1"),
        ));
    }
    if options.depth_of_field.is_some() && options.projection == Projection::Orthographic {
        diags.report(Diag::warning(
            "render::camera",
            "DepthOfField needs a perspective projection: the orthographic camera stays a pinhole",
        ));
    }
    if options.near <= 0.0 {
        diags.report(Diag::warning(
            "render::camera",
            format!(
                "Clipping near plane {} must be positive; using ε",
                options.near
            ),
        ));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(xres: u32, yres: u32, projection: Projection) -> Camera {
        let mut o = Options::default();
        o.xres = xres;
        o.yres = yres;
        o.projection = projection;
        Camera::from_options(&o, Mat4::IDENTITY, &HashMap::new())
    }

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).abs().max_element() < 1e-3
    }

    #[test]
    fn perspective_projects_known_points_to_known_pixels() {
        // fov 90 on 640×480: screen window [-4/3, 4/3] × [-1, 1]; (1, 1, 2) → screen (0.5, 0.5)
        // → NDC (0.6875, 0.25) → raster (440, 120).
        let c = cam(640, 480, Projection::Perspective { fov: 90.0 });
        assert!(close(
            c.project(Vec3::new(1.0, 1.0, 2.0)),
            Vec3::new(440.0, 120.0, 2.0)
        ));
        // The fov spans the shorter (vertical) side: y = z·tan(45°) is the top edge.
        assert!(close(
            c.project(Vec3::new(0.0, 3.0, 3.0)),
            Vec3::new(320.0, 0.0, 3.0)
        ));
        // Portrait: the fov spans the horizontal side.
        let c = cam(480, 640, Projection::Perspective { fov: 60.0 });
        let t = 30f32.to_radians().tan();
        assert!(close(
            c.project(Vec3::new(2.0 * t, 0.0, 2.0)),
            Vec3::new(480.0, 320.0, 2.0)
        ));
        // Raster space round-trips through camera_from_space (with a clipping range that
        // keeps screen z well conditioned in f32).
        let mut o = Options::default();
        o.projection = Projection::Perspective { fov: 60.0 };
        (o.near, o.far) = (0.1, 100.0);
        let c = Camera::from_options(&o, Mat4::IDENTITY, &HashMap::new());
        let p = Vec3::new(0.3, -0.2, 5.0);
        let r = c.raster_from_camera().project_point3(p);
        let back = c.camera_from_space("raster").unwrap().project_point3(r);
        assert!(close(back, p));
    }

    #[test]
    fn orthographic_maps_the_screen_window() {
        let c = cam(200, 100, Projection::Orthographic);
        // Window [-2, 2] × [-1, 1]: (−2, 1) is the top-left corner, (2, −1) the bottom-right.
        assert!(close(
            c.project(Vec3::new(-2.0, 1.0, 7.0)),
            Vec3::new(0.0, 0.0, 7.0)
        ));
        assert!(close(
            c.project(Vec3::new(2.0, -1.0, 7.0)),
            Vec3::new(200.0, 100.0, 7.0)
        ));
    }

    #[test]
    fn crop_window_follows_the_spec_rounding() {
        assert_eq!(
            crop_region(640, 480, [0.1, 0.5, 0.0, 1.0]),
            PixelRect {
                x0: 64,
                y0: 0,
                x1: 320,
                y1: 480
            }
        );
        assert_eq!(
            crop_region(10, 10, [0.0, 1.0, 0.0, 1.0]),
            PixelRect {
                x0: 0,
                y0: 0,
                x1: 10,
                y1: 10
            }
        );
        // Per the spec's rounding a window this thin covers no pixel.
        assert!(crop_region(10, 10, [0.55, 0.56, 0.0, 1.0]).is_empty());
        let r = crop_region(10, 10, [0.55, 0.65, 0.0, 1.0]);
        assert_eq!((r.x0, r.x1), (6, 7));
    }

    #[test]
    fn named_spaces_are_camera_from_named() {
        let mut o = Options::default();
        o.projection = Projection::Perspective { fov: 45.0 };
        let camera_from_world = Mat4::from_translation(Vec3::new(0.0, 0.0, 5.0));
        let mut cs = HashMap::new();
        cs.insert(
            "lamp".to_string(),
            Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0)),
        );
        let c = Camera::from_options(&o, camera_from_world, &cs);
        let origin = c
            .camera_from_space("lamp")
            .unwrap()
            .transform_point3(Vec3::ZERO);
        assert!(close(origin, Vec3::new(1.0, 2.0, 8.0)));
        assert!(close(
            c.camera_from_space("world")
                .unwrap()
                .transform_point3(Vec3::ZERO),
            Vec3::new(0.0, 0.0, 5.0)
        ));
        assert!(c.camera_from_space("nowhere").is_none());
    }
}
