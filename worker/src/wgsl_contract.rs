//! The Rust-WGSL contract, checked without a GPU: every shader the worker compiles is parsed
//! and validated with naga (the front end wgpu itself uses), and for each entry point the
//! `@group/@binding` globals it uses must be exactly the rows of the Rust binding tables its
//! pipeline is built from: same group and slot, same name, same access (uniform, read, read
//! and write), and the same byte size of the Rust record behind the binding as naga's layouter
//! gives the WGSL type (the `bytemuck` twins: `Params`, `Split`, `Point`, `Level`, `Frame`,
//! `PmPoint`, the `stats` counters). The constants and workgroup size both sides rely on are
//! checked too.
//!
//! A wrong table row (a slot, a name, `read` for `read_write`, a struct field too many) fails
//! here, with the stage's label, before any device would reject or, worse, accept it.

use std::collections::BTreeMap;

use naga::valid::{Capabilities, ModuleInfo, ValidationFlags, Validator};

use crate::gpu::{Access, Binding};
use crate::pm_adapt::buffers::{STAT_CANCELLED, STAT_COLLAPSES, STAT_REMOVED_FACES};
use crate::pm_adapt::pipelines::{SCAN_BLOCK, STAGES, WG};
use crate::render;

/// A parsed, validated shader with the layouts of its types.
struct Shader {
    what: String,
    module: naga::Module,
    info: ModuleInfo,
    layouter: naga::proc::Layouter,
}

fn parse(what: &str, wgsl: &str) -> Shader {
    let module = naga::front::wgsl::parse_str(wgsl).unwrap_or_else(|e| panic!("{what}: {}", e.emit_to_string(wgsl)));
    let info = Validator::new(ValidationFlags::all(), Capabilities::default())
        .validate(&module)
        .unwrap_or_else(|e| panic!("{what}: invalid WGSL: {e:?}"));
    let mut layouter = naga::proc::Layouter::default();
    layouter.update(module.to_ctx()).unwrap_or_else(|e| panic!("{what}: {e}"));
    Shader { what: what.to_string(), module, info, layouter }
}

/// A binding as the WGSL declares it.
#[derive(Debug, PartialEq)]
struct Declared {
    name: String,
    access: Access,
    /// The size of the variable's type, or of one element of a runtime-sized array.
    bytes: u64,
    /// The type (or element type) name, for messages.
    ty: String,
}

impl Shader {
    /// The bound globals entry point `entry` uses (directly or through the functions it calls),
    /// by `(group, slot)`.
    fn used_bindings(&self, entry: &str) -> BTreeMap<(u32, u32), Declared> {
        let index = self
            .module
            .entry_points
            .iter()
            .position(|ep| ep.name == entry)
            .unwrap_or_else(|| panic!("{}: no entry point {entry}", self.what));
        let uses = self.info.get_entry_point(index);
        let mut out = BTreeMap::new();
        for (handle, var) in self.module.global_variables.iter() {
            let Some(binding) = &var.binding else { continue };
            if uses[handle].is_empty() {
                continue;
            }
            let name = var.name.clone().unwrap_or_default();
            let access = match var.space {
                naga::AddressSpace::Uniform => Access::Uniform,
                naga::AddressSpace::Storage { access } if access.contains(naga::StorageAccess::STORE) => {
                    Access::ReadWrite
                }
                naga::AddressSpace::Storage { .. } => Access::Read,
                other => panic!("{}: {name} is in {other:?}, which no binding table describes", self.what),
            };
            let (bytes, ty) = match self.module.types[var.ty].inner {
                naga::TypeInner::Array { base, size: naga::ArraySize::Dynamic, stride } => {
                    (stride as u64, self.type_name(base))
                }
                _ => (self.layouter[var.ty].size as u64, self.type_name(var.ty)),
            };
            out.insert((binding.group, binding.binding), Declared { name, access, bytes, ty });
        }
        out
    }

    fn type_name(&self, ty: naga::Handle<naga::Type>) -> String {
        let t = &self.module.types[ty];
        t.name.clone().unwrap_or_else(|| format!("{:?}", t.inner))
    }

    /// The value of the `u32` constant `name`, if the shader declares one.
    fn constant(&self, name: &str) -> Option<u32> {
        let (_, c) = self.module.constants.iter().find(|(_, c)| c.name.as_deref() == Some(name))?;
        match self.module.global_expressions[c.init] {
            naga::Expression::Literal(naga::Literal::U32(v)) => Some(v),
            ref e => panic!("{}: constant {name} is {e:?}, not a u32 literal", self.what),
        }
    }

    fn workgroup_size(&self, entry: &str) -> [u32; 3] {
        self.module.entry_points.iter().find(|ep| ep.name == entry).expect("checked by used_bindings").workgroup_size
    }
}

