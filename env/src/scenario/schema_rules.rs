//! The schema transforms named by `#[schemars(transform = ...)]` on the scenario's serde types
//! (see [`super::json_schema`] for what they add). They depend only on [`super::tables`], so
//! `schema` and `traffic` can name them while `json_schema` builds the schema from `schema`.

use super::tables::{CATEGORIES, LANE_NAMES, SCENARIO_VERSION, SPEED_NAMES};
use schemars::Schema;
use serde_json::{json, Map, Value};

fn obj(schema: &mut Schema) -> &mut Map<String, Value> {
    schema.ensure_object()
}

fn required(keys: &[&str]) -> Value {
    json!({ "required": keys })
}

/// A schema that fails when any of `keys` is present.
fn none_of(keys: &[&str]) -> Value {
    json!({ "not": { "anyOf": keys.iter().map(|k| required(&[*k])).collect::<Vec<_>>() } })
}

fn push_all_of(schema: &mut Schema, v: Value) {
    let o = obj(schema);
    match o.get_mut("allOf") {
        Some(Value::Array(a)) => a.push(v),
        _ => {
            o.insert("allOf".into(), json!([v]));
        }
    }
}

/// A place: `lane` (+ `s`, `offset_m`) or both `x` and `y`, never both forms.
pub(crate) fn place_alternatives(schema: &mut Schema) {
    push_all_of(
        schema,
        json!({ "oneOf": [
            { "allOf": [required(&["lane"]), none_of(&["x", "y"])] },
            { "allOf": [required(&["x", "y"]), none_of(&["lane", "s", "offset_m"])] },
        ]}),
    );
}

/// Start trigger: exactly one of `time_s`, `ego_within_m` / `ego_eta_s` (with an optional
/// `of`) and `after` (with optional `delay_s`, `event`).
pub(crate) fn trigger_alternatives(schema: &mut Schema) {
    let chain = ["after", "delay_s", "event"];
    push_all_of(
        schema,
        json!({ "oneOf": [
            { "allOf": [required(&["time_s"]), none_of(&["ego_within_m", "ego_eta_s", "of", "after", "delay_s", "event"])] },
            { "allOf": [required(&["ego_within_m"]), none_of(&["time_s", "ego_eta_s"]), none_of(&chain)] },
            { "allOf": [required(&["ego_eta_s"]), none_of(&["time_s", "ego_within_m"]), none_of(&chain)] },
            { "allOf": [required(&["after"]), none_of(&["time_s", "ego_within_m", "ego_eta_s", "of"])] },
        ]}),
    );
}

/// Light override: at least one of `offset_s`, `start_phase`, `phases`; `offset_s` and
/// `start_phase` exclude each other; `phase_elapsed_s` needs `start_phase`.
pub(crate) fn light_alternatives(schema: &mut Schema) {
    push_all_of(
        schema,
        json!({ "anyOf": [required(&["offset_s"]), required(&["start_phase"]), required(&["phases"])] }),
    );
    push_all_of(schema, json!({ "not": required(&["offset_s", "start_phase"]) }));
    push_all_of(schema, json!({ "if": required(&["phase_elapsed_s"]), "then": required(&["start_phase"]) }));
}

/// Restricts the string alternative of an untagged enum to `names`.
fn string_names(schema: &mut Schema, names: &[&str]) {
    if let Some(Value::Array(alts)) = obj(schema).get_mut("anyOf") {
        for a in alts.iter_mut() {
            if a.get("type") == Some(&json!("string")) {
                a["enum"] = json!(names);
            }
        }
    }
}

/// `of` of a distance trigger: the only name is `"actor_self"`.
pub(crate) fn of_alternatives(schema: &mut Schema) {
    string_names(schema, &["actor_self"]);
}

/// `depart_lane`: an index or one of SUMO's names.
pub(crate) fn lane_names(schema: &mut Schema) {
    string_names(schema, &LANE_NAMES);
}

