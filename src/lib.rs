//! arbor: a RenderMan-style scene and shading language compiler with a REYES renderer.
//!
//! The pipeline (DESIGN.md §1): RIB text → [`rib`] requests → [`scene`] builder → `Scene`;
//! shaders: [`sl`] preprocess → parse → check → compile → `Program`; render: [`render`] buckets
//! → [`geom`] split/dice → [`shade`] grids → hiders → [`film`] filter and write.

pub mod diag;
pub mod encoding;
pub mod farm;
pub mod film;
pub mod foreign_path;
pub mod geom;
pub mod lsp;
pub mod num;
pub mod pathcase;
pub mod pattern;
pub mod pipeline;
pub mod pool;
pub mod ray;
pub mod render;
pub mod rib;
pub mod scene;
pub mod shade;
pub mod sl;
pub mod swatch;
pub mod texture;
