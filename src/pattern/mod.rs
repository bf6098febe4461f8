//! pattern (see DESIGN.md §2).
