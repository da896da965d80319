//! `dh-benchmark`: the open-loop R1–R3 suite.
