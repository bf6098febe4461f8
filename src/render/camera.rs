//! The camera: projection and the named coordinate systems of a frame.
//!
//! Input: a built [`crate::scene::Scene`]. Output: the transforms between camera space and
//! screen, NDC and raster space, and every named space shaders may ask for.
//! Invariants: camera space is RenderMan's left-handed space (+z into the screen); "current"
//! space, where grids are shaded, is camera space.

use std::collections::HashMap;

use glam::Mat4;

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
}

impl Camera {
    pub fn raster_from_camera(&self) -> Mat4 {
        self.raster_from_screen * self.screen_from_camera
    }
    /// camera_from_space for "camera"/"current", "world", "screen", "NDC", "raster" and named
    /// coordinate systems ("object" and "shader" depend on the primitive and are handled by the
    /// shading context).
    pub fn camera_from_space(&self, name: &str) -> Option<Mat4> {
        match name {
            "camera" | "current" => Some(Mat4::IDENTITY),
            "world" => Some(self.camera_from_world),
            "screen" => Some(self.screen_from_camera.inverse()),
            "NDC" => Some((self.ndc_from_screen * self.screen_from_camera).inverse()),
            "raster" => Some(self.raster_from_camera().inverse()),
            _ => self.named.get(name).copied(),
        }
    }
}
