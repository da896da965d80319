//! Answer parsers, exactly as the original scorer (docs/protocol.md#answer-parsing). Each mirrors one Python
//! regex or helper; comments give the regex. Hand-written matchers keep Python's Unicode
//! classes (`\s`, `\d`, `\b`) and leftmost-first semantics, and cannot panic.

use crate::pyjson::{self, PyValue};
use crate::pyunicode as pu;

/// Tries `[-+]?(?:\d+\.\d+|\d+|\.\d+)(?:[eE][-+]?\d+)?` at `i`; returns (end, value).
fn number_at(s: &[char], i: usize) -> Option<(usize, f64)> {
    let digit = |k: usize| s.get(k).and_then(|c| pu::decimal_value(*c));
    let run = |mut k: usize| {
        while digit(k).is_some() {
            k += 1;
        }
        k
    };
    let mut k = i;
    if matches!(s.get(k), Some('+' | '-')) {
        k += 1;
    }
    let body_start = k;
    // Alternatives in order: \d+\.\d+ | \d+ | \.\d+ (the first that matches wins).
    let int_end = run(k);
    let mut end = if int_end > k {
        if s.get(int_end) == Some(&'.') && digit(int_end + 1).is_some() {
            run(int_end + 1)
        } else {
            int_end
        }
    } else if s.get(k) == Some(&'.') && digit(k + 1).is_some() {
        run(k + 1)
    } else {
        return None;
    };
    if matches!(s.get(end), Some('e' | 'E')) {
        let mut e = end + 1;
        if matches!(s.get(e), Some('+' | '-')) {
            e += 1;
        }
        let e_end = run(e);
        if e_end > e {
            end = e_end;
        }
    }
    // float() reads any Unicode decimal digit; map them to ASCII for Rust's parser.
    let mut text = String::with_capacity(end - i);
    if body_start > i {
        text.push(s[i]);
    }
    for &c in &s[body_start..end] {
        match pu::decimal_value(c) {
            Some(d) => text.push(char::from_digit(d, 10).unwrap_or('0')),
            None => text.push(c),
        }
    }
    // Rust parses overflow to ±inf, like Python's float().
    text.parse::<f64>().ok().map(|v| (end, v))
}

/// `NUMBER_RE.search(text)` → the first number (the original first replaces `,` by a space,
/// which cannot change a match of this regex).
pub fn first_number(text: &str) -> Option<f64> {
    let s: Vec<char> = text.chars().collect();
    (0..s.len()).find_map(|i| number_at(&s, i).map(|(_, v)| v))
}

/// `NUMBER_RE.findall(text)` as floats.
pub fn all_numbers(text: &str) -> Vec<f64> {
    let s: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < s.len() {
        match number_at(&s, i) {
            Some((end, v)) => {
                out.push(v);
                i = end;
            }
            None => i += 1,
        }
    }
    out
}

/// `extract_first_number`: numbers come only from strings or real numbers (not bools).
pub fn number_of(v: &PyValue) -> Option<f64> {
    match v {
        PyValue::Int(t) => t.parse::<f64>().ok(),
        PyValue::Float(f) => Some(*f),
        PyValue::Str(s) => first_number(s),
        _ => None,
    }
}

/// `normalize_text`: strip, lower, collapse whitespace, drop chars outside `[a-z0-9 ]`, strip.
pub fn normalize_text(text: &str) -> String {
    let lowered = pu::lower(pu::strip(text));
    let mut out = String::with_capacity(lowered.len());
    let mut in_space = false;
    for c in lowered.chars() {
        if pu::is_space(c) {
            if !in_space {
                out.push(' ');
            }
            in_space = true;
            continue;
        }
        in_space = false;
        if c.is_ascii_lowercase() || c.is_ascii_digit() {
            out.push(c);
        }
    }
    out.trim_matches(' ').to_string()
}

