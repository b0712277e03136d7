//! Fuzz the table reader (covariates, batch pairs, subject lists) and
//! writer (index.csv): no panic on any input, and every table that parses
//! is written back to the same cells (`test_support::table_round_trip`,
//! which `cargo test` replays on this target's committed corpus).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    fshape_mesh::test_support::table_round_trip(data);
});
