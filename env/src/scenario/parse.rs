//! TOML → [`ScenarioFile`] with errors that name the TOML path (`actors[2].speed_mps`), the
//! offending text and the line/column.

use super::schema::ScenarioFile;
use crate::{Error, Result};
use std::ops::Range;
use std::path::Path;
use toml::de::{DeTable, DeValue};
use toml::Spanned;

/// 1-based line and column of a byte offset.
pub fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let col = before.rfind('\n').map_or(before.chars().count(), |i| before[i + 1..].chars().count()) + 1;
    (line, col)
}

/// Deepest TOML path whose key or value span contains `pos`.
fn path_at(table: &DeTable<'_>, pos: usize, path: &mut String) {
    for (k, v) in table.iter() {
        let in_key = k.span().contains(&pos);
        if in_key || v.span().contains(&pos) || value_contains(v, pos) {
            push_key(path, k.get_ref());
            if !in_key {
                descend(v, pos, path);
            }
            return;
        }
    }
}

fn value_contains(v: &Spanned<DeValue<'_>>, pos: usize) -> bool {
    // Array-of-tables values are spread over the file; look inside.
    match v.get_ref() {
        DeValue::Array(a) => a.iter().any(|e| e.span().contains(&pos) || value_contains(e, pos)),
        DeValue::Table(t) => t
            .iter()
            .any(|(k, e)| k.span().contains(&pos) || e.span().contains(&pos) || value_contains(e, pos)),
        _ => false,
    }
}

fn descend(v: &Spanned<DeValue<'_>>, pos: usize, path: &mut String) {
    match v.get_ref() {
        DeValue::Table(t) => path_at(t, pos, path),
        DeValue::Array(a) => {
            if let Some(i) = a.iter().position(|e| e.span().contains(&pos) || value_contains(e, pos)) {
                path.push_str(&format!("[{i}]"));
                descend(&a[i], pos, path);
            }
        }
        _ => {}
    }
}

fn push_key(path: &mut String, k: &str) {
    if !path.is_empty() {
        path.push('.');
    }
    path.push_str(k);
}

fn snippet(text: &str, span: &Range<usize>) -> String {
    let s = text.get(span.clone()).unwrap_or("").trim();
    let s: String = s.chars().take(60).collect();
    if s.is_empty() {
        "<missing>".into()
    } else {
        s
    }
}

/// Parses scenario TOML; `file` names the source in errors.
pub fn parse_scenario_str(file: &Path, text: &str) -> Result<ScenarioFile> {
    // Syntax first: a spanned tree for locating later schema errors.
    let doc = DeTable::parse(text).map_err(|e| {
        let span = e.span().unwrap_or(0..0);
        let (l, c) = line_col(text, span.start);
        Error::scenario(
            file,
            format!("<syntax at line {l}, column {c}>"),
            snippet(text, &span),
            format!("malformed TOML at line {l}, column {c}: {}", e.message()),
        )
    })?;
    toml::from_str::<ScenarioFile>(text).map_err(|e| {
        let span = e.span().unwrap_or(0..0);
        let (l, c) = line_col(text, span.start);
        let mut path = String::new();
        path_at(doc.get_ref(), span.start, &mut path);
        if path.is_empty() {
            path.push_str("<document>");
        }
        Error::scenario(file, path, snippet(text, &span), format!("{} (line {l}, column {c})", e.message()))
    })
}

/// Reads and parses a scenario file.
pub fn parse_scenario_file(path: &Path) -> Result<ScenarioFile> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    parse_scenario_str(path, &text)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MIN: &str = r#"
version = 1
id = "t"
category = "01_pedestrian"
map = "m.net.xml"
[ego]
start = { x = 0.0, y = 0.0, yaw_deg = 0.0 }
destination = { x = 50.0, y = 0.0 }
"#;

    fn err(text: &str) -> String {
        parse_scenario_str(Path::new("f.toml"), text).unwrap_err().to_string()
    }

    #[test]
    fn minimal_parses() {
        let s = parse_scenario_str(Path::new("f.toml"), MIN).unwrap();
        assert_eq!(s.id, "t");
        assert!(s.actors.is_empty());
    }

    #[test]
    fn unknown_key_names_its_path() {
        let t = format!("{MIN}\n[[actors]]\nkind = \"car\"\nspeed_mps = 3.0\n\n[[actors]]\nkind = \"car\"\ncolour = [1, 2, 3]\n");
        let e = err(&t);
        assert!(e.contains("actors[1].colour"), "{e}");
        assert!(e.contains("line 16"), "{e}");
    }

    #[test]
    fn wrong_type_names_its_path() {
        let t = format!("{MIN}\n[[actors]]\nkind = \"car\"\nspeed_mps = \"fast\"\n");
        let e = err(&t);
        assert!(e.contains("actors[0].speed_mps") && e.contains("fast"), "{e}");
        let t = format!("{MIN}\n[[actors]]\nkind = \"tank\"\n");
        assert!(err(&t).contains("actors[0].kind"), "{}", err(&t));
    }

    #[test]
    fn syntax_error_has_line_and_column() {
        let e = err("version = 1\nid = \"x\nmap = 3\n");
        assert!(e.contains("line 2"), "{e}");
    }

    #[test]
    fn missing_field_is_reported() {
        let e = err("version = 1\nid = \"x\"\ncategory = \"01_pedestrian\"\n[ego]\n");
        assert!(e.contains("map"), "{e}");
    }
}
