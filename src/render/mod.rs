//! render (see DESIGN.md §2).
