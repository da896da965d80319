//! Light and weather of an episode (`[conditions]` in a scenario file, `[variation] conditions`
//! per seed, or a run-wide override): plain data read by the scenario loader and drawn by
//! `render` (`render::conditions`). They never change the world, only the pictures.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Time of day.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum TimeOfDay {
    /// High sun, the default.
    #[default]
    Noon,
    /// Low warm sun, long shadows, dimmer sky light.
    Dusk,
    /// Dark sky; vehicle headlamps and street lights light the road.
    Night,
}

/// Weather.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Weather {
    /// The default.
    #[default]
    Clear,
    /// Flat grey sky, no hard shadows.
    Overcast,
    /// Overcast, a wet road that mirrors the sky and lights, drops on the camera lens.
    Rain,
    /// Everything fades to the fog colour with distance (visibility about 60 m).
    Fog,
}

impl TimeOfDay {
    pub const ALL: [TimeOfDay; 3] = [TimeOfDay::Noon, TimeOfDay::Dusk, TimeOfDay::Night];
    pub fn as_str(self) -> &'static str {
        match self {
            TimeOfDay::Noon => "noon",
            TimeOfDay::Dusk => "dusk",
            TimeOfDay::Night => "night",
        }
    }
}

impl Weather {
    pub const ALL: [Weather; 4] = [Weather::Clear, Weather::Overcast, Weather::Rain, Weather::Fog];
    pub fn as_str(self) -> &'static str {
        match self {
            Weather::Clear => "clear",
            Weather::Overcast => "overcast",
            Weather::Rain => "rain",
            Weather::Fog => "fog",
        }
    }
}

/// `[conditions]` as written (both keys optional: noon, clear).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ConditionsSpec {
    /// noon (default) | dusk | night.
    #[serde(default)]
    pub time_of_day: Option<TimeOfDay>,
    /// clear (default) | overcast | rain | fog.
    #[serde(default)]
    pub weather: Option<Weather>,
}

/// The conditions an episode is drawn under.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct Conditions {
    pub time_of_day: TimeOfDay,
    pub weather: Weather,
}

impl From<ConditionsSpec> for Conditions {
    fn from(s: ConditionsSpec) -> Self {
        Conditions { time_of_day: s.time_of_day.unwrap_or_default(), weather: s.weather.unwrap_or_default() }
    }
}

impl Conditions {
    /// Every combination, noon/clear first.
    pub fn all() -> impl Iterator<Item = Conditions> {
        TimeOfDay::ALL
            .into_iter()
            .flat_map(|t| Weather::ALL.into_iter().map(move |w| Conditions { time_of_day: t, weather: w }))
    }

    /// The short name: `noon`, `night`, `rain`, `night+rain`, ... (the default part left out;
    /// noon/clear is `noon`).
    pub fn name(self) -> String {
        match (self.time_of_day, self.weather) {
            (t, Weather::Clear) => t.as_str().to_owned(),
            (TimeOfDay::Noon, w) => w.as_str().to_owned(),
            (t, w) => format!("{}+{}", t.as_str(), w.as_str()),
        }
    }

    /// Parses a name: a time of day, a weather, or `time+weather` (either order; the part left
    /// out takes its default). `Err` holds the reason.
    pub fn parse(name: &str) -> std::result::Result<Conditions, String> {
        let mut c = Conditions::default();
        let (mut time, mut weather) = (false, false);
        for part in name.split('+') {
            let part = part.trim();
            if let Some(t) = TimeOfDay::ALL.into_iter().find(|t| t.as_str() == part) {
                if std::mem::replace(&mut time, true) {
                    return Err(format!("`{name}` names two times of day"));
                }
                c.time_of_day = t;
            } else if let Some(w) = Weather::ALL.into_iter().find(|w| w.as_str() == part) {
                if std::mem::replace(&mut weather, true) {
                    return Err(format!("`{name}` names two weathers"));
                }
                c.weather = w;
            } else {
                return Err(format!(
                    "unknown condition `{part}`: expected a time of day ({}), a weather ({}) or \
                     time+weather, e.g. night+rain",
                    TimeOfDay::ALL.map(TimeOfDay::as_str).join(", "),
                    Weather::ALL.map(Weather::as_str).join(", ")
                ));
            }
        }
        Ok(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_bad_names_are_refused() {
        for c in Conditions::all() {
            assert_eq!(Conditions::parse(&c.name()), Ok(c), "{}", c.name());
        }
        assert_eq!(Conditions::default().name(), "noon");
        assert_eq!(
            Conditions::parse("rain+dusk"),
            Ok(Conditions { time_of_day: TimeOfDay::Dusk, weather: Weather::Rain })
        );
        assert_eq!(Conditions::parse("clear"), Ok(Conditions::default()));
        assert!(Conditions::parse("midnight").unwrap_err().contains("midnight"));
        assert!(Conditions::parse("night+dusk").is_err());
        assert!(Conditions::parse("").is_err());
    }
}
