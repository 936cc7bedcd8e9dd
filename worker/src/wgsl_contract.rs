//! The Rust-WGSL contract, checked without a GPU. The binding lists are the WGSL's own
//! (`crate::reflect` reads them), so what is left to check is the Rust side of each binding:
//! every buffer the worker binds is named after its WGSL variable, and the Rust record behind
//! that name ([`RECORDS`], one row per name, however many stages bind it) has the byte size
//! naga's layouter gives the WGSL type (the `bytemuck` twins: `Params`, `GpuVState`,
//! `PmPoint`, `DecodeParams`, `FrameUniform`, the `stats` counters...). The constants and
//! workgroup sizes both sides rely on are checked too.
//!
//! A record of the wrong size, or a WGSL binding no record names, fails here with the
//! shader's name, before any device would reject or, worse, accept it.

use std::mem::size_of;

use crate::gpu::Binding;
use crate::pm_adapt::buffers::{
    Errors, GpuVState, LevelUniform, Params, Queue, Stats, STAT_CANCELLED, STAT_COLLAPSES, STAT_REMOVED_FACES,
};
use crate::pm_adapt::decoder::{batch_wgsl, DecodeParams, Job, RawDecoded, DECODE_WG};
use crate::pm_adapt::pipelines::{SCAN_BLOCK, STAGES, WG};
use crate::reflect::Reflected;
use crate::render::{self, FrameUniform, PmPoint};

/// The Rust record behind each binding name of the worker's shaders: bytes of the whole
/// record, or of one element of a runtime-sized array.
const RECORDS: &[(&str, u64)] = &[
    ("P", size_of::<Params>() as u64),
    ("L", size_of::<LevelUniform>() as u64),
    ("vstate", size_of::<GpuVState>() as u64),
    ("dstate", size_of::<GpuVState>() as u64),
    ("vpoint", size_of::<PmPoint>() as u64),
    ("dpoint", size_of::<PmPoint>() as u64),
    ("pm_points", size_of::<PmPoint>() as u64),
    ("D", size_of::<DecodeParams>() as u64),
    ("jobs", size_of::<Job>() as u64),
    ("decoded", size_of::<RawDecoded>() as u64),
    ("errors", size_of::<Errors>() as u64),
    ("stats", size_of::<Stats>() as u64),
    ("queue", size_of::<Queue>() as u64),
    ("dstack", size_of::<[u32; 4]>() as u64),
    ("scratch", size_of::<[u32; 4]>() as u64),
    ("frame", size_of::<FrameUniform>() as u64),
    // Arrays of u32.
    ("vfvid", 4),
    ("dfvid", 4),
    ("vcnt", 4),
    ("fcnt", 4),
    ("vsum", 4),
    ("fsum", 4),
    ("occ", 4),
    ("list", 4),
    ("diff", 4),
    ("reach", 4),
    ("up", 4),
    ("root", 4),
    ("ops", 4),
    ("tables", 4),
    ("dec_faces", 4),
    ("face_idx", 4),
    ("face_fvid", 4),
    ("face_owner", 4),
    ("hole", 4),
    ("sc_faces", 4),
    ("data", 4),
    ("sums", 4),
];

/// Every binding of `bindings` (of `what`) whose name no record has, or whose record's size
/// is not the WGSL type's.
fn mismatches(what: &str, bindings: &[Binding], records: &[(&str, u64)]) -> Vec<String> {
    let mut problems = Vec::new();
    for b in bindings {
        match records.iter().find(|(name, _)| *name == b.name) {
            None => problems.push(format!(
                "{what}: WGSL binds {} ({}) at slot {}, which no Rust record names",
                b.name, b.ty, b.slot
            )),
            Some((_, bytes)) if *bytes != b.bytes => {
                problems.push(format!("{what}: {} ({}) is {} bytes in WGSL, {bytes} in Rust", b.name, b.ty, b.bytes))
            }
            Some(_) => {}
        }
    }
    problems
}

fn assert_none(problems: Vec<String>) {
    assert!(problems.is_empty(), "the Rust records and the WGSL disagree:\n{}", problems.join("\n"));
}

