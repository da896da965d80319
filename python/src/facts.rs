//! `_core.constants()`: the Rust facts that Python and the editor page need (step length,
//! categories, termination reasons, the scenario format's enums), read from the Rust items
//! themselves so that no other copy exists. Enum names come from each type's JSON Schema
//! (`schemars`, i.e. what serde reads), so a new variant shows up here without an edit.

use dh_env::conditions::{TimeOfDay, Weather};
use dh_env::map::VClass;
use dh_env::render::CameraFault;
use dh_env::scenario::schema::{ActorSpec, AtEndSpec, BehaviorSpec, BrakeSpec, ChainEventSpec, TriggerSpec};
use dh_env::scenario::traffic::{
    parse_vtypes, LaneChoice, SpeedChoice, BUILTIN_VTYPES, BUILTIN_VTYPES_NAME, DEFAULT_VTYPE,
};
use dh_env::scenario::{vclass_of, TrafficMode, CATEGORIES, EGO_VCLASS, OF_RULES, SCENARIO_VERSION};
use dh_env::score::TerminationReason;
use dh_env::view::{ActorKind, SignKind};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use schemars::JsonSchema;
use serde::de::DeserializeOwned;
use serde_json::Value;

/// The string values serde accepts for `T`, in declaration order: the `enum` / `const` of its
/// schema and of its `oneOf` / `anyOf` alternatives (the string names of an untagged enum).
fn names<T: JsonSchema>() -> Vec<String> {
    fn collect(v: &Value, out: &mut Vec<String>) {
        let strings = v.get("enum").and_then(Value::as_array).into_iter().flatten().chain(v.get("const"));
        out.extend(strings.filter_map(Value::as_str).map(str::to_owned));
        for key in ["oneOf", "anyOf"] {
            for alt in v.get(key).and_then(Value::as_array).into_iter().flatten() {
                collect(alt, out);
            }
        }
    }
    let mut out = Vec::new();
    collect(&schemars::schema_for!(T).to_value(), &mut out);
    out
}

/// The variant of `T` that serde reads from `name`.
fn variant<T: DeserializeOwned>(name: &str) -> PyResult<T> {
    serde_json::from_value(Value::String(name.to_owned())).map_err(|e| {
        PyRuntimeError::new_err(format!("`{name}` is listed by the schema but not read by serde: {e}"))
    })
}

/// Keys of a struct's table as written in a scenario file (its schema's `properties`).
fn keys<T: JsonSchema>() -> Vec<String> {
    let schema = schemars::schema_for!(T).to_value();
    schema
        .get("properties")
        .and_then(Value::as_object)
        .map(|p| p.keys().cloned().collect())
        .unwrap_or_default()
}

/// The keys that pick one of a table's exclusive forms (a start trigger's `time_s`,
/// `ego_within_m`, ...): the first required key of each `oneOf` alternative of its schema.
fn alternatives<T: JsonSchema>() -> Vec<String> {
    let schema = schemars::schema_for!(T).to_value();
    let alts = schema.get("allOf").and_then(Value::as_array).into_iter().flatten();
    alts.filter_map(|a| a.get("oneOf").and_then(Value::as_array))
        .flatten()
        .filter_map(|alt| alt.pointer("/allOf/0/required/0").and_then(Value::as_str))
        .map(str::to_owned)
        .collect()
}

/// The Rust facts as one plain dict (see `_core.pyi` for its keys).
#[pyfunction]
fn constants(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("tick_s", dh_env::DT_S)?;
    d.set_item("ticks_per_decision", dh_env::DECISION_INTERVAL_TICKS)?;
    d.set_item("decision_hz", 1.0 / (dh_env::DT_S * f64::from(dh_env::DECISION_INTERVAL_TICKS)))?;
    d.set_item("warmup_ticks", dh_env::sim::WARMUP_TICKS)?;
    d.set_item("scenario_version", SCENARIO_VERSION)?;
    d.set_item("categories", CATEGORIES.to_vec())?;
    d.set_item("termination_reasons", names::<TerminationReason>())?;
    d.set_item("openloop_tasks", dh_benchmark::TASKS.iter().map(|t| t.name).collect::<Vec<_>>())?;

    let kinds = names::<ActorKind>();
    let (mut statics, mut moving) = (Vec::new(), Vec::new());
    let vclass = PyDict::new(py);
    for k in &kinds {
        let kind: ActorKind = variant(k)?;
        if kind.is_static() { &mut statics } else { &mut moving }.push(k.clone());
        vclass.set_item(k, VClass::sumo_name(vclass_of(kind)))?;
    }
    d.set_item("kinds", &kinds)?;
    // Scripted actors move; an obstacle may be any kind, the static ones first (the usual pick).
    d.set_item("actor_kinds", &moving)?;
    d.set_item("obstacle_kinds", statics.iter().chain(&moving).collect::<Vec<_>>())?;
    d.set_item("vclass_of", vclass)?;
    d.set_item("actor_keys", keys::<ActorSpec>())?;
    d.set_item("behaviors", names::<BehaviorSpec>())?;
    d.set_item("at_end", names::<AtEndSpec>())?;
    d.set_item("chain_events", names::<ChainEventSpec>())?;
    d.set_item("start_triggers", alternatives::<TriggerSpec>())?;
    d.set_item("brake_triggers", alternatives::<BrakeSpec>())?;
    d.set_item("sign_kinds", names::<SignKind>())?;
    d.set_item("depart_lanes", names::<LaneChoice>())?;
    d.set_item("depart_speeds", names::<SpeedChoice>())?;
    d.set_item("ego_vclass", EGO_VCLASS.sumo_name())?;
    let vtypes = parse_vtypes(BUILTIN_VTYPES_NAME, BUILTIN_VTYPES)
        .map_err(|e| PyRuntimeError::new_err(format!("the shipped vehicle types do not parse: {e}")))?;
    // id -> SUMO class, in file order: the editor snaps a traffic row's route to its type's class.
    let shipped = PyDict::new(py);
    for t in &vtypes {
        shipped.set_item(&t.id, t.vclass.sumo_name())?;
    }
    d.set_item("builtin_vtypes", shipped)?;
    d.set_item("default_vtype", DEFAULT_VTYPE)?;
    let rules = PyList::empty(py);
    for r in OF_RULES {
        let rule = PyDict::new(py);
        rule.set_item("table", r.table)?;
        rule.set_item("key", r.key)?;
        rule.set_item("actor_self", r.actor_self)?;
        rule.set_item("required", r.required)?;
        rules.append(rule)?;
    }
    d.set_item("of_rules", rules)?;
    d.set_item("times_of_day", names::<TimeOfDay>())?;
    d.set_item("weathers", names::<Weather>())?;
    d.set_item("camera_faults", CameraFault::ALL.map(CameraFault::as_str).to_vec())?;

    let modes = names::<TrafficMode>();
    for m in &modes {
        variant::<TrafficMode>(m)?;
    }
    d.set_item("traffic_modes", modes)?;
    let old = PyDict::new(py);
    for (name, mode) in TrafficMode::DEPRECATED_NAMES {
        old.set_item(name, mode.as_str())?;
    }
    d.set_item("deprecated_traffic_modes", old)?;
    Ok(d)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(constants, m)?)?;
    Ok(())
}