/// `depart_speed`: m/s or one of SUMO's names.
pub(crate) fn speed_names(schema: &mut Schema) {
    string_names(schema, &SPEED_NAMES);
}

/// Braking: exactly one of the `when` keys; `of` only with `ego_within_m` (optional) and
/// `ego_eta_s` (required there); `delay_s` / `event` only with `after`.
pub(crate) fn brake_alternatives(schema: &mut Schema) {
    let whens = [
        "at_s",
        "after_s",
        "ego_within_m",
        "ego_gap_m",
        "ego_gap_s",
        "ego_ttc_s",
        "ego_eta_s",
        "gap_held_s",
        "after",
    ];
    let chain = ["delay_s", "event"];
    let alts: Vec<Value> = whens
        .iter()
        .map(|w| {
            let others: Vec<&str> = whens.iter().copied().filter(|o| o != w).collect();
            let mut all = vec![required(&[w]), none_of(&others)];
            match *w {
                "ego_eta_s" => all.push(required(&["of"])),
                "ego_within_m" => {}
                _ => all.push(none_of(&["of"])),
            }
            if *w != "after" {
                all.push(none_of(&chain));
            }
            json!({ "allOf": all })
        })
        .collect();
    push_all_of(schema, json!({ "oneOf": alts }));
}

/// Pacing: a gap (`gap_s` and/or `gap_m`) or a conflict point `meet` (+ `offset_s`).
pub(crate) fn pace_alternatives(schema: &mut Schema) {
    push_all_of(
        schema,
        json!({ "oneOf": [
            { "allOf": [{ "anyOf": [required(&["gap_s"]), required(&["gap_m"])] }, none_of(&["meet", "offset_s"])] },
            { "allOf": [required(&["meet"]), none_of(&["gap_s", "gap_m"])] },
        ]}),
    );
}

/// Lane path: exactly one of `edges` and `lanes`; `start_lane` only with `edges`.
pub(crate) fn route_alternatives(schema: &mut Schema) {
    push_all_of(
        schema,
        json!({ "oneOf": [
            { "allOf": [required(&["edges"]), none_of(&["lanes"])] },
            { "allOf": [required(&["lanes"]), none_of(&["edges", "start_lane"])] },
        ]}),
    );
}

/// Actor: `external` actors stand `at` a place; scripted ones follow `waypoints` or a `route`.
pub(crate) fn actor_alternatives(schema: &mut Schema) {
    push_all_of(
        schema,
        json!({
            "if": { "required": ["behavior"], "properties": { "behavior": { "const": "external" } } },
            "then": { "allOf": [required(&["at"]), none_of(&["waypoints", "route"])] },
            "else": { "allOf": [
                none_of(&["at"]),
                { "oneOf": [
                    { "allOf": [required(&["waypoints"]), none_of(&["route"])] },
                    { "allOf": [required(&["route"]), none_of(&["waypoints"])] },
                ]},
            ]},
        }),
    );
}

/// Ego: a `destination` or `route_edges` (or both).
pub(crate) fn ego_alternatives(schema: &mut Schema) {
    push_all_of(schema, json!({ "anyOf": [required(&["destination"]), required(&["route_edges"])] }));
}

/// Flow: exactly one of `vehs_per_hour` and `probability`.
pub(crate) fn flow_alternatives(schema: &mut Schema) {
    push_all_of(schema, json!({ "oneOf": [required(&["vehs_per_hour"]), required(&["probability"])] }));
}

/// Top level: the version this build reads and the ten category names.
pub(crate) fn file_constraints(schema: &mut Schema) {
    if let Some(Value::Object(props)) = obj(schema).get_mut("properties") {
        if let Some(Value::Object(v)) = props.get_mut("version") {
            v.insert("const".into(), json!(SCENARIO_VERSION));
        }
        if let Some(Value::Object(c)) = props.get_mut("category") {
            c.insert("enum".into(), json!(CATEGORIES));
        }
    }
}
