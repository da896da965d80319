//! drive (in progress)
