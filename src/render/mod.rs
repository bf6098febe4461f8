//! The REYES renderer: camera, buckets, split/dice decisions, hiders, and the frame driver.

pub mod camera;

pub use camera::Camera;
