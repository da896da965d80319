//! `dh-agents`: policies that must be fast or fuzzable.

pub mod expert;
pub mod vlm;
