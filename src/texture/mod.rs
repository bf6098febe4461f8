//! texture (see DESIGN.md §2).

pub mod horizon;
