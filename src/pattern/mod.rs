//! Procedural patterns (DESIGN.md §2; notes/shading.md §3): noise, fractal sums and fractal
//! terrain, shared by the shading runtime and by geometry.
//!
//! Input: points in shader space (and time), filter widths, fractal parameters, seeds.
//! Output: scalar/vector pattern values and terrain height grids / meshes.
//! Invariants: every function is pure and deterministic (fixed permutation, hashed random
//! numbers keyed by lattice coordinates, no global mutable state), and never panics.

pub mod fractal;
pub mod hash;
pub mod noise;
pub mod terrain;

pub use fractal::*;
pub use hash::{hash_combine, hash_coords, hash_float, hash_gaussian, hash_pair_sym, hash_u32};
pub use noise::*;
