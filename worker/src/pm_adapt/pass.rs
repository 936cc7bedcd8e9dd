//! One adaptation pass (Algorithms 1 to 5, see the module docs of [`super`]): the two
//! submissions, the scans, and the buffer resizes between them.

use codec::pm::{PassStats, Viewpoint};

use codec::pm::Levels;

use super::adapter::{GpuAdapter, Shared, MARKS};
use super::buffers::{
    needs_resize, storage, FaceSet, LevelUniform, Params, ScanLevel, VertexSet, ERRORS_BYTES, Q_DESCEND, Q_MOST,
    Q_NEXT, Q_PAUSED, Q_SC_LEAVES, Q_STEPS, READBACK_BYTES, STATE_BYTES, STATS_BYTES, STAT_CANCELLED, STAT_COLLAPSES,
    STAT_DESCENTS, STAT_REMOVED_FACES, STAT_SPLIT_VERTICES, VERTEX_USAGE,
};
use super::error::AdaptError;
use super::limits::{DEEP_DESCENT, DEEP_PASSES, MAX_SCALE, SCALE_STEP, SOFTWARE_DESCENT_SLOTS};
use super::pipelines::{Stage, SCAN_BLOCK, WG};
use crate::gpu::GpuError;

const APPLY: wgpu::CommandEncoderDescriptor = wgpu::CommandEncoderDescriptor { label: Some("pm: apply") };
const APPLY_PASS: wgpu::ComputePassDescriptor =
    wgpu::ComputePassDescriptor { label: Some("pm: apply"), timestamp_writes: None };
const COUNT: wgpu::CommandEncoderDescriptor = wgpu::CommandEncoderDescriptor { label: Some("pm: count") };
const COUNT_PASS: wgpu::ComputePassDescriptor =
    wgpu::ComputePassDescriptor { label: Some("pm: count"), timestamp_writes: None };

/// What the count of a pass found, within the budget: the totals read back, whether the
/// pass refines all levels, and whether the budget held splits back.
struct Count {
    totals: [u32; 12],
    all: bool,
    held: bool,
}

impl GpuAdapter {
    pub(super) fn pass(&mut self, view: Option<&Viewpoint>) -> Result<PassStats, AdaptError> {
        let gpu = self.gpu.clone();
        gpu.scoped(|| self.pass_unscoped(view))
    }

