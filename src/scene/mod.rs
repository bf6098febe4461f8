//! Scene building: the request table, parameter lists, graphics state and the built [`Scene`].
//!
//! Input: [`crate::rib::Request`]s. Output: one [`Scene`] per frame (plain data, see `types`).
//! Invariants: every request is validated against the table; errors are collected, not stopped
//! at; requests that are recognised but not implemented warn once, by name.

pub mod types;

pub use types::*;
