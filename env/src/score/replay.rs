//! Run log (JSONL) and re-scoring without the simulator.
//!
//! A run log is one JSON object per line, tagged by `"kind"`:
//! ```text
//! {"kind":"header","protocol_version":"drivehierarchy-r4/2","scene_id":"…","route":[[x,y],…],
//!  "start":[x,y],"start_on_road":true,"destination":[x,y],"reference_duration_s":12.5|null,
//!  "scenario_duration_s":30.0|null,"params":{…}}
//! {"kind":"tick","tick":1,"time_s":0.05,"x":…,"y":…,"yaw":…,"speed_mps":…,"on_road":true,
//!  "contacts":[{"actor_id":3,"class":"vehicle"}],"red_light":false,"stop_sign":false,"stop":null}
//! …
//! {"kind":"end","wall_duration_s":…,"decisions":…,"parse_failures":…}
//! ```
//! `contacts`, `red_light`, `stop_sign` and `stop` may be omitted when empty/false/null.
//! Floats are written shortest-round-trip (serde_json / Python `json`) and read back exactly,
//! so [`rescore`] reproduces the live [`ScoreTracker`] bit for bit.

use super::event::{Contact, ExternalStop, TickInput};
use super::params::ScoreParams;
use super::record::{RunInfo, SceneScore, PROTOCOL_VERSION};
use super::tracker::ScoreTracker;
use crate::geom::{Polyline, Vec2};
use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// First line of a run log: everything the score depends on besides the ticks.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunHeader {
    pub protocol_version: String,
    pub scene_id: String,
    /// Scoring route polyline, world frame.
    pub route: Vec<[f64; 2]>,
    pub start: [f64; 2],
    /// Whether the ego centre was on the road at t = 0 (sample 0).
    #[serde(default = "yes")]
    pub start_on_road: bool,
    pub destination: [f64; 2],
    pub reference_duration_s: Option<f64>,
    /// The scenario duration (the timeout is 2 × it); `null` → the reference duration.
    #[serde(default)]
    pub scenario_duration_s: Option<f64>,
    pub params: ScoreParams,
}

fn yes() -> bool {
    true
}

impl RunHeader {
    /// Header for a run scored with `route` (the same polyline the tracker gets).
    pub fn new(
        scene_id: impl Into<String>,
        route: &Polyline,
        start: Vec2,
        destination: Vec2,
        reference_duration_s: Option<f64>,
        params: ScoreParams,
    ) -> Self {
        Self {
            protocol_version: PROTOCOL_VERSION.to_owned(),
            scene_id: scene_id.into(),
            route: route.points().iter().map(|p| [p.x, p.y]).collect(),
            start: [start.x, start.y],
            start_on_road: true,
            destination: [destination.x, destination.y],
            reference_duration_s,
            scenario_duration_s: None,
            params,
        }
    }

    /// Sets the scenario duration and whether the start is on the road.
    pub fn with_scenario(mut self, scenario_duration_s: Option<f64>, start_on_road: bool) -> Self {
        self.scenario_duration_s = scenario_duration_s;
        self.start_on_road = start_on_road;
        self
    }

    /// A fresh tracker configured as the live run's was.
    pub fn tracker(&self) -> Result<ScoreTracker> {
        let route = Polyline::new(self.route.iter().map(|p| Vec2::new(p[0], p[1])).collect());
        ScoreTracker::new(
            route,
            Vec2::new(self.start[0], self.start[1]),
            Vec2::new(self.destination[0], self.destination[1]),
            self.reference_duration_s,
            self.params.clone(),
        )?
        .with_scenario_duration(self.scenario_duration_s)
        .map(|t| t.with_start_on_road(self.start_on_road))
    }
}

fn is_false(b: &bool) -> bool {
    !*b
}

/// The ego state after one tick, plus what happened to it during the tick.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrajectorySample {
    /// 1-based tick index.
    pub tick: u64,
    /// Sim time after the tick (informational; scoring uses tick × dt).
    pub time_s: f64,
    pub x: f64,
    pub y: f64,
    /// Radians, counter-clockwise from +x (not used by the score).
    pub yaw: f64,
    pub speed_mps: f64,
    pub on_road: bool,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub contacts: Vec<Contact>,
    #[serde(default, skip_serializing_if = "is_false")]
    pub red_light: bool,
    #[serde(default, skip_serializing_if = "is_false")]
    pub stop_sign: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stop: Option<ExternalStop>,
}

impl TrajectorySample {
    pub fn tick_input(&self) -> TickInput<'_> {
        TickInput {
            position: Vec2::new(self.x, self.y),
            speed_mps: self.speed_mps,
            on_road: self.on_road,
            contacts: &self.contacts,
            red_light: self.red_light,
            stop_sign: self.stop_sign,
            stop: self.stop,
        }
    }
}

/// Last line of a run log.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunFooter {
    pub wall_duration_s: f64,
    pub decisions: u64,
    pub parse_failures: u64,
    /// Set when the runner stopped the run between ticks (after the last sample).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stop: Option<ExternalStop>,
}

/// One line of a run log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum LogLine {
    Header(Box<RunHeader>),
    Tick(TrajectorySample),
    End(RunFooter),
}