/// `extract_yes_no`: `Some(true)` = yes, `Some(false)` = no, `None` = unparseable.
pub fn yes_no(text: &str) -> Option<bool> {
    let t = normalize_text(text);
    if t.is_empty() {
        return None;
    }
    if matches!(t.as_str(), "yes" | "y" | "true") || t.starts_with("yes") {
        return Some(true);
    }
    if matches!(t.as_str(), "no" | "n" | "false") || t.starts_with("no") {
        return Some(false);
    }
    None
}

fn skip_space(s: &[char], mut i: usize) -> usize {
    while s.get(i).is_some_and(|c| pu::is_space(*c)) {
        i += 1;
    }
    i
}

/// `^\s*["'\(\[\{]*\s*([A-Z])(?:\s*[\)\]\}"'\.,:;-]|$)`
fn leading_choice(s: &[char]) -> Option<char> {
    let mut i = skip_space(s, 0);
    while matches!(s.get(i), Some('"' | '\'' | '(' | '[' | '{')) {
        i += 1;
    }
    i = skip_space(s, i);
    let c = *s.get(i)?;
    if !c.is_ascii_uppercase() {
        return None;
    }
    let j = skip_space(s, i + 1);
    let punct = matches!(s.get(j), Some(')' | ']' | '}' | '"' | '\'' | '.' | ',' | ':' | ';' | '-'));
    // Python's `$` also matches just before a final newline.
    let end = i + 1 == s.len() || (i + 2 == s.len() && s[i + 1] == '\n');
    (punct || end).then_some(c)
}

/// `\b(?:OPTION|ANSWER|CHOICE)\s*[:\-]?\s*([A-Z])\b`, leftmost match.
fn choice_hint(s: &[char]) -> Option<char> {
    const KEYWORDS: [&[char]; 3] =
        [&['O', 'P', 'T', 'I', 'O', 'N'], &['A', 'N', 'S', 'W', 'E', 'R'], &['C', 'H', 'O', 'I', 'C', 'E']];
    for start in 0..s.len() {
        if start > 0 && pu::is_word(s[start - 1]) {
            continue;
        }
        let Some(kw) = KEYWORDS.iter().find(|k| s[start..].starts_with(k)) else {
            continue;
        };
        let mut i = skip_space(s, start + kw.len());
        if matches!(s.get(i), Some(':' | '-')) {
            i += 1;
        }
        i = skip_space(s, i);
        let Some(&c) = s.get(i) else { continue };
        if c.is_ascii_uppercase() && s.get(i + 1).is_none_or(|n| !pu::is_word(*n)) {
            return Some(c);
        }
    }
    None
}

/// `extract_choice_letter` on a string: a single letter, else the leading-letter pattern,
/// else the `OPTION/ANSWER/CHOICE X` hint.
pub fn choice_letter(text: &str) -> Option<char> {
    let up = pu::upper(pu::strip(text));
    let s: Vec<char> = up.chars().collect();
    if s.is_empty() {
        return None;
    }
    if s.len() == 1 && pu::is_alpha(s[0]) {
        return Some(s[0]);
    }
    leading_choice(&s).or_else(|| choice_hint(&s))
}

/// `extract_choice_letter` on any value (`None` → unparseable, others through `str()`).
pub fn choice_letter_of(v: &PyValue) -> Option<char> {
    match v {
        PyValue::None => None,
        PyValue::Str(s) => choice_letter(s),
        other => choice_letter(&other.py_str()),
    }
}

/// ASCII letter, or one of the four non-ASCII chars Python's `re.IGNORECASE` folds onto one.
fn ci_letter(c: char) -> bool {
    c.is_ascii_alphabetic() || matches!(c, '\u{130}' | '\u{131}' | '\u{17f}' | '\u{212a}')
}

fn ci_eq(c: char, k: char) -> bool {
    c.to_ascii_lowercase() == k
        || (k == 'i' && matches!(c, '\u{130}' | '\u{131}'))
        || (k == 's' && c == '\u{17f}')
}

