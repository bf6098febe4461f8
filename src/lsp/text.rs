//! Positions in an editor's document: byte offsets ↔ LSP positions, and edits.
//!
//! Input: a document's text (UTF-8) and LSP positions (0-based line, column in UTF-16 code
//! units, as LSP counts by default). Output: byte offsets into the text and back; the text after
//! an incremental `didChange` edit.
//! Invariants: never panics on any position or text: a line past the end clamps to the end of
//! the text, a column past the end of its line clamps to the line's end, a column inside a
//! surrogate pair or a multi-byte character rounds down to the character's start; every
//! returned byte offset is on a `char` boundary.

use lsp_types::{Position, Range};

/// Start offsets of every line of a text (`\n` ends a line; a `\r` before it belongs to the
/// line's end, not its columns).
#[derive(Clone, Debug)]
pub struct LineIndex {
    starts: Vec<usize>,
}

impl LineIndex {
    pub fn new(text: &str) -> LineIndex {
        let mut starts = vec![0];
        for (i, b) in text.bytes().enumerate() {
            if b == b'\n' {
                starts.push(i + 1);
            }
        }
        LineIndex { starts }
    }

    pub fn line_count(&self) -> usize {
        self.starts.len()
    }

    /// The byte range of line `line` without its line break.
    fn line_range(&self, text: &str, line: usize) -> (usize, usize) {
        let start = self.starts[line].min(text.len());
        let mut end = self
            .starts
            .get(line + 1)
            .map(|&n| n - 1)
            .unwrap_or(text.len())
            .min(text.len());
        if end > start && text.as_bytes()[end - 1] == b'\r' {
            end -= 1;
        }
        (start, end.max(start))
    }

    /// The byte offset of an LSP position (clamped, see the module invariants).
    pub fn offset(&self, text: &str, pos: Position) -> usize {
        let line = pos.line as usize;
        if line >= self.starts.len() {
            return text.len();
        }
        let (start, end) = self.line_range(text, line);
        let mut units = 0u32;
        for (i, ch) in text[start..end].char_indices() {
            let w = ch.len_utf16() as u32;
            if units + w > pos.character {
                return start + i;
            }
            units += w;
        }
        end
    }

    /// The LSP position of a byte offset (clamped to the text, rounded down to a char start).
    pub fn position(&self, text: &str, offset: usize) -> Position {
        let mut offset = offset.min(text.len());
        while !text.is_char_boundary(offset) {
            offset -= 1;
        }
        let line = self.starts.partition_point(|&s| s <= offset) - 1;
        let start = self.starts[line];
        let col: usize = text[start..offset].chars().map(char::len_utf16).sum();
        Position::new(line as u32, col as u32)
    }

    pub fn range(&self, text: &str, start: usize, end: usize) -> Range {
        Range::new(
            self.position(text, start),
            self.position(text, end.max(start)),
        )
    }
}

/// Applies one `didChange` content change: a range replaced by `new_text`, or (no range) the
/// whole text. Returns the new text.
pub fn apply_change(text: &str, range: Option<Range>, new_text: &str) -> String {
    let Some(range) = range else {
        return new_text.to_string();
    };
    let idx = LineIndex::new(text);
    let a = idx.offset(text, range.start);
    let b = idx.offset(text, range.end).max(a);
    let mut out = String::with_capacity(text.len() + new_text.len());
    out.push_str(&text[..a]);
    out.push_str(new_text);
    out.push_str(&text[b..]);
    out
}

/// The identifier (letters, digits, `_`) around byte `offset`, with its byte range.
pub fn word_at(text: &str, offset: usize) -> Option<(usize, usize, &str)> {
    let b = text.as_bytes();
    let offset = offset.min(b.len());
    let is_word = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let mut s = offset;
    while s > 0 && is_word(b[s - 1]) {
        s -= 1;
    }
    let mut e = offset;
    while e < b.len() && is_word(b[e]) {
        e += 1;
    }
    (e > s).then(|| (s, e, &text[s..e]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utf16_columns_count_surrogate_pairs_as_two() {
        let text = "a\u{1F600}b\nxé\r\nz";
        let idx = LineIndex::new(text);
        // 'b' is after a 4-byte char that is 2 UTF-16 units.
        assert_eq!(idx.offset(text, Position::new(0, 3)), 5);
        assert_eq!(idx.position(text, 5), Position::new(0, 3));
        // Inside the surrogate pair rounds down to the character's start.
        assert_eq!(idx.offset(text, Position::new(0, 2)), 1);
        // 'é' is 2 bytes, 1 unit; the \r is not a column.
        assert_eq!(idx.offset(text, Position::new(1, 2)), 10);
        assert_eq!(idx.offset(text, Position::new(1, 99)), 10);
        assert_eq!(idx.position(text, text.len()), Position::new(2, 1));
        assert_eq!(idx.offset(text, Position::new(99, 0)), text.len());
        // A byte inside a multi-byte char maps to its start.
        assert_eq!(idx.position(text, 2), Position::new(0, 1));
    }

    #[test]
    fn incremental_edits_replace_ranges() {
        let t = "surface s() {\n  Ci = Cs;\n}\n";
        let t2 = apply_change(
            t,
            Some(Range::new(Position::new(1, 7), Position::new(1, 9))),
            "Os",
        );
        assert_eq!(t2, "surface s() {\n  Ci = Os;\n}\n");
        // Reversed and out-of-range ranges never panic.
        let t3 = apply_change(
            &t2,
            Some(Range::new(Position::new(9, 0), Position::new(0, 0))),
            "!",
        );
        assert_eq!(t3, format!("{t2}!"));
        assert_eq!(apply_change(&t3, None, "x"), "x");
    }

    #[test]
    fn words_are_found_around_the_cursor() {
        assert_eq!(word_at("a + noise(P)", 6), Some((4, 9, "noise")));
        assert_eq!(word_at("a + noise(P)", 9), Some((4, 9, "noise")));
        assert_eq!(word_at("  ", 1), None);
    }
}
