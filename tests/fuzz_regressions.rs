//! Every input that once crashed a fuzz target (`fuzz/regressions/TARGET/`) through the same
//! check the target runs (`codec::fuzzing`, `protocol::fuzz_round_trip`,
//! `master::wall::fuzz_wall`), in an ordinary test: CI runs them on every change
//! without a fuzzer. Every target in `fuzz/fuzz_targets/` has its check here; a target or a
//! regression folder without one fails the test.

mod common;

use std::path::{Path, PathBuf};

use common::entries;

/// What a fuzz target runs on each input.
type Check = fn(&[u8]);

/// The check each fuzz target runs, by the target's name.
const CHECKS: [(&str, Check); 6] = [
    ("decode_bft", codec::fuzzing::decode_bft),
    ("decode_dpm", codec::fuzzing::decode_dpm),
    ("decode_nsp", codec::fuzzing::decode_nsp),
    ("decode_protocol", protocol::fuzz_round_trip),
    ("load_gltf", codec::fuzzing::load_gltf),
    ("parse_wall", master::wall::fuzz_wall),
];

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz")
}

#[test]
fn every_fuzz_target_has_its_check_here() {
    let targets: Vec<String> = entries(&fuzz_dir().join("fuzz_targets"))
        .iter()
        .filter_map(|n| n.strip_suffix(".rs").map(String::from))
        .collect();
    let checked: Vec<&str> = CHECKS.iter().map(|(n, _)| *n).collect();
    assert_eq!(targets, checked, "fuzz/fuzz_targets/ and this test's CHECKS");
}

#[test]
fn regression_inputs_pass_their_targets_checks() {
    let mut ran = 0;
    for target in entries(&fuzz_dir().join("regressions")) {
        let check = CHECKS.iter().find(|(n, _)| *n == target).map(|(_, f)| f);
        let check = check.unwrap_or_else(|| panic!("fuzz/regressions/{target}: no such fuzz target"));
        for input in entries(&fuzz_dir().join("regressions").join(&target)) {
            let path = fuzz_dir().join("regressions").join(&target).join(&input);
            let data = std::fs::read(&path).unwrap();
            if let Err(e) = std::panic::catch_unwind(|| check(&data)) {
                let why = e.downcast_ref::<String>().cloned().or(e.downcast_ref::<&str>().map(|s| s.to_string()));
                panic!("{}: {}", path.display(), why.unwrap_or_default());
            }
            ran += 1;
        }
    }
    assert!(ran >= 2, "the regression inputs were found ({ran})");
}