/// `strip_choice_prefix`: drop a leading `X.`/`X)`/`X:`/`X-`, then a leading
/// `option|answer|choice [:-] X` (case-insensitive), then strip.
pub fn strip_choice_prefix(text: &str) -> String {
    let s: Vec<char> = pu::strip(text).chars().collect();
    // ^\s*[A-Za-z]\s*[\.\):\-]\s*
    let mut start = 0;
    let i = skip_space(&s, 0);
    if s.get(i).is_some_and(|c| c.is_ascii_alphabetic()) {
        let j = skip_space(&s, i + 1);
        if matches!(s.get(j), Some('.' | ')' | ':' | '-')) {
            start = skip_space(&s, j + 1);
        }
    }
    // ^\s*(?:option|answer|choice)\s*[:\-]?\s*[A-Za-z]\s*   (IGNORECASE)
    let rest = &s[start..];
    let i = skip_space(rest, 0);
    for kw in ["option", "answer", "choice"] {
        let n = kw.len();
        if rest.len() >= i + n && rest[i..i + n].iter().zip(kw.chars()).all(|(c, k)| ci_eq(*c, k)) {
            let mut j = skip_space(rest, i + n);
            if matches!(rest.get(j), Some(':' | '-')) {
                j += 1;
            }
            j = skip_space(rest, j);
            if rest.get(j).is_some_and(|c| ci_letter(*c)) {
                start += skip_space(rest, j + 1);
            }
            break;
        }
    }
    let out: String = s[start..].iter().collect();
    pu::strip(&out).to_string()
}

/// Python's `sorted((a, b))` for two floats (stable; NaN compares false).
fn sorted2(a: f64, b: f64) -> (f64, f64) {
    if b < a {
        (b, a)
    } else {
        (a, b)
    }
}

fn canonical_box(v: [f64; 4]) -> [f64; 4] {
    let (l, r) = sorted2(v[0], v[2]);
    let (t, b) = sorted2(v[1], v[3]);
    [l, t, r, b]
}

/// `extract_bbox`: a dict's `bbox`; a list whose first 4 items are numbers (else its first
/// item if that is a list); a string that parses as JSON into one of those, else the first
/// 4 numbers of the string; canonicalised to [min x, min y, max x, max y].
pub fn bbox_of(v: &PyValue) -> Option<[f64; 4]> {
    match v {
        PyValue::Dict(_) => v.get("bbox").and_then(bbox_of),
        PyValue::List(items) => {
            if items.len() >= 4 {
                let nums: Vec<f64> = items[..4].iter().map_while(number_of).collect();
                if nums.len() == 4 {
                    return Some(canonical_box([nums[0], nums[1], nums[2], nums[3]]));
                }
            }
            match items.first() {
                Some(first @ PyValue::List(_)) => bbox_of(first),
                _ => None,
            }
        }
        PyValue::Str(s) => bbox_of_str(s),
        _ => None,
    }
}

/// `extract_bbox` on a string (the model's reply).
pub fn bbox_of_str(s: &str) -> Option<[f64; 4]> {
    let text = pu::strip(s);
    if text.is_empty() {
        return None;
    }
    if let Some(b) = pyjson::loads(text).as_ref().and_then(bbox_of) {
        return Some(b);
    }
    let nums = all_numbers(text);
    (nums.len() >= 4).then(|| canonical_box([nums[0], nums[1], nums[2], nums[3]]))
}

/// Python's `max(a, b)`: keeps `a` unless `b > a`.
pub(crate) fn py_max(a: f64, b: f64) -> f64 {
    if b > a {
        b
    } else {
        a
    }
}

/// Python's `min(a, b)`: keeps `a` unless `b < a`.
pub(crate) fn py_min(a: f64, b: f64) -> f64 {
    if b < a {
        b
    } else {
        a
    }
}

/// `bbox_iou` with the original's operation order (NaN behaves as in Python).
pub fn iou(g: [f64; 4], p: [f64; 4]) -> f64 {
    let inter_w = py_max(0.0, py_min(g[2], p[2]) - py_max(g[0], p[0]));
    let inter_h = py_max(0.0, py_min(g[3], p[3]) - py_max(g[1], p[1]));
    let inter = inter_w * inter_h;
    let g_area = py_max(0.0, g[2] - g[0]) * py_max(0.0, g[3] - g[1]);
    let p_area = py_max(0.0, p[2] - p[0]) * py_max(0.0, p[3] - p[1]);
    let union = g_area + p_area - inter;
    if union <= 0.0 {
        return 0.0;
    }
    inter / union
}

