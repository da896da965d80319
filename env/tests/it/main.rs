//! The crate's integration tests, one module per area, in one test binary: one link and
//! one copy of the dependencies' generic code instead of one per file.

mod common;

mod drive_pipeline;
mod fuzz_regressions;
mod map_parse;
mod map_perf;
mod map_real;
mod module_cycles;
mod render_conditions;
mod render_golden;
mod render_semantic;
mod render_surface;
mod scenario_errors;
mod scenario_features;
mod scenario_hazards;
mod scenario_r4;
mod score_cases;
mod score_rescore;
mod sim_episode;
mod sumo_cosim;
mod traffic_world;
mod world_basic;