/// Every mismatch between what `entry` of `shader` uses and the Rust `groups` (group index,
/// table) of its pipeline.
fn mismatches(shader: &Shader, entry: &str, groups: &[(u32, &[Binding])]) -> Vec<String> {
    let what = format!("{} ({entry})", shader.what);
    let mut problems = Vec::new();
    let mut expected = BTreeMap::new();
    for &(group, table) in groups {
        for b in table {
            if expected.insert((group, b.slot), b).is_some() {
                problems.push(format!("{what}: the Rust table has slot {group}/{} twice", b.slot));
            }
            if table.iter().filter(|o| o.name == b.name).count() > 1 {
                problems.push(format!("{what}: the Rust table names {} twice", b.name));
            }
        }
    }
    let declared = shader.used_bindings(entry);
    for (&(group, slot), d) in &declared {
        let Some(b) = expected.get(&(group, slot)) else {
            problems.push(format!("{what}: WGSL binds {} at {group}/{slot}, the Rust table nothing", d.name));
            continue;
        };
        if b.name != d.name {
            problems.push(format!("{what}: {group}/{slot} is {} in WGSL, {} in Rust", d.name, b.name));
        }
        if b.access != d.access {
            problems.push(format!("{what}: {} is {:?} in WGSL, {:?} in Rust", d.name, d.access, b.access));
        }
        if b.bytes != d.bytes {
            problems.push(format!("{what}: {} ({}) is {} bytes in WGSL, {} in Rust", d.name, d.ty, d.bytes, b.bytes));
        }
    }
    for (&(group, slot), b) in &expected {
        if !declared.contains_key(&(group, slot)) {
            problems
                .push(format!("{what}: the Rust table binds {} at {group}/{slot}, which WGSL does not use", b.name));
        }
    }
    problems
}

fn assert_none(problems: Vec<String>) {
    assert!(problems.is_empty(), "the Rust tables and the WGSL disagree:\n{}", problems.join("\n"));
}

#[test]
fn pm_stage_bindings_match_the_wgsl() {
    let mut problems = Vec::new();
    for stage in STAGES {
        let shader = parse(stage.label, &stage.shader.wgsl());
        problems.extend(mismatches(&shader, stage.entry, &[(0, stage.bindings)]));
        // Every stage is dispatched in workgroups of WG threads (the scan's blocks too).
        let size = shader.workgroup_size(stage.entry);
        if size != [WG, 1, 1] {
            problems.push(format!(
                "{} ({}): workgroup size {size:?}, Rust dispatches [{WG}, 1, 1]",
                stage.label, stage.entry
            ));
        }
    }
    assert_none(problems);
}

#[test]
fn pm_decoder_bindings_match_the_wgsl() {
    use crate::pm_adapt::decoder::{batch_wgsl, BATCH_BINDINGS, DECODE_WG};
    let shader = parse("pm: decode batch", &batch_wgsl());
    let mut problems = mismatches(&shader, "main", &[(0, BATCH_BINDINGS)]);
    let size = shader.workgroup_size("main");
    if size != [DECODE_WG, 1, 1] {
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
        ("STACK_WORDS", crate::pm_adapt::STACK_WORDS as u32),
        ("RESUME_VECS", crate::pm_adapt::RESUME_VECS as u32),
        ("LEVELS_PER_PASS", codec::pm::LEVELS_PER_PASS),
    ];
    let shaders: Vec<Shader> = STAGES.iter().map(|s| parse(s.label, &s.shader.wgsl())).collect();
    let mut problems = Vec::new();
    for (name, value) in rust {
        let mut found = false;
        for shader in &shaders {
            if let Some(v) = shader.constant(name) {
                found = true;
                if v != value {
                    problems.push(format!("{}: {name} is {v} in WGSL, {value} in Rust", shader.what));
                }
            }
        }
        if !found {
            problems.push(format!("no PM shader declares {name}"));
        }
    }
    assert_none(problems);
}

#[test]
fn render_bindings_match_the_wgsl() {
    let shader = parse("render", render::SHADER);
    let frame = (render::FRAME_GROUP, render::FRAME_BINDINGS);
    let pulled = (render::PULLED_GROUP, render::PULLED_BINDINGS);
    let mut problems = Vec::new();
    // The clear pipeline has no bind group; the mesh pipeline's stages read the frame; the
    // pulled pipeline's vertex stage reads the adapted mesh too (its fragment stage is fs_main).
    for (entry, groups) in [
        ("clear_vs", &[][..]),
        ("clear_fs", &[][..]),
        ("vs_main", &[frame][..]),
        ("vs_pulled", &[frame, pulled][..]),
        ("fs_main", &[frame][..]),
    ] {
        problems.extend(mismatches(&shader, entry, groups));
    }
    assert_none(problems);
}

/// The checks can fail: a table with a wrong slot, name, access or size, as a slip in
/// `pipelines.rs` would make it, is reported, each way.
#[test]
fn a_wrong_table_row_is_reported() {
    let stage = &crate::pm_adapt::pipelines::COMPACT_SPLITS;
    let shader = parse(stage.label, &stage.shader.wgsl());
    assert_none(mismatches(&shader, stage.entry, &[(0, stage.bindings)]));
    let row = |i: usize| stage.bindings[i];
    let with = |i: usize, b: Binding| {
        let mut t = stage.bindings.to_vec();
        t[i] = b;
        t
    };
    let wrong: [(&str, Vec<Binding>); 5] = [
        ("slot", with(1, Binding { slot: 7, ..row(1) })),
        ("name", with(1, Binding { name: "vcnt", ..row(1) })),
        ("access", with(2, Binding { access: Access::Read, ..row(2) })),
        ("size", with(0, Binding { bytes: row(0).bytes + 4, ..row(0) })),
        ("missing row", stage.bindings[..3].to_vec()),
    ];
    for (what, table) in wrong {
        assert!(!mismatches(&shader, stage.entry, &[(0, &table[..])]).is_empty(), "a wrong {what} passed");
    }
}