    fn pass_unscoped(&mut self, view: Option<&Viewpoint>) -> Result<PassStats, AdaptError> {
        let pass_start = std::time::Instant::now();
        self.times = [0.0; 3];
        // Out of core: the nodes that arrived go in before the pass, which then sees one page
        // table throughout.
        self.sync_nodes()?;
        let (n, m) = (self.n, self.m);
        let unchanged = PassStats { vertices: n as usize, faces: m as usize, ..Default::default() };
        if n == 0 {
            return Ok(unchanged);
        }
        self.reserve_temporaries(n);
        self.prepare_scan(n as u64 + 1);
        if let Some(v) = view {
            self.note_view(v);
        }
        // A full refinement goes one level a pass, as the CPU reference's `refine_step`.
        let all = view.is_some() && self.tuning.levels == Levels::All && !(self.tuning.mixed && self.deep);
        let mut params = self.pass_params(view, all);
        let Some(Count { totals, all, held }) = self.count_within_budget(&mut params, view, all, pass_start)? else {
            return Ok(PassStats { held: true, ..unchanged });
        };
        self.times[0] = pass_start.elapsed().as_secs_f64() * 1e3;
        let (n_new, f_add) = (totals[0], totals[1]);
        let counters = &totals[2..10];
        let (collapses, cancelled, removed) =
            (counters[STAT_COLLAPSES], counters[STAT_CANCELLED], counters[STAT_REMOVED_FACES]);
        let splits = (n_new + collapses).checked_sub(n).ok_or(AdaptError::InconsistentTotals {
            vertices: n,
            after: n_new,
            collapses,
        })?;
        self.note_descents(all, splits, collapses);
        // The threads of the split stages: one per splitting vertex.
        let split_vertices = if all { counters[STAT_SPLIT_VERTICES] } else { splits };
        if splits == 0 && collapses == 0 {
            // Converged at a raised error with room to spare: the next passes try a finer one,
            // not below the error that last overflowed for this view.
            let finer = view.is_some() && self.memory.error_scale > self.memory.floor && self.fits_finer();
            if finer {
                self.memory.error_scale = (self.memory.error_scale / SCALE_STEP).max(self.memory.floor);
            }
            return Ok(PassStats { cancelled: cancelled as usize, held: held || finer, ..unchanged });
        }
        let m_new = m - removed + f_add;
        let dst = self.reserve_apply(n_new, f_add, removed)?;
        params.n_new = n_new;
        params.f_add = f_add;
        params.m_new = m_new;
        params.splits = split_vertices;
        // `descend` pauses after half the count's steps: its steps also write what they find.
        params.round_steps = self.descend_steps();
        params.rounds = self.rounds_for(self.steps, self.most, params.round_steps);
        self.gpu.queue().write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        self.apply(&params, all, dst, splits);
        if self.tuning.profile {
            self.gpu.wait_for(self.gpu.queue().submit([]))?;
            self.times[1] = pass_start.elapsed().as_secs_f64() * 1e3 - self.times[0];
        }
        if needs_resize(self.faces.idx.cap, m_new as u64, self.n_alloc) {
            self.resize_faces(m_new as u64 + self.n_alloc as u64, m_new as u64);
        }
        self.cur = dst;
        if all {
            // Room for what this count kept, for the next passes (this one's buffers stay
            // alive until its submission ran).
            self.grow_scratch(self.sc_kept);
        }
        self.n = n_new;
        self.m = m_new;
        Ok(PassStats {
            splits: splits as usize,
            collapses: collapses as usize,
            cancelled: cancelled as usize,
            vertices: n_new as usize,
            faces: m_new as usize,
            held,
        })
    }

    /// Stage 0: the temporaries (vertex and face counts, split list, marks) hold `n + 1`
    /// counts (the last one the scan's total).
    fn reserve_temporaries(&mut self, n: u32) {
        let na = self.n_alloc as u64;
        if needs_resize(self.vcnt.cap, n as u64 + 1, self.n_alloc) {
            let cap = n as u64 + 1 + na;
            self.vcnt = storage(self.gpu.device(), "pm: vertex counts", cap, 4, VERTEX_USAGE);
            self.fcnt = storage(self.gpu.device(), "pm: face counts", cap, 4, VERTEX_USAGE);
            self.list = storage(self.gpu.device(), "pm: split list", cap, 4, VERTEX_USAGE);
            self.marks = MARKS.map(|name| storage(self.gpu.device(), name, cap, 4, VERTEX_USAGE));
            self.reallocations += 1;
        }
    }

    /// A new view may refine finer than the error that overflowed for the last one, and
    /// starts with all levels again.
    fn note_view(&mut self, v: &Viewpoint) {
        if self.memory.last_view != Some(*v) {
            self.memory.last_view = Some(*v);
            self.memory.floor = 1.0;
            (self.deep, self.deep_passes, self.deep_tree) = (false, 0, false);
        }
    }

    /// The pass's parameters before the count: the view (none: a full refinement), and one
    /// level or `all`.
    fn pass_params(&self, view: Option<&Viewpoint>, all: bool) -> Params {
        let (n, m) = (self.n, self.m);
        let mut params = Params {
            n,
            m,
            mode: 1,
            levels: all as u32,
            budget: self.tuning.descent_budget,
            loop_probe: 2,
            round_steps: self.tuning.round_steps,
            ..Default::default()
        };
        if let Some(v) = view {
            params.mode = 0;
            params.planes = v.planes().map(|p| p.to_array());
            params.eye = [v.eye.x, v.eye.y, v.eye.z, 1.0];
            params.pixels_per_unit = v.pixels_per_unit;
            params.error_px = v.error_px * self.memory.error_scale;
            params.c_lod = v.c_lod;
            params.attribute_scale = v.attribute_scale;
            if let Some(o) = &self.occluder {
                (params.occ_vp, params.occ_rect, params.occ_size) = o.params();
            }
        }
        params
    }

