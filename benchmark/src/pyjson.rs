//! Python values as the original scorer sees them: `json.loads` (with its NaN/Infinity
//! literals), `str()`/`repr()` and `json.dumps`, reproduced so parsing matches bit for bit.

use crate::pyunicode;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Style {
    Repr,
    Json,
}

/// A value as Python's `json.loads` would build it.
#[derive(Debug, Clone, PartialEq)]
pub enum PyValue {
    None,
    Bool(bool),
    /// A Python `int`, kept as its decimal text (arbitrary precision).
    Int(String),
    Float(f64),
    Str(String),
    List(Vec<PyValue>),
    /// A `dict` in insertion order; a repeated key keeps its first position and last value.
    Dict(Vec<(String, PyValue)>),
}

/// Deepest nesting accepted; CPython raises `RecursionError` near 1000, we stop earlier.
const MAX_DEPTH: usize = 400;

impl PyValue {
    /// Converts a serde_json value (how records are read) to the Python view.
    pub fn from_json(v: &serde_json::Value) -> PyValue {
        use serde_json::Value as V;
        match v {
            V::Null => PyValue::None,
            V::Bool(b) => PyValue::Bool(*b),
            V::Number(n) => {
                if n.is_i64() || n.is_u64() {
                    PyValue::Int(n.to_string())
                } else {
                    PyValue::Float(n.as_f64().unwrap_or(f64::NAN))
                }
            }
            V::String(s) => PyValue::Str(s.clone()),
            V::Array(a) => PyValue::List(a.iter().map(PyValue::from_json).collect()),
            V::Object(o) => {
                PyValue::Dict(o.iter().map(|(k, v)| (k.clone(), PyValue::from_json(v))).collect())
            }
        }
    }

    /// `dict.get(key)`.
    pub fn get(&self, key: &str) -> Option<&PyValue> {
        match self {
            PyValue::Dict(items) => items.iter().find(|(k, _)| k == key).map(|(_, v)| v),
            _ => None,
        }
    }

    /// Python truthiness (`x or y`).
    pub fn is_truthy(&self) -> bool {
        match self {
            PyValue::None => false,
            PyValue::Bool(b) => *b,
            PyValue::Int(t) => !t.trim_start_matches('-').trim_start_matches('0').is_empty(),
            PyValue::Float(f) => *f != 0.0,
            PyValue::Str(s) => !s.is_empty(),
            PyValue::List(l) => !l.is_empty(),
            PyValue::Dict(d) => !d.is_empty(),
        }
    }

    /// `str(value)`.
    pub fn py_str(&self) -> String {
        match self {
            PyValue::Str(s) => s.clone(),
            other => {
                let mut out = String::new();
                other.write_repr(&mut out);
                out
            }
        }
    }

    /// `repr(value)` appended to `out`.
    pub fn write_repr(&self, out: &mut String) {
        self.write(out, Style::Repr);
    }

    /// `json.dumps(value, ensure_ascii=False)`.
    pub fn dumps(&self) -> String {
        let mut out = String::new();
        self.write(&mut out, Style::Json);
        out
    }

    /// Python's `repr` and `json.dumps` differ only in scalars and string quoting; containers
    /// are walked the same way.
    fn write(&self, out: &mut String, style: Style) {
        let key = |k: &str, out: &mut String| match style {
            Style::Repr => str_repr(k, out),
            Style::Json => dumps_str(k, out),
        };
        match self {
            PyValue::List(items) => {
                out.push('[');
                for (i, item) in items.iter().enumerate() {
                    if i > 0 {
                        out.push_str(", ");
                    }
                    item.write(out, style);
                }
                out.push(']');
            }
            PyValue::Dict(items) => {
                out.push('{');
                for (i, (k, v)) in items.iter().enumerate() {
                    if i > 0 {
                        out.push_str(", ");
                    }
                    key(k, out);
                    out.push_str(": ");
                    v.write(out, style);
                }
                out.push('}');
            }
            PyValue::Str(s) => key(s, out),
            PyValue::Int(t) => out.push_str(t),
            PyValue::None => out.push_str(if style == Style::Repr { "None" } else { "null" }),
            PyValue::Bool(b) => out.push_str(match (style, b) {
                (Style::Repr, true) => "True",
                (Style::Repr, false) => "False",
                (Style::Json, true) => "true",
                (Style::Json, false) => "false",
            }),
            PyValue::Float(f) => {
                if style == Style::Json && f.is_nan() {
                    out.push_str("NaN");
                } else if style == Style::Json && f.is_infinite() {
                    out.push_str(if *f > 0.0 { "Infinity" } else { "-Infinity" });
                } else {
                    out.push_str(&float_repr(*f));
                }
            }
        }
    }
}

