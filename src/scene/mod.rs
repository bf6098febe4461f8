//! Scene building: the request table, parameter lists, graphics state and the built [`Scene`].
//!
//! Input: [`crate::rib::Request`]s. Output: one [`Scene`] per frame (plain data, see `types`).
//! Invariants: every request is validated against the table; errors are collected, not stopped
//! at; requests that are recognised but not implemented warn once, by name.
//!
//! Layout: `table` (one row per request), `params` (declarations and value counts),
//! `builder` (driver, blocks, frames), and one file per request family: `options`,
//! `attributes`, `transforms`, `geometry`, `archive`, `cond` (conditional RIB), `procedural`
//! (procedural primitives, with `runprogram` for RunProgram's processes and `ri_api` for the
//! C RI functions DynamicLoad libraries call).

mod archive;
mod attributes;
pub mod blobby;
pub mod builder;
pub mod cond;
mod geometry;
pub mod known;
mod motion;
mod options;
pub mod params;
mod procedural;
mod resources;
pub mod ri_api;
mod runprogram;
pub mod table;
mod texjobs;
mod transforms;
pub mod types;

pub use builder::{build_scenes, BuildContext, Builder};
pub use types::*;