    /// Stage 1, submission 1 within the budget: the count ([`Self::classify`]) for
    /// `params`; `None` when a full refinement must stop because its splits do not fit.
    fn count_within_budget(
        &mut self,
        params: &mut Params,
        view: Option<&Viewpoint>,
        mut all: bool,
        pass_start: std::time::Instant,
    ) -> Result<Option<Count>, AdaptError> {
        let (n, m) = (self.n, self.m);
        let mut totals = self.classify(params, pass_start)?;
        let mut held = false;
        let over = |a: &GpuAdapter, t: &[u32; 12]| a.exceeds((t[0] as u64).max(n as u64), m as u64 + t[1] as u64);
        // An all-levels pass whose splits would take the mesh past the budget or the binding
        // limit is tried again as a pass of one level, which may fit: the mesh then fills the
        // room at the view's error, pass by pass, before the error is raised.
        if all && totals[0] > n && over(self, &totals) {
            all = false;
            params.levels = 0;
            totals = self.classify(params, pass_start)?;
        }
        // A pass whose splits would take the mesh past the budget or the binding limit splits
        // nothing: with a view it collapses what the view lets go and raises the error the
        // passes after it adapt to ("Memory budget" in docs/design.md); a full refinement
        // stops there.
        if totals[0] > n && over(self, &totals) {
            held = true;
            match view {
                None => return Ok(None),
                Some(v) => {
                    self.memory.error_scale = (self.memory.error_scale * SCALE_STEP).min(MAX_SCALE);
                    self.memory.floor = self.memory.error_scale;
                    params.mode = 2;
                    params.error_px = v.error_px * self.memory.error_scale;
                    totals = self.classify(params, pass_start)?;
                }
            }
        }
        Ok(Some(Count { totals, all, held }))
    }

    /// The deep-descent bookkeeping of a mixed file's all-levels passes (see
    /// [`DEEP_DESCENT`]).
    fn note_descents(&mut self, all: bool, splits: u32, collapses: u32) {
        if all && self.tuning.mixed && !self.deep_tree && splits > DEEP_DESCENT.saturating_mul(self.descents) {
            self.deep = true;
        }
        if self.deep && !all && splits + collapses > 0 {
            self.deep_passes += 1;
            if self.deep_passes >= DEEP_PASSES {
                (self.deep, self.deep_tree) = (false, true);
            }
        }
    }

    /// Stage 2: checks the pass's buffers against the device's binding limit and makes room
    /// for its result; returns the vertex set that receives it.
    fn reserve_apply(&mut self, n_new: u32, f_add: u32, removed: u32) -> Result<usize, AdaptError> {
        let (m, na) = (self.m, self.n_alloc as u64);
        // Every buffer of the pass is bound whole: past the device's binding limit the pass
        // would fail validation ([`GpuAdapter::exceeds`] holds splits back before that, so
        // this fails only for a base mesh beyond it).
        let limit = self.gpu.device().limits().max_storage_buffer_binding_size;
        for (elements, each, what) in
            [(n_new as u64 + na, STATE_BYTES, "vertices"), (m as u64 + f_add as u64 + na, 12, "faces")]
        {
            if elements * each > limit {
                return Err(AdaptError::TooLarge { elements, what, bytes: elements * each, limit });
            }
        }

        // Memory management (section 5.3): the other vertex set receives the reorganised
        // vertices, so it is reallocated without copying; the face buffers keep their content.
        let dst = 1 - self.cur;
        if needs_resize(self.sets[dst].fvid.cap, n_new as u64, self.n_alloc) {
            let cap = n_new as u64 + na;
            self.sets[dst] = VertexSet::new(self.gpu.device(), if dst == 0 { "A" } else { "B" }, cap);
            self.reallocations += 1;
        }
        let total = m as u64 + f_add as u64;
        if self.faces.idx.cap < total {
            self.resize_faces(total + na, m as u64);
        }
        if needs_resize(self.hole.cap, removed as u64, self.n_alloc) {
            self.hole = storage(self.gpu.device(), "pm: face holes", removed as u64 + na, 4, VERTEX_USAGE);
            self.reallocations += 1;
        }
        Ok(dst)
    }