impl LogLine {
    /// The line's `kind` tag, as written.
    pub fn kind(&self) -> &'static str {
        match self {
            LogLine::Header(_) => "header",
            LogLine::Tick(_) => "tick",
            LogLine::End(_) => "end",
        }
    }

    /// The line as compact JSON, without the trailing newline.
    pub fn to_json(&self) -> String {
        // Serialising these plain structs cannot fail (no maps with non-string keys); NaN
        // floats become `null` and are rejected when read back.
        serde_json::to_string(self).unwrap_or_default()
    }
}

/// A whole run log.
#[derive(Debug, Clone, PartialEq)]
pub struct RunLog {
    pub header: RunHeader,
    pub samples: Vec<TrajectorySample>,
    pub footer: RunFooter,
}

impl RunLog {
    /// Parses JSONL text; `source` names the file in errors (with the 1-based line number).
    pub fn from_jsonl(text: &str, source: &str) -> Result<RunLog> {
        let mut lines = Vec::new();
        for (i, line) in text.lines().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let where_ = format!("line {}", i + 1);
            let parsed: LogLine = serde_json::from_str(line).map_err(|e| {
                Error::scenario(source, &where_, truncate(line), format!("not a run-log line: {e}"))
            })?;
            lines.push((where_, parsed));
        }
        Self::from_lines(lines, source)
    }

    /// Assembles parsed lines (each with where it came from, for errors): the header first and
    /// once, ticks, then the `end` line last.
    pub fn from_lines(lines: impl IntoIterator<Item = (String, LogLine)>, source: &str) -> Result<RunLog> {
        let mut header = None;
        let mut samples = Vec::new();
        let mut footer = None;
        for (where_, parsed) in lines {
            if footer.is_some() {
                return Err(Error::scenario(source, &where_, parsed.kind(), "line after the `end` line"));
            }
            match parsed {
                LogLine::Header(h) => {
                    if header.is_some() || !samples.is_empty() {
                        return Err(Error::scenario(
                            source,
                            &where_,
                            "header",
                            "the header must be the first line, once",
                        ));
                    }
                    header = Some(*h);
                }
                LogLine::Tick(s) => {
                    if header.is_none() {
                        return Err(Error::scenario(source, &where_, "tick", "tick before the header"));
                    }
                    samples.push(s);
                }
                LogLine::End(f) => footer = Some(f),
            }
        }
        let header = header.ok_or_else(|| Error::scenario(source, "header", "missing", "no header line"))?;
        let footer = footer
            .ok_or_else(|| Error::scenario(source, "end", "missing", "no `end` line (run not finished?)"))?;
        Ok(RunLog { header, samples, footer })
    }

    /// The log's lines in file order: header, ticks, end.
    pub fn lines(&self) -> impl Iterator<Item = LogLine> + '_ {
        std::iter::once(LogLine::Header(Box::new(self.header.clone())))
            .chain(self.samples.iter().cloned().map(LogLine::Tick))
            .chain(std::iter::once(LogLine::End(self.footer.clone())))
    }

    pub fn read_jsonl(path: impl AsRef<Path>) -> Result<RunLog> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Self::from_jsonl(&text, &path.display().to_string())
    }

    pub fn to_jsonl(&self) -> String {
        let mut out = String::with_capacity(128 * (self.samples.len() + 2));
        for line in self.lines() {
            out.push_str(&line.to_json());
            out.push('\n');
        }
        out
    }

    /// Re-scores this log; see [`rescore`].
    pub fn rescore(&self) -> Result<SceneScore> {
        rescore(&self.header, &self.samples, &self.footer)
    }
}

fn truncate(s: &str) -> String {
    let mut t: String = s.chars().take(80).collect();
    if t.len() < s.len() {
        t.push('…');
    }
    t
}

/// Replays the score tracker over recorded ticks. Samples must be ticks 1, 2, … in order and
/// must stop at the tick that terminated the run. The result equals the live record.
pub fn rescore(header: &RunHeader, samples: &[TrajectorySample], footer: &RunFooter) -> Result<SceneScore> {
    if header.protocol_version != PROTOCOL_VERSION {
        return Err(Error::config(
            "protocol_version",
            &header.protocol_version,
            format!("this build scores {PROTOCOL_VERSION}"),
        ));
    }
    let mut tracker = header.tracker()?;
    for (i, s) in samples.iter().enumerate() {
        let want = i as u64 + 1;
        if s.tick != want {
            return Err(Error::config(format!("samples[{i}].tick"), s.tick, format!("expected tick {want}")));
        }
        if let Some(t) = tracker.termination() {
            return Err(Error::config(
                format!("samples[{i}]"),
                s.tick,
                format!("the run terminated at tick {} ({})", t.tick, t.reason.as_str()),
            ));
        }
        tracker.update(&s.tick_input());
    }
    if let Some(stop) = footer.stop {
        tracker.stop(stop);
    }
    Ok(tracker.finish(&RunInfo {
        scene_id: header.scene_id.clone(),
        wall_duration_s: footer.wall_duration_s,
        decisions: footer.decisions,
        parse_failures: footer.parse_failures,
    }))
}
