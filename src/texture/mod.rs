//! texture (see DESIGN.md §2).
