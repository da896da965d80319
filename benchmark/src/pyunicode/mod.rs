//! CPython's character classes, so the parsers match the original Python scorer exactly.
//!
//! Rust's `char::is_whitespace`/`is_alphanumeric` differ from Python's `str` methods at the
//! edges (e.g. U+001C..U+001F are Python whitespace, circled letters are Rust-alphabetic but
//! not Python-alpha); the original's regexes use Python's definitions, so we use tables
//! generated from CPython (`scripts/gen_pyunicode_tables.py`).

#[rustfmt::skip]
mod tables;

pub use tables::UNICODE_VERSION;

fn in_ranges(table: &[(u32, u32)], c: char) -> bool {
    let cp = c as u32;
    table
        .binary_search_by(|&(a, b)| {
            if b < cp {
                std::cmp::Ordering::Less
            } else if a > cp {
                std::cmp::Ordering::Greater
            } else {
                std::cmp::Ordering::Equal
            }
        })
        .is_ok()
}

/// `str.isspace()`, also `re`'s `\s`.
pub fn is_space(c: char) -> bool {
    c.is_whitespace() || ('\u{1c}'..='\u{1f}').contains(&c)
}

/// `str.isalpha()` for one character.
pub fn is_alpha(c: char) -> bool {
    if c.is_ascii() {
        return c.is_ascii_alphabetic();
    }
    in_ranges(tables::ALPHA, c)
}

/// `re`'s word character (`\w`, used by `\b`): `str.isalnum()` or `_`.
pub fn is_word(c: char) -> bool {
    if c.is_ascii() {
        return c.is_ascii_alphanumeric() || c == '_';
    }
    in_ranges(tables::WORD, c)
}

/// `str.isprintable()` for one character (decides `repr` escapes).
pub fn is_printable(c: char) -> bool {
    if c.is_ascii() {
        return (' '..='~').contains(&c);
    }
    in_ranges(tables::PRINTABLE, c)
}

/// Decimal value of a `\d` character (`str.isdecimal()`), as `float()` reads it.
pub fn decimal_value(c: char) -> Option<u32> {
    if c.is_ascii_digit() {
        return Some(c as u32 - '0' as u32);
    }
    if c.is_ascii() || !in_ranges(tables::DECIMAL, c) {
        return None;
    }
    let cp = c as u32;
    let idx = tables::DECIMAL_ZEROS.partition_point(|&z| z <= cp);
    let zero = tables::DECIMAL_ZEROS[idx.checked_sub(1)?];
    let v = cp - zero;
    (v <= 9).then_some(v)
}

/// `str.strip()` (no argument).
pub fn strip(s: &str) -> &str {
    s.trim_matches(is_space)
}

/// `str.upper()`.
pub fn upper(s: &str) -> String {
    if s.is_ascii() {
        return s.to_ascii_uppercase();
    }
    s.to_uppercase()
}

/// `str.lower()`.
pub fn lower(s: &str) -> String {
    if s.is_ascii() {
        return s.to_ascii_lowercase();
    }
    s.to_lowercase()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classes_match_python_at_the_edges() {
        assert!(is_space('\u{1c}') && is_space('\u{3000}') && !is_space('\u{200b}'));
        assert!(is_alpha('é') && !is_alpha('Ⓐ') && !is_alpha('Ⅷ'));
        assert!(is_word('_') && is_word('½') && is_word('é') && !is_word('-'));
        assert_eq!(decimal_value('٣'), Some(3));
        assert_eq!(decimal_value('𝟗'), Some(9));
        assert_eq!(decimal_value('½'), None);
        assert!(!is_printable('\u{a0}') && is_printable('é') && !is_printable('\n'));
        assert_eq!(strip("\u{1f} a \u{3000}"), "a");
    }
}