fn dumps_str(s: &str, out: &mut String) {
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            '\u{8}' => out.push_str("\\b"),
            '\u{c}' => out.push_str("\\f"),
            c if (c as u32) < 0x20 => out.push_str(&format!("\\u{:04x}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
}

/// `repr(str)`: single quotes unless the text has `'` and no `"`; non-printables escaped.
fn str_repr(s: &str, out: &mut String) {
    let quote = if s.contains('\'') && !s.contains('"') { '"' } else { '\'' };
    out.push(quote);
    for c in s.chars() {
        match c {
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if c == quote => {
                out.push('\\');
                out.push(c);
            }
            c if pyunicode::is_printable(c) => out.push(c),
            c => {
                let cp = c as u32;
                if cp <= 0xff {
                    out.push_str(&format!("\\x{cp:02x}"));
                } else if cp <= 0xffff {
                    out.push_str(&format!("\\u{cp:04x}"));
                } else {
                    out.push_str(&format!("\\U{cp:08x}"));
                }
            }
        }
    }
    out.push(quote);
}

/// `repr(float)`: shortest round-trip digits, fixed notation for 1e-4 <= |x| < 1e16.
pub fn float_repr(f: f64) -> String {
    if f.is_nan() {
        return "nan".into();
    }
    if f.is_infinite() {
        return if f > 0.0 { "inf" } else { "-inf" }.into();
    }
    let sci = format!("{:e}", f.abs());
    let (mant, exp) = sci.split_once('e').unwrap_or((&sci, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    let digits: String = mant.chars().filter(|c| *c != '.').collect();
    let sign = if f.is_sign_negative() { "-" } else { "" };
    if (-4..16).contains(&exp) {
        let body = if exp >= 0 {
            let int_len = exp as usize + 1;
            let (int_part, frac) = if digits.len() > int_len {
                (digits[..int_len].to_string(), digits[int_len..].to_string())
            } else {
                (format!("{digits}{}", "0".repeat(int_len - digits.len())), "0".to_string())
            };
            format!("{int_part}.{frac}")
        } else {
            format!("0.{}{digits}", "0".repeat((-exp - 1) as usize))
        };
        format!("{sign}{body}")
    } else {
        let m = if digits.len() > 1 { format!("{}.{}", &digits[..1], &digits[1..]) } else { digits };
        let esign = if exp < 0 { '-' } else { '+' };
        format!("{sign}{m}e{esign}{:02}", exp.abs())
    }
}

/// `json.loads(text)`; `None` where Python raises `JSONDecodeError` (or would recurse too deep).
pub fn loads(text: &str) -> Option<PyValue> {
    let chars: Vec<char> = text.chars().collect();
    let mut p = Parser { s: &chars, i: 0 };
    p.ws();
    let v = p.value(0)?;
    p.ws();
    (p.i == chars.len()).then_some(v)
}

struct Parser<'a> {
    s: &'a [char],
    i: usize,
}

impl Parser<'_> {
    fn peek(&self) -> Option<char> {
        self.s.get(self.i).copied()
    }

    fn ws(&mut self) {
        while matches!(self.peek(), Some(' ' | '\t' | '\n' | '\r')) {
            self.i += 1;
        }
    }

    fn lit(&mut self, word: &str) -> bool {
        let n = word.chars().count();
        if self.i + n <= self.s.len() && self.s[self.i..self.i + n].iter().copied().eq(word.chars()) {
            self.i += n;
            true
        } else {
            false
        }
    }

    fn value(&mut self, depth: usize) -> Option<PyValue> {
        if depth > MAX_DEPTH {
            return None;
        }
        match self.peek()? {
            '"' => {
                self.i += 1;
                self.string().map(PyValue::Str)
            }
            '{' => {
                self.i += 1;
                self.object(depth)
            }
            '[' => {
                self.i += 1;
                self.array(depth)
            }
            'n' => self.lit("null").then_some(PyValue::None),
            't' => self.lit("true").then_some(PyValue::Bool(true)),
            'f' => self.lit("false").then_some(PyValue::Bool(false)),
            'N' => self.lit("NaN").then_some(PyValue::Float(f64::NAN)),
            'I' => self.lit("Infinity").then_some(PyValue::Float(f64::INFINITY)),
            '-' if self.s.get(self.i + 1) == Some(&'I') => {
                self.i += 1;
                self.lit("Infinity").then_some(PyValue::Float(f64::NEG_INFINITY))
            }
            _ => self.number(),
        }
    }

    fn digits(&mut self) -> usize {
        let start = self.i;
        while matches!(self.peek(), Some('0'..='9')) {
            self.i += 1;
        }
        self.i - start
    }

    fn number(&mut self) -> Option<PyValue> {
        let start = self.i;
        if self.peek() == Some('-') {
            self.i += 1;
        }
        match self.peek()? {
            '0' => self.i += 1,
            '1'..='9' => {
                self.digits();
            }
            _ => return None,
        }
        let mut is_float = false;
        if self.peek() == Some('.') && matches!(self.s.get(self.i + 1), Some('0'..='9')) {
            self.i += 1;
            self.digits();
            is_float = true;
        }
        if matches!(self.peek(), Some('e' | 'E')) {
            let save = self.i;
            self.i += 1;
            if matches!(self.peek(), Some('+' | '-')) {
                self.i += 1;
            }
            if self.digits() == 0 {
                self.i = save;
            } else {
                is_float = true;
            }
        }
        let text: String = self.s[start..self.i].iter().collect();
        if is_float {
            text.parse::<f64>().ok().map(PyValue::Float)
        } else {
            // int("-0") is 0.
            let t = if text == "-0" { "0".to_string() } else { text };
            Some(PyValue::Int(t))
        }
    }

    fn hex4(&mut self) -> Option<u32> {
        if self.i + 4 > self.s.len() {
            return None;
        }
        let mut v = 0u32;
        for k in 0..4 {
            v = v * 16 + self.s[self.i + k].to_digit(16)?;
        }
        self.i += 4;
        Some(v)
    }

    fn string(&mut self) -> Option<String> {
        let mut out = String::new();
        loop {
            let c = self.peek()?;
            self.i += 1;
            match c {
                '"' => return Some(out),
                '\\' => {
                    let e = self.peek()?;
                    self.i += 1;
                    match e {
                        '"' => out.push('"'),
                        '\\' => out.push('\\'),
                        '/' => out.push('/'),
                        'b' => out.push('\u{8}'),
                        'f' => out.push('\u{c}'),
                        'n' => out.push('\n'),
                        'r' => out.push('\r'),
                        't' => out.push('\t'),
                        'u' => {
                            let hi = self.hex4()?;
                            let cp = if (0xd800..0xdc00).contains(&hi)
                                && self.s.get(self.i) == Some(&'\\')
                                && self.s.get(self.i + 1) == Some(&'u')
                            {
                                let save = self.i;
                                self.i += 2;
                                match self.hex4() {
                                    Some(lo) if (0xdc00..0xe000).contains(&lo) => {
                                        0x10000 + ((hi - 0xd800) << 10) + (lo - 0xdc00)
                                    }
                                    Some(_) => {
                                        self.i = save;
                                        hi
                                    }
                                    None => return None,
                                }
                            } else {
                                hi
                            };
                            // A lone surrogate is valid in Python but not in Rust; U+FFFD
                            // behaves the same in every parser here (not space, alpha or word).
                            out.push(char::from_u32(cp).unwrap_or('\u{fffd}'));
                        }
                        _ => return None,
                    }
                }
                c if (c as u32) < 0x20 => return None,
                c => out.push(c),
            }
        }
    }

    fn array(&mut self, depth: usize) -> Option<PyValue> {
        let mut items = Vec::new();
        self.ws();
        if self.peek() == Some(']') {
            self.i += 1;
            return Some(PyValue::List(items));
        }
        loop {
            self.ws();
            items.push(self.value(depth + 1)?);
            self.ws();
            match self.peek()? {
                ',' => self.i += 1,
                ']' => {
                    self.i += 1;
                    return Some(PyValue::List(items));
                }
                _ => return None,
            }
        }
    }

    fn object(&mut self, depth: usize) -> Option<PyValue> {
        let mut items: Vec<(String, PyValue)> = Vec::new();
        self.ws();
        if self.peek() == Some('}') {
            self.i += 1;
            return Some(PyValue::Dict(items));
        }
        loop {
            self.ws();
            if self.peek()? != '"' {
                return None;
            }
            self.i += 1;
            let key = self.string()?;
            self.ws();
            if self.peek()? != ':' {
                return None;
            }
            self.i += 1;
            self.ws();
            let v = self.value(depth + 1)?;
            if let Some(slot) = items.iter_mut().find(|(k, _)| *k == key) {
                slot.1 = v;
            } else {
                items.push((key, v));
            }
            self.ws();
            match self.peek()? {
                ',' => self.i += 1,
                '}' => {
                    self.i += 1;
                    return Some(PyValue::Dict(items));
                }
                _ => return None,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loads_like_python() {
        assert_eq!(
            loads(" [1, 2.5, \"a\"] "),
            Some(PyValue::List(vec![
                PyValue::Int("1".into()),
                PyValue::Float(2.5),
                PyValue::Str("a".into())
            ]))
        );
        assert!(matches!(loads("NaN"), Some(PyValue::Float(f)) if f.is_nan()));
        assert_eq!(loads("-Infinity"), Some(PyValue::Float(f64::NEG_INFINITY)));
        assert_eq!(loads("1e400"), Some(PyValue::Float(f64::INFINITY)));
        for bad in ["1.", "01", "[1,]", "{\"a\" 1}", "'a'", "\"a\tb\"", "[1] x", "", "\u{feff}1"] {
            assert_eq!(loads(bad), None, "{bad:?}");
        }
        assert_eq!(loads("\"\\ud83d\\ude00\""), Some(PyValue::Str("😀".into())));
        assert_eq!(
            loads("{\"a\": 1, \"b\": 2, \"a\": 3}").unwrap().get("a"),
            Some(&PyValue::Int("3".into()))
        );
        let deep = "[".repeat(5000);
        assert_eq!(loads(&deep), None);
    }

    #[test]
    fn str_and_repr_like_python() {
        let v = loads(r#"[["B"], {"x": "it's"}, null, true, 1.5e-7, 1e16, 100.0, "\t"]"#).unwrap();
        assert_eq!(v.py_str(), r#"[['B'], {'x': "it's"}, None, True, 1.5e-07, 1e+16, 100.0, '\t']"#);
        assert_eq!(float_repr(0.0001), "0.0001");
        assert_eq!(float_repr(-0.0), "-0.0");
        assert_eq!(float_repr(123456789.5), "123456789.5");
        assert_eq!(PyValue::Str("\u{a0}".into()).dumps(), "\"\u{a0}\"");
        assert_eq!(v.dumps(), r#"[["B"], {"x": "it's"}, null, true, 1.5e-07, 1e+16, 100.0, "\t"]"#);
    }
}