    /// The operation decoder's buffers, by their WGSL names (`decode.wgsl`): its parameters,
    /// the operations, the tables, the faces it decodes to and its error report. (Of the
    /// fields, not `&self`: the caller goes on changing other fields.)
    fn decoder_buffers<'a>(
        shared: &'a Shared,
        faces: &'a FaceSet,
        errors: &'a wgpu::Buffer,
    ) -> [(&'static str, &'a wgpu::Buffer); 5] {
        [
            ("D", &shared.decode),
            ("ops", &shared.ops),
            ("tables", &shared.tables),
            ("dec_faces", &faces.fvid.buffer),
            ("errors", errors),
        ]
    }

    /// Stage 3, submission 2: reorganisation, splits, index update, face compaction, into
    /// vertex set `dst`.
    fn apply(&mut self, params: &Params, all: bool, dst: usize, splits: u32) {
        let (n, m) = (self.n, self.m);
        let (f_add, m_new, split_vertices) = (params.f_add, params.m_new, params.splits);
        let mut enc = self.gpu.device().create_command_encoder(&APPLY);
        {
            let (src, dstset) = (&self.sets[self.cur], &self.sets[dst]);
            let (p, f) = (&self.shared.pipelines, &self.faces);
            // The vertex and face counts were scanned in place: from here on they are the
            // prefix sums `vsum` and `fsum`.
            // Every buffer of the submission by its WGSL name; each stage binds those its
            // shader declares.
            let mut buffers = vec![
                ("P", &self.params),
                ("vfvid", &src.fvid.buffer),
                ("vstate", &src.state.buffer),
                ("vpoint", &src.point.buffer),
                ("vsum", &self.vcnt.buffer),
                ("fsum", &self.fcnt.buffer),
                ("list", &self.list.buffer),
                ("dfvid", &dstset.fvid.buffer),
                ("dstate", &dstset.state.buffer),
                ("dpoint", &dstset.point.buffer),
                ("occ", &self.occ.buffer),
                ("root", &self.marks[3].buffer),
                ("face_idx", &f.idx.buffer),
                ("face_fvid", &f.fvid.buffer),
                ("face_owner", &f.owner.buffer),
                ("hole", &self.hole.buffer),
                ("stats", &self.stats),
                ("dstack", &self.stack.buffer),
                ("queue", &self.queue),
                ("scratch", &self.scratch.buffer),
                ("sc_faces", &self.sc_faces.buffer),
            ];
            buffers.extend(Self::decoder_buffers(&self.shared, &self.faces, &self.errors));
            let reorganise = p.reorganise.bind(&self.gpu, &buffers);
            let split_decode = (if all { &p.descend } else { &p.split_decode }).bind(&self.gpu, &buffers);
            let compact = p.compact_splits.bind(&self.gpu, &buffers);
            let split = (if all { &p.index_new } else { &p.split }).bind(&self.gpu, &buffers);
            let index = p.index_update.bind(&self.gpu, &buffers);
            let holes = p.holes.bind(&self.gpu, &buffers);
            let fill = p.fill.bind(&self.gpu, &buffers);
            let mut pass = enc.begin_compute_pass(&APPLY_PASS);
            self.dispatch(&mut pass, &p.compact_splits, &compact, n);
            if all {
                drop(pass);
                // What the count kept, placed, where it all fitted; else the descents walked
                // again.
                let kept = self.sc_kept.iter().zip(&self.sc_cap).all(|(k, c)| k <= c);
                if split_vertices > 0 && !kept {
                    self.run_rounds(&mut enc, &p.descend, &split_decode, params.rounds, Some(Q_DESCEND));
                }
                pass = enc.begin_compute_pass(&APPLY_PASS);
                if split_vertices > 0 && kept {
                    let leaves = p.place_leaves.bind(&self.gpu, &buffers);
                    let splits = p.place_splits.bind(&self.gpu, &buffers);
                    self.dispatch(&mut pass, &p.place_leaves, &leaves, self.sc_kept[0]);
                    self.dispatch(&mut pass, &p.place_splits, &splits, self.sc_kept[1]);
                }
                self.dispatch(&mut pass, &p.reorganise, &reorganise, n);
                self.dispatch(&mut pass, &p.index_new, &split, f_add);
            } else {
                self.dispatch(&mut pass, &p.split_decode, &split_decode, splits);
                self.dispatch(&mut pass, &p.reorganise, &reorganise, n);
                self.dispatch(&mut pass, &p.split, &split, splits);
            }
            self.dispatch(&mut pass, &p.index_update, &index, m);
            self.dispatch(&mut pass, &p.holes, &holes, m_new);
            self.dispatch(&mut pass, &p.fill, &fill, m + f_add - m_new);
        }
        self.gpu.queue().submit([enc.finish()]);
    }

    /// Submission 1 (state update, collapses, scans) for `params`, and its totals read back:
    /// vertices after the pass and faces its splits add, the counters, the first decoding
    /// error (which fails the pass). Where a software adapter's count reaches llvmpipe's loop
    /// limit (its operations heavier than [`super::SOFTWARE_ROUND_STEPS`] allows for), the
    /// slots' steps a round are halved for good and the submission runs again: it changes
    /// nothing but the pass's counts.
    fn classify(&mut self, params: &mut Params, pass_start: std::time::Instant) -> Result<[u32; 12], AdaptError> {
        loop {
            match self.classify_once(params, pass_start) {
                Err(AdaptError::LoopLimit { .. })
                    if self.count_ran && self.tuning.round_steps != u32::MAX && self.tuning.round_steps > 1 =>
                {
                    self.tuning.round_steps /= 2;
                    params.round_steps = self.tuning.round_steps;
                    let mut enc = self.gpu.device().create_command_encoder(&COUNT);
                    enc.clear_buffer(&self.errors, 0, None);
                    self.gpu.queue().submit([enc.finish()]);
                }
                other => return other,
            }
        }
    }

    /// [`Self::classify`] once.
    fn classify_once(&mut self, params: &mut Params, pass_start: std::time::Instant) -> Result<[u32; 12], AdaptError> {
        let n = params.n;
        self.count_ran = false;
        self.gpu.queue().write_buffer(&self.params, 0, bytemuck::bytes_of(params));
        let mut enc =
            self.gpu.device().create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("pm: classify") });
        enc.clear_buffer(&self.stats, 0, None);
        let all = params.levels == 1;
        self.descents = 0;

        if all {
            // diff, reach and root start at zero; `up` is written for every vertex.
            for k in [0, 1, 3] {
                enc.clear_buffer(&self.marks[k].buffer, 0, Some((n as u64 + 1) * 4));
            }
        }
        {
            let set = &self.sets[self.cur];
            let p = &self.shared.pipelines;
            // Every buffer of the submission by its WGSL name; each stage binds those its
            // shader declares.
            let [diff, reach, up, root] = &self.marks;
            let mut buffers = vec![
                ("P", &self.params),
                ("vfvid", &set.fvid.buffer),
                ("vstate", &set.state.buffer),
                ("vpoint", &set.point.buffer),
                ("vcnt", &self.vcnt.buffer),
                ("fcnt", &self.fcnt.buffer),
                ("occ", &self.occ.buffer),
                ("stats", &self.stats),
                ("diff", &diff.buffer),
                ("reach", &reach.buffer),
                ("up", &up.buffer),
                ("root", &root.buffer),
                ("list", &self.list.buffer),
            ];
            buffers.extend(Self::decoder_buffers(&self.shared, &self.faces, &self.errors));
            let state = p.state.bind(&self.gpu, &buffers);
            let node_check = self.resident.as_ref().map(|_| p.node_check.bind(&self.gpu, &buffers));
            let collapse = p.collapse.bind(&self.gpu, &buffers);
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("pm: classify"),
                timestamp_writes: None,
            });
            if let Some(bg) = &node_check {
                self.dispatch(&mut pass, &p.node_check, bg, n);
            }
            if all {
                let mark = p.mark.bind(&self.gpu, &buffers);
                let regions = p.regions.bind(&self.gpu, &buffers);
                self.dispatch(&mut pass, &p.mark, &mark, n + 1);
                self.scan(&mut pass, &diff.buffer);
                drop(pass);
                // How many vertices descend, read back to size the count's dispatches and
                // the stacks (with an indirect dispatch instead, lavapipe once took 7.9 s
                // instead of 0.5 s a cluster frame; the parameters were in a uniform buffer
                // then, whose recompiles may account for it: docs/design.md).
                enc.copy_buffer_to_buffer(&self.stats, 0, &self.readback, 8, STATS_BYTES);
                enc.copy_buffer_to_buffer(&self.errors, 0, &self.readback, 8 + STATS_BYTES, ERRORS_BYTES);
                self.gpu.queue().submit([enc.finish()]);
                let totals = self.read_totals()?;
                // An operation the last pass could not decode fails this one, before the count.
                if totals[10] != 0 {
                    return Err(AdaptError::corrupt(totals[10], totals[11], self.resident.is_some()));
                }
                let descents = totals[2 + STAT_DESCENTS];
                self.descents = descents;
                let (slots, max) = (self.stack_slots(), self.stack_max_bytes(self.memory.bytes));
                let cap = if self.tuning.round_steps == u32::MAX { u32::MAX } else { SOFTWARE_DESCENT_SLOTS };
                let want = (descents.min(cap) as u64).min(max / self.stack_slot_bytes());
                if (slots as u64) < want {
                    // Grown to the descents (at least double), within the most it may take.
                    let bytes = (want * self.stack_slot_bytes()).max(self.stack.cap * 8).min(max);
                    self.stack = storage(self.gpu.device(), "pm: descent stacks", bytes / 4, 4, VERTEX_USAGE);
                    self.reallocations += 1;
                }
                self.slots = self.stack_slots().min(cap).min(descents.max(1));
                params.stack_slots = self.slots;
                [params.sc_leaves, params.sc_splits, params.sc_faces] = self.sc_cap;
                buffers.push(("dstack", &self.stack.buffer));
                buffers.push(("queue", &self.queue));
                buffers.push(("scratch", &self.scratch.buffer));
                // The count writes the faces it finds to the scratch faces.
                for b in buffers.iter_mut().filter(|(name, _)| *name == "dec_faces") {
                    b.1 = &self.sc_faces.buffer;
                }
                let count = p.count.bind(&self.gpu, &buffers);
                enc = self.gpu.device().create_command_encoder(&COUNT);
                self.count_ran = true;
                (self.steps, self.most, self.sc_kept) = self.count_descents(&mut enc, params, &count, descents)?;
                let mut pass = enc.begin_compute_pass(&COUNT_PASS);
                self.dispatch(&mut pass, &p.regions, &regions, n);
            } else {
                self.dispatch(&mut pass, &p.state, &state, n + 1);
                self.dispatch(&mut pass, &p.collapse, &collapse, n);
            }
        }
        if self.tuning.profile {
            // Time the state update and collapses apart from the scans.
            self.gpu.wait_for(self.gpu.queue().submit([enc.finish()]))?;
            self.times[2] = pass_start.elapsed().as_secs_f64() * 1e3;
            enc =
                self.gpu.device().create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("pm: scans") });
        }
        {
            let mut pass = enc
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("pm: scans"), timestamp_writes: None });
            self.scan(&mut pass, &self.vcnt.buffer);
            self.scan(&mut pass, &self.fcnt.buffer);
        }
        enc.copy_buffer_to_buffer(&self.vcnt.buffer, n as u64 * 4, &self.readback, 0, 4);
        enc.copy_buffer_to_buffer(&self.fcnt.buffer, n as u64 * 4, &self.readback, 4, 4);
        enc.copy_buffer_to_buffer(&self.stats, 0, &self.readback, 8, STATS_BYTES);
        enc.copy_buffer_to_buffer(&self.errors, 0, &self.readback, 8 + STATS_BYTES, ERRORS_BYTES);
        self.gpu.queue().submit([enc.finish()]);
        let totals = self.read_totals()?;
        // An operation the last pass could not decode fails this one.
        if totals[10] != 0 {
            return Err(AdaptError::corrupt(totals[10], totals[11], self.resident.is_some()));
        }
        Ok(totals)
    }

    /// Records `count` over the pass's `total` descents into `enc` and runs it to the end:
    /// round after round of the pass's slots until the queue is empty and no descent paused
    /// (a software adapter's slots pause; one round on hardware), its queue read back after
    /// each batch of rounds. Returns the steps of the descents in all and the most of one,
    /// which size `descend`'s rounds, and the leaves, splits and faces it asked its scratch
    /// area to keep. `enc` is then a new encoder for what follows.
    fn count_descents(
        &self,
        enc: &mut wgpu::CommandEncoder,
        params: &mut Params,
        bg: &[wgpu::BindGroup],
        total: u32,
    ) -> Result<(u64, u64, [u32; 3]), AdaptError> {
        if total == 0 {
            return Ok((0, 0, [0; 3]));
        }
        // Enough rounds for any descents (the most steps each), the last of which fails the
        // pass if a descent still has to pause (descent.wgsl): the host stops there. A batch
        // of rounds finishes the descents that a round of every slot can hold, and the
        // longest then.
        let most = self.descent_steps();
        let bound = self.rounds_for(total as u64 * most, most, self.tuning.round_steps);
        let batch = if self.tuning.round_steps == u32::MAX {
            1
        } else {
            (most.div_ceil(self.tuning.round_steps as u64) + 1) as u32
        };
        params.rounds = bound;
        self.gpu.queue().write_buffer(&self.params, 0, bytemuck::bytes_of(params));
        let mut run = 0;
        loop {
            let rounds = batch.min(bound - run);
            self.run_rounds(enc, &self.shared.pipelines.count, bg, rounds, (run == 0).then_some(0));
            run += rounds;
            enc.copy_buffer_to_buffer(&self.queue, 0, &self.readback, 0, 32);
            let done = std::mem::replace(enc, self.gpu.device().create_command_encoder(&COUNT));
            self.gpu.queue().submit([done.finish()]);
            let q = self.read_totals()?;
            if (q[Q_NEXT] >= total && q[Q_PAUSED] == 0) || run >= bound {
                let kept = [q[Q_SC_LEAVES], q[Q_SC_LEAVES + 1], q[Q_SC_LEAVES + 2]];
                return Ok((q[Q_STEPS] as u64 | (q[Q_STEPS + 1] as u64) << 32, q[Q_MOST] as u64, kept));
            }
        }
    }

    /// Records `rounds` dispatches of `stage` (`count` or `descend`) over the pass's slots
    /// into `enc`, each round going on with the descents the last one paused (a software
    /// adapter) and taking more from the queue; with `fresh`, the queue at that word and the
    /// slots' resume records are cleared first.
    fn run_rounds(
        &self,
        enc: &mut wgpu::CommandEncoder,
        stage: &Stage,
        bg: &[wgpu::BindGroup],
        rounds: u32,
        fresh: Option<u64>,
    ) {
        if let Some(q) = fresh {
            let (resume, records) = self.resume_range();
            enc.clear_buffer(&self.stack.buffer, resume, Some(records));
            enc.clear_buffer(&self.queue, q * 4, Some(32));
        }
        let mut pass = enc
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("pm: descents"), timestamp_writes: None });
        for _ in 0..rounds {
            self.dispatch(&mut pass, stage, bg, self.slots);
        }
    }

    /// Reallocates the face buffers to `cap` faces, keeping the first `keep`.
    fn resize_faces(&mut self, cap: u64, keep: u64) {
        let d = self.gpu.device();
        let new = FaceSet::new(d, cap);
        if keep > 0 {
            let mut enc = d.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("pm: face resize") });
            enc.copy_buffer_to_buffer(&self.faces.idx.buffer, 0, &new.idx.buffer, 0, keep * 12);
            enc.copy_buffer_to_buffer(&self.faces.fvid.buffer, 0, &new.fvid.buffer, 0, keep * 12);
            enc.copy_buffer_to_buffer(&self.faces.owner.buffer, 0, &new.owner.buffer, 0, keep * 4);
            self.gpu.queue().submit([enc.finish()]);
        }
        self.faces = new;
        self.reallocations += 1;
    }

    /// Sizes the block-sum buffers of the scan levels for `count` elements and writes each
    /// level's count.
    fn prepare_scan(&mut self, count: u64) {
        let mut counts = vec![count];
        while *counts.last().expect("non-empty") > SCAN_BLOCK as u64 {
            counts.push(counts.last().expect("non-empty").div_ceil(SCAN_BLOCK as u64));
        }
        while self.scan_levels.len() < counts.len() {
            let k = self.scan_levels.len();
            let uniform = self.gpu.device().create_buffer(&wgpu::BufferDescriptor {
                label: Some(&format!("pm: scan level {k}")),
                size: 16,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            self.scan_levels.push(ScanLevel {
                sums: storage(self.gpu.device(), "pm: scan sums", 0, 4, VERTEX_USAGE),
                uniform,
                blocks: 0,
            });
        }
        self.scan_levels.truncate(counts.len());
        for (level, &c) in self.scan_levels.iter_mut().zip(&counts) {
            let blocks = c.div_ceil(SCAN_BLOCK as u64);
            if level.sums.cap < blocks {
                level.sums = storage(self.gpu.device(), "pm: scan sums", blocks * 2, 4, VERTEX_USAGE);
            }
            level.blocks = blocks as u32;
            let uniform = LevelUniform { count: c as u32, pad: [0; 3] };
            self.gpu.queue().write_buffer(&level.uniform, 0, bytemuck::bytes_of(&uniform));
        }
    }

    /// Exclusive scan of `data` in place over the levels set by [`Self::prepare_scan`].
    fn scan(&self, pass: &mut wgpu::ComputePass<'_>, data: &wgpu::Buffer) {
        let p = &self.shared.pipelines;
        let mut adds = Vec::with_capacity(self.scan_levels.len());
        // Down: scan each level's blocks, the block sums becoming the next level's data.
        for (k, level) in self.scan_levels.iter().enumerate() {
            let input = if k == 0 { data } else { &self.scan_levels[k - 1].sums.buffer };
            let buffers = [("L", &level.uniform), ("data", input), ("sums", &level.sums.buffer)];
            self.dispatch_groups(pass, &p.scan_blocks, &p.scan_blocks.bind(&self.gpu, &buffers), level.blocks);
            adds.push(buffers);
        }
        // Up: add the scanned block sums back (the top level is a single block).
        for (level, buffers) in self.scan_levels.iter().zip(&adds).rev().skip(1) {
            self.dispatch_groups(pass, &p.add_blocks, &p.add_blocks.bind(&self.gpu, buffers), level.blocks);
        }
    }

    /// Dispatches one thread per element, `threads` in all (nothing for zero).
    fn dispatch(&self, pass: &mut wgpu::ComputePass<'_>, stage: &Stage, bg: &[wgpu::BindGroup], threads: u32) {
        self.dispatch_groups(pass, stage, bg, threads.div_ceil(WG));
    }

    /// Dispatches `groups` workgroups, in two dimensions beyond the per-dimension limit.
    fn dispatch_groups(&self, pass: &mut wgpu::ComputePass<'_>, stage: &Stage, bg: &[wgpu::BindGroup], groups: u32) {
        if groups == 0 {
            return;
        }
        let x = groups.min(self.shared.max_groups);
        let y = groups.div_ceil(x);
        stage.compute.set(pass, bg);
        pass.dispatch_workgroups(x, y, 1);
    }

    pub(super) fn read_totals(&self) -> Result<[u32; 12], GpuError> {
        self.gpu.map_read(&self.readback, READBACK_BYTES, |mapped| {
            let mut out = [0u32; 12];
            out.copy_from_slice(bytemuck::cast_slice(mapped));
            out
        })
    }
}
