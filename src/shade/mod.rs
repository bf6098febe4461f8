//! The shading runtime: compiled programs executed over whole grids.
//!
//! Input: a diced [`Grid`] and the primitive's shaders. Output: the grid's `ci`/`oi` (and P/N
//! after displacement). Invariants: see `exec` (masking) and `ops` (no panics).

pub mod color;
pub mod exec;
pub mod grid;
pub mod ops;
pub mod rays;
pub mod system;
pub mod value;

pub use grid::{Grid, GridVar};
