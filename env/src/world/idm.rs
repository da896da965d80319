//! Native reactive background traffic (work in progress).

use super::traffic::{TrafficFrame, TrafficInput, TrafficModel};
use crate::scenario::ResolvedScenario;
use crate::{Error, Result};

/// IDM car-following on the lane graph.
#[derive(Debug)]
pub struct IdmTraffic {}

impl IdmTraffic {
    pub fn new(_scenario: &ResolvedScenario) -> Result<IdmTraffic> {
        Err(Error::config("traffic", "native", "the native traffic mode is not available in this build"))
    }
}

impl TrafficModel for IdmTraffic {
    fn start(&mut self, _input: &TrafficInput<'_>, _seed: u64, _out: &mut TrafficFrame) -> Result<()> {
        Ok(())
    }
    fn tick(&mut self, _input: &TrafficInput<'_>, _out: &mut TrafficFrame) -> Result<()> {
        Ok(())
    }
    fn name(&self) -> &str {
        "native"
    }
}
