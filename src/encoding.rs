//! Source text decoding: shaders, headers and RIB files written on 8-bit systems.
//!
//! Input: the bytes of a file. Output: its text — UTF-8 when the bytes are valid UTF-8, else
//! ISO-8859-1 (Latin-1: each byte is the code point of the same value), which is what an
//! accented comment or name in a shader from a Latin-1 (or Windows-1252) editor decodes to.
//! Invariants: never fails and never loses a byte; ASCII decodes to itself either way, so
//! spans into the text still match byte offsets of ASCII files.

use std::path::Path;

/// UTF-8 when valid, else Latin-1.
pub fn decode(bytes: Vec<u8>) -> String {
    match String::from_utf8(bytes) {
        Ok(s) => s,
        Err(e) => e.into_bytes().iter().map(|&b| char::from(b)).collect(),
    }
}

/// Reads a text file (UTF-8, else Latin-1).
pub fn read_text(path: &Path) -> std::io::Result<String> {
    std::fs::read(path).map(decode)
}

#[cfg(test)]
mod tests {
    use super::decode;

    #[test]
    fn utf8_stays_and_latin1_is_mapped() {
        assert_eq!(decode("café".as_bytes().to_vec()), "café");
        assert_eq!(decode(b"caf\xe9 \xb0".to_vec()), "café °");
        assert_eq!(decode(b"plain".to_vec()), "plain");
    }
}
