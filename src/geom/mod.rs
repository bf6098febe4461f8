//! geom (see DESIGN.md §2).
