//! JSON Schema of the scenario file, generated from the serde types of [`super::schema`] and
//! [`super::traffic`] with `schemars` (committed as `docs/scenario.schema.json`; editors use it
//! for completion and checks, e.g. Taplo's `#:schema` directive).
//!
//! What serde accepts is the base (every table `additionalProperties: false`, defaults,
//! descriptions from the doc comments). TOML has no null, so the `null` that `Option` adds is
//! dropped. The alternatives that the Rust types keep as flat optional fields (so that the
//! resolver can name the wrong field) are added as `oneOf`/`not` constraints by the transforms
//! of [`super::schema_rules`]; the resolver stays the authority on values that need the map.

use super::schema::ScenarioFile;
use super::tables::SCENARIO_VERSION;
use schemars::generate::SchemaSettings;
use schemars::transform::{transform_subschemas, Transform};
use schemars::Schema;
use serde_json::{json, Value};

/// `$id` of the published schema (repo-relative file name).
pub const SCHEMA_ID: &str = "scenario.schema.json";

/// The scenario-file JSON Schema (draft 07, which Taplo / Even Better TOML and the Python
/// `jsonschema` package read).
pub fn scenario_json_schema() -> Value {
    // DropNull first: draft 07's own transforms then move `$ref` siblings into `allOf`.
    let generator =
        SchemaSettings::draft07().with(|s| s.transforms.insert(0, Box::new(DropNull))).into_generator();
    let mut schema = generator.into_root_schema_for::<ScenarioFile>();
    schema.insert("$id".into(), json!(SCHEMA_ID));
    schema.insert(
        "title".into(),
        json!(format!("DriveHierarchy R4 scenario file (version {SCENARIO_VERSION})")),
    );
    schema.insert("description".into(), json!("One R4 scenario in TOML; see docs/scenario-format.md."));
    schema.to_value()
}

/// [`scenario_json_schema`] as pretty JSON with a trailing newline (the committed file).
pub fn scenario_json_schema_string() -> String {
    let mut s = serde_json::to_string_pretty(&scenario_json_schema()).expect("a JSON value serialises");
    s.push('\n');
    s
}

/// Removes `null` from `Option` fields (`type: [T, "null"]`, `anyOf: [T, {type: null}]`,
/// `default: null`): a TOML key is either absent or has a value.
#[derive(Debug, Clone)]
struct DropNull;

impl Transform for DropNull {
    fn transform(&mut self, schema: &mut Schema) {
        transform_subschemas(self, schema);
        let Some(obj) = schema.as_object_mut() else { return };
        if obj.get("default") == Some(&Value::Null) {
            obj.remove("default");
        }
        if let Some(Value::Array(types)) = obj.get_mut("type") {
            types.retain(|t| *t != "null");
            if types.len() == 1 {
                let t = types.remove(0);
                obj.insert("type".into(), t);
            }
        }
        if let Some(Value::Array(alts)) = obj.get_mut("anyOf") {
            alts.retain(|a| a.get("type") != Some(&json!("null")));
            if alts.len() == 1 {
                let only = alts.remove(0);
                obj.remove("anyOf");
                match only {
                    Value::Object(m) => {
                        for (k, v) in m {
                            obj.entry(k).or_insert(v);
                        }
                    }
                    other => {
                        obj.insert("allOf".into(), json!([other]));
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_reject_unknown_keys_and_options_are_not_nullable() {
        let s = scenario_json_schema();
        assert_eq!(s["additionalProperties"], json!(false));
        assert_eq!(s["definitions"]["PlaceSpec"]["additionalProperties"], json!(false));
        assert_eq!(s["definitions"]["TrafficSpec"]["additionalProperties"], json!(false));
        assert!(!scenario_json_schema_string().contains("\"null\""), "TOML has no null");
        assert_eq!(s["properties"]["version"]["const"], json!(SCENARIO_VERSION));
    }

    #[test]
    fn committed_schema_is_current() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/scenario.schema.json");
        let committed = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(
            committed == scenario_json_schema_string(),
            "docs/scenario.schema.json is stale: `drivehierarchy scenario schema --out docs/scenario.schema.json`"
        );
    }
}
