//! The shading runtime: compiled programs executed over whole grids.

pub mod grid;

pub use grid::{Grid, GridVar};
