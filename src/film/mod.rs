//! film (see DESIGN.md §2).
