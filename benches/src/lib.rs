//! Shared problem definitions for the benchmarks.