/// `re.findall(r"\b([A-Z])\b", text)`.
fn standalone_capitals(text: &str) -> Vec<PyValue> {
    let s: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    for (i, &c) in s.iter().enumerate() {
        if c.is_ascii_uppercase()
            && (i == 0 || !pu::is_word(s[i - 1]))
            && s.get(i + 1).is_none_or(|n| !pu::is_word(*n))
        {
            out.push(PyValue::Str(c.to_string()));
        }
    }
    out
}

/// `extract_label_sequence`: a list (or JSON list; a JSON scalar is a one-item list), else
/// the standalone capitals of the upper-cased text; each item → its option letter (or the
/// item itself if a single letter); de-duplicated keeping first occurrences.
pub fn label_sequence(v: &PyValue) -> Vec<char> {
    let owned;
    let items: &[PyValue] = match v {
        PyValue::List(items) => items,
        PyValue::Str(s) => {
            let text = pu::strip(s);
            if text.is_empty() {
                return Vec::new();
            }
            owned = match pyjson::loads(text) {
                Some(PyValue::List(items)) => items,
                Some(scalar) => vec![scalar],
                None => standalone_capitals(&pu::upper(text)),
            };
            &owned
        }
        _ => return Vec::new(),
    };
    let mut labels: Vec<char> = Vec::new();
    for item in items {
        let label = choice_letter_of(item).or_else(|| {
            let token = pu::upper(pu::strip(&item.py_str()));
            let mut cs = token.chars();
            match (cs.next(), cs.next()) {
                (Some(c), None) if pu::is_alpha(c) => Some(c),
                _ => None,
            }
        });
        if let Some(l) = label {
            if !labels.contains(&l) {
                labels.push(l);
            }
        }
    }
    labels
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(x: &str) -> PyValue {
        PyValue::Str(x.into())
    }

    #[test]
    fn numbers() {
        assert_eq!(first_number("52.54 m"), Some(52.54));
        assert_eq!(first_number("about 1,234 m"), Some(1.0));
        assert_eq!(first_number("-3"), Some(-3.0));
        assert_eq!(first_number("x.5e2y"), Some(50.0));
        assert_eq!(first_number("1.e5"), Some(1.0));
        assert_eq!(first_number("1E+2"), Some(100.0));
        assert_eq!(first_number("2e"), Some(2.0));
        assert_eq!(first_number("- 3"), Some(3.0));
        assert_eq!(first_number("+-4"), Some(-4.0));
        assert_eq!(first_number("١٢"), Some(12.0));
        assert_eq!(first_number("1e999"), Some(f64::INFINITY));
        assert_eq!(first_number("none"), None);
        assert_eq!(all_numbers("[1,2, 3.5 ,4e1]"), vec![1.0, 2.0, 3.5, 40.0]);
        assert_eq!(number_of(&PyValue::Bool(true)), None);
        assert_eq!(number_of(&PyValue::Int("7".into())), Some(7.0));
        assert_eq!(number_of(&PyValue::List(vec![])), None);
    }

    #[test]
    fn normalisation_and_yes_no() {
        assert_eq!(normalize_text("  Yes,\tIt  IS! "), "yes it is");
        assert_eq!(normalize_text("a é b"), "a  b");
        assert_eq!(yes_no("Yes."), Some(true));
        assert_eq!(yes_no("yesterday"), Some(true));
        assert_eq!(yes_no("TRUE"), Some(true));
        assert_eq!(yes_no("n"), Some(false));
        assert_eq!(yes_no("None"), Some(false));
        assert_eq!(yes_no("Not sure"), Some(false));
        assert_eq!(yes_no("maybe"), None);
        assert_eq!(yes_no("!!!"), None);
    }

    #[test]
    fn choice_letters() {
        assert_eq!(choice_letter("b"), Some('B'));
        assert_eq!(choice_letter("é"), Some('É'));
        assert_eq!(choice_letter("C. Turn left."), Some('C'));
        assert_eq!(choice_letter("(d)"), Some('D'));
        assert_eq!(choice_letter("[\"A\"]"), Some('A'));
        assert_eq!(choice_letter(" ' a"), Some('A'));
        assert_eq!(choice_letter("' \" a"), None);
        assert_eq!(choice_letter("A car"), None);
        assert_eq!(choice_letter("The answer: c"), Some('C'));
        // `IS` sits where the letter should be, and its `I` is not a whole word.
        assert_eq!(choice_letter("The answer is: c"), None);
        assert_eq!(choice_letter("Option-B"), Some('B'));
        assert_eq!(choice_letter("OPTIONS A"), Some('S'));
        assert_eq!(choice_letter("MYANSWER B"), None);
        assert_eq!(choice_letter("Turn left."), None);
        assert_eq!(choice_letter(""), None);
        assert_eq!(choice_letter_of(&PyValue::None), None);
    }

    #[test]
    fn choice_prefix() {
        assert_eq!(
            strip_choice_prefix("C. No Change (It remains moving)."),
            "No Change (It remains moving)."
        );
        assert_eq!(strip_choice_prefix("Answer: B) go"), ") go");
        assert_eq!(strip_choice_prefix("a - option: x stop"), "stop");
        assert_eq!(strip_choice_prefix("Options are"), "are");
        assert_eq!(strip_choice_prefix("ANſWER b keep"), "keep");
        assert_eq!(strip_choice_prefix("Turn left."), "Turn left.");
    }

    #[test]
    fn boxes() {
        let b = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(bbox_of_str("[1, 2, 3, 4]"), Some(b));
        assert_eq!(bbox_of_str("[3, 4, 1, 2]"), Some(b));
        assert_eq!(bbox_of_str("[[1, 2, 3, 4]]"), Some(b));
        assert_eq!(bbox_of_str("{\"bbox\": [\"1\", \"2px\", 3, 4]}"), Some(b));
        assert_eq!(bbox_of_str("\"[1, 2, 3, 4]\""), Some(b));
        assert_eq!(bbox_of_str("The box is (1, 2), (3, 4)."), Some(b));
        assert_eq!(bbox_of_str("[1, 2, 3]"), None);
        assert_eq!(bbox_of_str("[true, 1, 2, 3]"), None);
        assert_eq!(bbox_of_str("[true, 1, 2, 3, 4] 5"), Some([1.0, 2.0, 3.0, 4.0]));
        assert_eq!(bbox_of_str(""), None);
        let gt = PyValue::Dict(vec![(
            "bbox".into(),
            PyValue::List(["1452", "738", "1560", "960"].iter().map(|x| PyValue::Int((*x).into())).collect()),
        )]);
        assert_eq!(bbox_of(&gt), Some([1452.0, 738.0, 1560.0, 960.0]));
        assert_eq!(iou(b, b), 1.0);
        assert_eq!(iou([0.0, 0.0, 2.0, 2.0], [1.0, 0.0, 3.0, 2.0]), 2.0 / 6.0);
        assert_eq!(iou([0.0; 4], [0.0; 4]), 0.0);
    }

    #[test]
    fn labels() {
        let abc = vec!['A', 'B', 'C'];
        assert_eq!(label_sequence(&s("[\"A\", \"B\", \"C\"]")), abc);
        assert_eq!(label_sequence(&s("A -> B -> C")), abc);
        assert_eq!(label_sequence(&s("[\"A\", \"A\", \"B\", \"C\", \"B\"]")), abc);
        assert_eq!(label_sequence(&s("\"B\"")), vec!['B']);
        assert_eq!(label_sequence(&s("I don't know")), vec!['I', 'T']);
        assert_eq!(label_sequence(&s("[[\"C\"], \"image a\", 3]")), vec!['C']);
        assert_eq!(label_sequence(&s("[\"Image B\", \"option: a\"]")), vec!['A']);
        assert_eq!(label_sequence(&s("")), Vec::<char>::new());
        assert_eq!(label_sequence(&PyValue::None), Vec::<char>::new());
    }
}
