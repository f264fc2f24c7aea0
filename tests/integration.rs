//! The integration tests, one module per concern (`tests/<concern>.rs`), built as one test binary:
//! one link and one instantiation of the core's generic code instead of one per file (the
//! integration tests took about 1,000 CPU seconds to build as 25 binaries). Run one concern with
//! `cargo test --release --test integration <concern>::`. `no_alloc.rs` joined them (as a binary
//! of its own it instantiated the solver again: a 167-second unit for three tests); its counting
//! global allocator counts per thread, and libtest runs each test on a thread of its own.

mod common;

mod bad_scenes;
mod between_evaluations;
mod catalog;
mod cli;
mod cli_bounds;
mod cli_outputs;
mod closures;
mod conditioning;
mod fast_paths;
mod formulations;
mod fuzz_props;
mod hard_cases;
mod input_files;
mod layering;
mod mjcf_import;
mod no_alloc;
mod paper_examples;
mod rolling;
mod scene_order;
mod scenes;
mod schema;
mod servo;
mod servo_cli;
mod servo_internal;
mod testset;
mod urdf_import;
mod vocabulary;
