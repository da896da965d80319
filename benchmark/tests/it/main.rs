//! The crate's integration tests, one module per area, in one test binary: one link and
//! one copy of the dependencies' generic code instead of one per file.

mod original_layout;
mod paper_table1;
mod parsers_never_panic;
