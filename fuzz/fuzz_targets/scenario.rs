//! A simulator scenario file (YAML), through the loader `sim run` and `eval` use.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use sim::Scenario;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(scenario) = Scenario::from_yaml(text, Path::new("fuzz.yaml")) {
        // What loads has passed its own validation; checking again must agree.
        scenario.validate().expect("a loaded scenario is valid");
    }
});
