//! Binding lists read from the WGSL itself: the `@group/@binding` globals each entry point
//! uses, parsed and validated with naga (the front end wgpu compiles the same source with).
//! A shader's WGSL is the one place its binding list is written: pipelines build their
//! bind group layouts from what this returns, and bind each buffer to the variable of its
//! name (`Gpu::bind_group`). `wgsl_contract` checks the Rust record behind every name.

use std::collections::BTreeMap;

use naga::valid::{Capabilities, ModuleInfo, ValidationFlags, Validator};

use crate::gpu::{Access, Binding};

/// A parsed, validated shader with the layouts of its types.
pub(crate) struct Reflected {
    what: String,
    module: naga::Module,
    info: ModuleInfo,
    layouter: naga::proc::Layouter,
}

impl Reflected {
    /// Parses and validates `wgsl`; `what` names it in errors.
    pub(crate) fn parse(what: &str, wgsl: &str) -> Result<Reflected, String> {
        let shader_error = |e: String| format!("{what}: {e}");
        let module = naga::front::wgsl::parse_str(wgsl).map_err(|e| shader_error(e.emit_to_string(wgsl)))?;
        let info = Validator::new(ValidationFlags::all(), Capabilities::default())
            .validate(&module)
            .map_err(|e| shader_error(format!("invalid WGSL: {e:?}")))?;
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).map_err(|e| shader_error(e.to_string()))?;
        Ok(Reflected { what: what.to_string(), module, info, layouter })
    }

    /// The buffer bindings of `group` that the entry points `entries` use (directly or
    /// through the functions they call), by slot.
    pub(crate) fn bindings(&self, entries: &[&str], group: u32) -> Result<Vec<Binding>, String> {
        let mut out = BTreeMap::new();
        for entry in entries {
            for (g, b) in self.used(entry)? {
                if g == group {
                    out.insert(b.slot, b);
                }
            }
        }
        Ok(out.into_values().collect())
    }

    /// The buffer bindings entry point `entry` uses, one list per bind group from group 0 to
    /// the last it uses (a group it skips is an empty list), each by slot.
    pub(crate) fn groups(&self, entry: &str) -> Result<Vec<Vec<Binding>>, String> {
        let mut groups: Vec<BTreeMap<u32, Binding>> = Vec::new();
        for (g, b) in self.used(entry)? {
            if groups.len() <= g as usize {
                groups.resize_with(g as usize + 1, BTreeMap::new);
            }
            groups[g as usize].insert(b.slot, b);
        }
        Ok(groups.into_iter().map(|g| g.into_values().collect()).collect())
    }

    /// Every buffer binding entry point `entry` uses, with its group.
    pub(crate) fn used(&self, entry: &str) -> Result<Vec<(u32, Binding)>, String> {
        let index = self
            .module
            .entry_points
            .iter()
            .position(|ep| ep.name == entry)
            .ok_or_else(|| format!("{}: no entry point {entry}", self.what))?;
        let uses = self.info.get_entry_point(index);
        let mut out = Vec::new();
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
                other => {
                    return Err(format!("{}: {name} is in {other:?}; Tessera's shaders bind only buffers", self.what))
                }
            };
            let (bytes, ty) = match self.module.types[var.ty].inner {
                naga::TypeInner::Array { base, size: naga::ArraySize::Dynamic, stride } => {
                    (stride as u64, self.type_name(base))
                }
                _ => (self.layouter[var.ty].size as u64, self.type_name(var.ty)),
            };
            out.push((binding.group, Binding { slot: binding.binding, name, access, bytes, ty }));
        }
        Ok(out)
    }

    fn type_name(&self, ty: naga::Handle<naga::Type>) -> String {
        let t = &self.module.types[ty];
        t.name.clone().unwrap_or_else(|| format!("{:?}", t.inner))
    }

    /// The value of the `u32` constant `name`, if the shader declares one as a literal.
    #[cfg(test)]
    pub(crate) fn constant(&self, name: &str) -> Option<u32> {
        let (_, c) = self.module.constants.iter().find(|(_, c)| c.name.as_deref() == Some(name))?;
        match self.module.global_expressions[c.init] {
            naga::Expression::Literal(naga::Literal::U32(v)) => Some(v),
            _ => None,
        }
    }

    /// The workgroup size of entry point `entry`.
    #[cfg(test)]
    pub(crate) fn workgroup_size(&self, entry: &str) -> Option<[u32; 3]> {
        self.module.entry_points.iter().find(|ep| ep.name == entry).map(|ep| ep.workgroup_size)
    }

    /// What the shader is, for messages.
    #[cfg(test)]
    pub(crate) fn what(&self) -> &str {
        &self.what
    }
}
