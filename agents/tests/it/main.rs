//! The crate's integration tests, one module per area, in one test binary: one link and
//! one copy of the dependencies' generic code instead of one per file.

mod expert_support;

mod expert_closed_loop;
mod expert_features;
mod expert_r4;
mod expert_tongji;
mod expert_town01;
mod expert_unit;
mod lateral_motion;
mod vlm_props;
