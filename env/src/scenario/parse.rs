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

/// One step of a TOML path: a key or an array index.
enum Step<'a> {
    Key(&'a str),
    Index(usize),
}

/// `actors[2].route.lanes[1]` → keys and indices; `None` for text that is not a path.
fn steps(field: &str) -> Option<Vec<Step<'_>>> {
    let mut out = Vec::new();
    for part in field.split('.') {
        let (key, mut rest) = part.split_at(part.find('[').unwrap_or(part.len()));
        if key.is_empty() {
            return None;
        }
        out.push(Step::Key(key));
        while let Some(r) = rest.strip_prefix('[') {
            let end = r.find(']')?;
            out.push(Step::Index(r[..end].parse().ok()?));
            rest = &r[end + 1..];
        }
        if !rest.is_empty() {
            return None;
        }
    }
    Some(out)
}

/// Byte offset where the value at TOML path `field` is written (for a table: its header, or
/// its key when inline or dotted). A path that is not in the file (a key left out) gives the
/// place of its deepest ancestor that is; `None` when not even the first key is present.
pub fn path_offset(doc: &DeTable<'_>, field: &str) -> Option<usize> {
    let mut found: Option<usize> = None;
    let mut table = Some(doc);
    let mut value: Option<&Spanned<DeValue<'_>>> = None;
    for step in steps(field)? {
        let next = match (step, table, value.map(|v| v.get_ref())) {
            (Step::Key(k), Some(t), _) => t.iter().find(|(key, _)| key.get_ref() == k).map(|(_, v)| v),
            (Step::Index(i), _, Some(DeValue::Array(a))) => a.get(i),
            _ => None,
        };
        let Some(v) = next else { break };
        found = Some(v.span().start);
        value = Some(v);
        table = match v.get_ref() {
            DeValue::Table(t) => Some(t),
            _ => None,
        };
    }
    found
}

/// Adds the line and column of its field to a scenario error about `file` (`text` is the
/// file's content); other errors, and fields not found in the text, are returned unchanged.
pub fn locate(err: Error, file: &Path, text: &str) -> Error {
    let Error::Scenario { file: f, at: None, field, .. } = &err else { return err };
    if *f != file.display().to_string() {
        return err;
    }
    let Ok(doc) = DeTable::parse(text) else { return err };
    match path_offset(doc.get_ref(), field) {
        Some(off) => {
            let (l, c) = line_col(text, off);
            err.at(l, c)
        }
        None => err,
    }
}

/// Parses scenario TOML; `file` names the source in errors.
pub fn parse_scenario_str(file: &Path, text: &str) -> Result<ScenarioFile> {
    // Syntax first: a spanned tree for locating later schema errors.
    let doc = DeTable::parse(text).map_err(|e| {
        let span = e.span().unwrap_or(0..0);
        let (l, c) = line_col(text, span.start);
        Error::scenario(file, "<syntax>", snippet(text, &span), format!("malformed TOML: {}", e.message()))
            .at(l, c)
    })?;
    toml::from_str::<ScenarioFile>(text).map_err(|e| {
        let span = e.span().unwrap_or(0..0);
        let (l, c) = line_col(text, span.start);
        let mut path = String::new();
        path_at(doc.get_ref(), span.start, &mut path);
        if path.is_empty() {
            path.push_str("<document>");
        }
        Error::scenario(file, path, snippet(text, &span), e.message()).at(l, c)
    })
}

/// Reads and parses a scenario file.
pub fn parse_scenario_file(path: &Path) -> Result<ScenarioFile> {
    let text = read_scenario_text(path)?;
    parse_scenario_str(path, &text)
}

/// A scenario file's text.
pub fn read_scenario_text(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|e| Error::io(path, e))
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
        assert!(e.starts_with("f.toml:16:1: "), "{e}");
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
        assert!(e.starts_with("f.toml:2:") && e.contains("malformed TOML"), "{e}");
    }

    #[test]
    fn missing_field_is_reported() {
        let e = err("version = 1\nid = \"x\"\ncategory = \"01_pedestrian\"\n[ego]\n");
        assert!(e.contains("map"), "{e}");
    }

    fn at(text: &str, field: &str) -> Option<(usize, usize)> {
        let doc = DeTable::parse(text).unwrap();
        path_offset(doc.get_ref(), field).map(|o| line_col(text, o))
    }

    #[test]
    fn paths_map_to_where_they_are_written() {
        let t = format!(
            "{MIN}route_edges = [\"A\",\n  \"B\"]\n\n[[actors]]\nkind = \"car\"\n\n[[actors]]\nkind = \"car\"\nroute = {{ lanes = [\"a_0\", \"b_0\"] }}\nstart = {{ ego_within_m = 5.0, of = [1.0, 2.0] }}\n"
        );
        // MIN is 8 lines after its leading newline: [ego] is line 6.
        assert_eq!(at(&t, "ego"), Some((6, 1)));
        assert_eq!(at(&t, "ego.destination"), Some((8, 15)));
        assert_eq!(at(&t, "ego.route_edges[1]"), Some((10, 3)));
        assert_eq!(at(&t, "actors[1]"), Some((15, 1)));
        assert_eq!(at(&t, "actors[1].route.lanes[1]"), Some((17, 27)));
        assert_eq!(at(&t, "actors[1].start.of[1]"), Some((18, 42)));
        // Absent keys: the deepest ancestor that is written.
        assert_eq!(at(&t, "actors[0].waypoints"), Some((12, 1)));
        assert_eq!(at(&t, "ego.start.s"), Some((7, 9)));
        assert_eq!(at(&t, "obstacles[0].at"), None);
        assert_eq!(at(&t, "<document>"), None);
    }

    #[test]
    fn locate_adds_line_and_column_to_resolution_errors() {
        let f = Path::new("f.toml");
        let e = locate(Error::scenario(f, "ego.destination.x", 50, "too far"), f, MIN).to_string();
        assert_eq!(e, "f.toml:8:21: field `ego.destination.x` = 50: too far");
        // Another file's error stays as it is.
        let e = locate(Error::scenario("g.toml", "ego", 1, "x"), f, MIN).to_string();
        assert_eq!(e, "g.toml: field `ego` = 1: x");
    }
}
