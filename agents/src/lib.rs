//! `dh-agents`: policies that must be fast or fuzzable.

pub mod expert;
pub mod plan_reply;
pub mod vlm;
