//! Fuzz the TOML configuration: no panic on any input, and every
//! configuration that parses is written (`Config::to_toml`) to a text that
//! parses to the same configuration. `cargo test -p fshape-match` replays
//! this target's committed corpus with the same property.
#![no_main]

use fshape_match::Config;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(config) = Config::parse(text) else { return };
    let written = config.to_toml();
    let back = Config::parse(&written).expect("our own TOML parses");
    assert_eq!(back.to_toml(), written);
});
