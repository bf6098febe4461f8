//! sl (see DESIGN.md §2).