fn parse(what: &str, wgsl: &str) -> Reflected {
    Reflected::parse(what, wgsl).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn pm_stage_bindings_match_the_rust_records() {
    let mut problems = Vec::new();
    for (i, stage) in STAGES.iter().enumerate() {
        if STAGES[..i].iter().any(|s| s.label == stage.label) {
            problems.push(format!("two stages are labelled {}", stage.label));
        }
        let bindings = stage.bindings().unwrap_or_else(|e| panic!("{e}")).concat();
        problems.extend(mismatches(&format!("{} ({})", stage.label, stage.entry), &bindings, RECORDS));
        // Every stage is dispatched in workgroups of WG threads (the scan's blocks too).
        let size = parse(stage.label, &stage.shader.wgsl()).workgroup_size(stage.entry);
        if size != Some([WG, 1, 1]) {
            problems.push(format!(
                "{} ({}): workgroup size {size:?}, Rust dispatches [{WG}, 1, 1]",
                stage.label, stage.entry
            ));
        }
    }
    assert_none(problems);
}

#[test]
fn pm_decoder_bindings_match_the_rust_records() {
    let shader = parse("pm: decode batch", &batch_wgsl());
    let bindings = shader.groups("main").unwrap().concat();
    let mut problems = mismatches("pm: decode batch", &bindings, RECORDS);
    let size = shader.workgroup_size("main");
    if size != Some([DECODE_WG, 1, 1]) {
        problems.push(format!("pm: decode batch: workgroup size {size:?}, Rust dispatches [{DECODE_WG}, 1, 1]"));
    }
    assert_none(problems);
}

#[test]
fn pm_constants_match_the_rust() {
    let rust = [
        ("WG", WG),
        ("NONE", codec::pm::NONE),
        ("STAT_COLLAPSES", STAT_COLLAPSES as u32),
        ("STAT_CANCELLED", STAT_CANCELLED as u32),
        ("STAT_REMOVED_FACES", STAT_REMOVED_FACES as u32),
        ("BLOCK", SCAN_BLOCK),
        ("PENDING", crate::pm_adapt::buffers::PENDING),
        ("STACK_WORDS", crate::pm_adapt::limits::STACK_WORDS as u32),
        ("RESUME_VECS", crate::pm_adapt::limits::RESUME_VECS as u32),
        ("LEVELS_PER_PASS", codec::pm::LEVELS_PER_PASS),
    ];
    let shaders: Vec<Reflected> = STAGES.iter().map(|s| parse(s.label, &s.shader.wgsl())).collect();
    let mut problems = Vec::new();
    for (name, value) in rust {
        let mut found = false;
        for shader in &shaders {
            if let Some(v) = shader.constant(name) {
                found = true;
                if v != value {
                    problems.push(format!("{}: {name} is {v} in WGSL, {value} in Rust", shader.what()));
                }
            }
        }
        if !found {
            problems.push(format!("no PM shader declares {name} as a u32 literal"));
        }
    }
    assert_none(problems);
}

#[test]
fn render_bindings_match_the_rust_records() {
    let shader = parse("render", render::SHADER);
    let mut problems = Vec::new();
    // The clear pipeline has no bind group; the mesh pipeline's stages read the frame; the
    // pulled pipeline's vertex stage reads the adapted mesh too (its fragment stage is fs_main).
    for (entry, groups) in [
        ("clear_vs", &[][..]),
        ("clear_fs", &[][..]),
        ("vs_main", &[render::FRAME_GROUP][..]),
        ("vs_pulled", &[render::FRAME_GROUP, render::PULLED_GROUP][..]),
        ("fs_main", &[render::FRAME_GROUP][..]),
    ] {
        let used = shader.used(entry).unwrap();
        let mut groups_used: Vec<u32> = used.iter().map(|(g, _)| *g).collect();
        groups_used.sort_unstable();
        groups_used.dedup();
        if groups_used != groups {
            problems.push(format!("render ({entry}): binds groups {groups_used:?}, the pipeline lays out {groups:?}"));
        }
        let bindings: Vec<Binding> = used.into_iter().map(|(_, b)| b).collect();
        problems.extend(mismatches(&format!("render ({entry})"), &bindings, RECORDS));
    }
    assert_none(problems);
}

/// The check can fail: a record of the wrong size, or a binding no record names, is
/// reported.
#[test]
fn a_wrong_record_is_reported() {
    let stage = &crate::pm_adapt::pipelines::COMPACT_SPLITS;
    let bindings = &stage.bindings().unwrap().concat();
    assert_none(mismatches(stage.label, bindings, RECORDS));
    let resized: Vec<(&str, u64)> =
        RECORDS.iter().map(|&(name, bytes)| (name, if name == "P" { bytes + 4 } else { bytes })).collect();
    assert!(!mismatches(stage.label, bindings, &resized).is_empty(), "a wrong size passed");
    let without: Vec<(&str, u64)> = RECORDS.iter().copied().filter(|(name, _)| *name != "list").collect();
    assert!(!mismatches(stage.label, bindings, &without).is_empty(), "a missing record passed");
}
