//! Texture, environment and shadow maps (DESIGN.md §2; notes shading.md §2, pipeline.md
//! §3.7–3.9, §4.5–4.7).
//!
//! * [`image_in`]: source pictures → float images.
//! * [`mipmap`]: wrap modes and the pyramid.
//! * [`format`]: the tiled mip-mapped `.tex` file.
//! * [`make`]: `arbor texture` and the Make* requests.
//! * [`prman_tx`]: PRMan 3.x `txmake` texture files (read only).
//! * [`bump`]: the bump-map form (heights + slopes) and Blinn's perturbation for bump().
//! * [`cache`]: tiles on demand, shared across threads, bounded.
//! * [`filter`]: point / trilinear / EWA / summed-area-table lookups.
//! * [`sat`]: summed-area tables (Crow 1984).
//! * [`env`]: lat-long and cube environment lookups.
//! * [`shadow`]: percentage-closer filtering.
//! * [`system`]: the [`TextureLookup`](crate::shade::exec::TextureLookup) a frame renders with.

pub mod bump;
pub mod cache;
pub mod env;
pub mod filter;
pub mod format;
pub mod horizon;
pub mod image_in;
pub mod make;
pub mod mipmap;
pub mod prman_tx;
pub mod sat;
pub mod shadow;
pub mod system;

pub use system::{TextureSystem, DEFAULT_MEMORY_KB};
