//! The tess path on the GPU: its control points, indices and pipelines,
//! and for the error LOD, one frame slot's buffers the control shader
//! reads the frame plan from, written each frame in time that grows with
//! what the plan draws, not with the terrain.
//!
//! The error table starts as the terrain's bound and the choice buffer as
//! all zero. A frame writes its planned patches' rows, its merged nodes'
//! rows (in their first patch), its full-resolution bits and its merged
//! nodes' level bytes, and remembers them; the next frame in the same slot
//! puts those back first. So a patch the plan leaves out reads its bound,
//! whatever frames came before.

use std::time::Instant;

use ash::vk;

use super::geomip_path::{GeomipConstants, GeomipDraw, GeomipGeometry};
use super::pipelines::{build_pipelines, PathPipelines, PipelineTarget};
use super::settings::{ErrorMeasure, RenderPath, RenderSettings};
use super::view::FrameView;
use super::view_measure::seen_errors;
use crate::gpu::descriptors::DescriptorSet;
use crate::gpu::memory::Buffer;
use crate::gpu::owned::PipelineLayout;
use crate::gpu::Device;
use crate::lod::hierarchy::{rect_rows, Hierarchy};
use crate::lod::order::{DrawOrder, PatchMarks};
use crate::lod::patch_merge::MergedNode;
use crate::lod::plan::{FramePlan, PlanInputs, PlannedBlock, Planner, SightReading};
use crate::lod::seen::SeenPixels;
use crate::lod::view::Tau;
use crate::lod::view_measure::Diagonal;
use crate::render::error::{RenderError, Result};
use crate::shader_constants::{
    BINDING_ERROR_TABLE, BINDING_FRAME_STORAGE, BINDING_FULL_RESOLUTION, BINDING_VISIBILITY,
};
use crate::terrain::{ErrorTable, PatchGrid, Terrain};

pub(super) struct TessGeometry {
    pub(super) control_points: Buffer,
    pub(super) indices: Buffer,
    /// Fractional even spacing, for the distance LOD.
    pub(super) pipelines: PathPipelines,
    /// Equal spacing, for the error LOD's whole factors.
    pub(super) error_pipelines: PathPipelines,
    /// Per-patch errors, for choosing the full-resolution patches.
    pub(super) errors: ErrorTable,
}

impl TessGeometry {
    /// The path's control points, indices and pipelines for `terrain` on
    /// `layout`; `errors` is its error table (either diagonal).
    pub(super) fn new(
        target: &PipelineTarget,
        layout: &PipelineLayout,
        terrain: &Terrain,
        errors: ErrorTable,
        wireframe: bool,
    ) -> Result<TessGeometry> {
        let device = target.device;
        Ok(TessGeometry {
            control_points: device.upload_buffer(
                "terrain.control_points",
                vk::BufferUsageFlags::VERTEX_BUFFER,
                bytemuck::cast_slice(terrain.control_points()),
            )?,
            indices: device.upload_buffer(
                "terrain.patch_indices",
                vk::BufferUsageFlags::INDEX_BUFFER,
                bytemuck::cast_slice(terrain.indices()),
            )?,
            pipelines: build_pipelines(target, layout, (RenderPath::Tess, false), wireframe)?,
            error_pipelines: build_pipelines(target, layout, (RenderPath::Tess, true), wireframe)?,
            errors,
        })
    }

    /// Plans one frame of the error LOD at `pixels` (with the view's
    /// measured table under `ErrorMeasure::View`), writes it into
    /// `choice`, and sets the frame's exact draws; returns the frame's
    /// draws and what it expects.
    pub(super) fn plan_error_frame(
        &mut self,
        terrain: &Terrain,
        (hierarchy, seen_pixels): (&Hierarchy, Option<&SeenPixels>),
        geomip: &GeomipGeometry,
        (view, settings, pixels): (&FrameView, &RenderSettings, f32),
        (choice, exact, planner): (&mut ChoiceBuffers, &mut Vec<GeomipDraw>, &mut Planner),
        max_patches_per_draw: Option<u32>,
    ) -> Result<PlannedFrame> {
        let sight = match settings.error_measure {
            // Computed once per terrain, before the choice is timed.
            ErrorMeasure::Sight => terrain.sight_table(),
            _ => None,
        };
        let start = Instant::now();
        let seen = match settings.error_measure {
            ErrorMeasure::View => {
                let drawn = view.patches_drawn(terrain, settings.cull);
                seen_errors(
                    terrain,
                    &self.errors,
                    Diagonal::Either,
                    view,
                    (settings, pixels),
                    &drawn,
                )
            }
            _ => None,
        };
        let lod_view = view.lod_view(Tau::new(pixels).unwrap_or_default());
        let table = seen.as_ref().map_or(&self.errors, |s| &s.table);
        let frame_plan = planner.plan(
            terrain,
            hierarchy,
            &lod_view,
            &PlanInputs {
                table,
                sight,
                merge: settings.merge_patches,
                cull: settings.cull,
                reading: SightReading::Tessellated,
                seen: seen_pixels,
            },
        );
        let lod_ms = start.elapsed().as_secs_f64() * 1e3;
        let merged_indices = choice.write(frame_plan, (&self.errors, table), terrain)?;
        let order = DrawOrder::new(terrain.info(), terrain.grid(), view.eye_local);
        exact_draws(terrain, frame_plan, (geomip, &order), exact);
        Ok(PlannedFrame {
            lod_ms,
            tess_batches: block_batches(frame_plan, &order, max_patches_per_draw),
            merged_batches: patch_batches(0..merged_indices / 4, max_patches_per_draw),
            predicted_max_px: seen
                .as_ref()
                .map_or(frame_plan.predicted_max_px, |s| s.predicted_max_px),
            predicted_p99_px: seen.map(|s| s.predicted_p99_px),
            predicted_over_share: frame_plan.predicted_over_share,
            merged_nodes: frame_plan.merged.len(),
            patches_in_view: frame_plan.patches_in_view,
        })
    }
}
/// The full-resolution patches of `plan` as exact draws (geomip level
/// 0, no stitching: every edge they share is tessellated with a vertex on
/// every sample), in `order`'s runs.
fn exact_draws(
    terrain: &Terrain,
    plan: &FramePlan,
    (geomip, order): (&GeomipGeometry, &DrawOrder),
    exact: &mut Vec<GeomipDraw>,
) {
    let grid = terrain.grid();
    exact.clear();
    let marks = marked_blocks(plan, grid, true);
    for p in order
        .marked_runs(&marks)
        .into_iter()
        .flat_map(|(first, n)| first..first + n)
    {
        let p = p as usize;
        let rect = grid.sample_rect(grid.patch_id(p));
        let (first, count) = geomip.full_resolution_range([rect.cells_x(), rect.cells_z()]);
        exact.push(GeomipDraw {
            patch: p as u32,
            first,
            count,
            constants: GeomipConstants {
                origin: [rect.col0 as i32, rect.row0 as i32],
                level: 0,
                interior: 0.0,
                sides: [0.0; 4],
            },
        });
    }
}

/// One frame of the error LOD as the renderer draws and reports it.
pub(super) struct PlannedFrame {
    /// Milliseconds of the level choice, the view measure included.
    pub(super) lod_ms: f64,
    /// The tessellated patches' and the merged nodes' draws.
    pub(super) tess_batches: Vec<(u32, u32)>,
    pub(super) merged_batches: Vec<(u32, u32)>,
    pub(super) predicted_max_px: f32,
    pub(super) predicted_p99_px: Option<f32>,
    /// The view model's share of pixels over tau (`FramePlan`).
    pub(super) predicted_over_share: Option<f32>,
    pub(super) merged_nodes: usize,
    pub(super) patches_in_view: usize,
}

/// One frame slot's choice buffers and what its last frame wrote.
pub(super) struct ChoiceBuffers {
    /// Errors of each patch at 1, 2, ..., 64 segments, as the control
    /// shader reads them.
    errors: Buffer,
    /// One full-resolution bit a patch, 32 to a word, then one merged
    /// level byte a patch, four to a word.
    choice: Buffer,
    /// Four control point indices per merged node drawn.
    pub(super) merged_indices: Buffer,
    /// Patches whose error row the last frame wrote.
    written_rows: Vec<u32>,
    /// The full-resolution bits, built here and written to the mapped
    /// memory a word at a time: that memory may be write-combined
    /// (device-local, host-visible), where a read-modify-write of single
    /// words reads across the bus each time.
    full_bits: Vec<u32>,
    /// The words of `full_bits` the last frame set, which the next one
    /// clears: a frame writes the words it and the frame before set, not
    /// the grid's.
    full_words: Vec<u32>,
    /// The merged nodes whose level bytes the last frame set.
    merged: Vec<MergedNode>,
    /// The chosen blocks whose level bytes the last frame set.
    chosen: Vec<PlannedBlock>,
}

impl ChoiceBuffers {
    /// Slot `slot`'s buffers for `terrain`, starting as `bound`, and its
    /// descriptor set pointed at them and at the occlusion state
    /// `visibility`.
    pub(super) fn new(
        device: &Device,
        slot: usize,
        terrain: &Terrain,
        bound: &ErrorTable,
        (set, frame): (DescriptorSet, &Buffer),
        visibility: &Buffer,
    ) -> Result<Self> {
        let patches = terrain.grid().patch_count();
        // Full-resolution bits, merged levels, chosen levels.
        let words = patches.div_ceil(32) + 2 * patches.div_ceil(4);
        let choice = device.create_host_buffer(
            &format!("terrain.patch_choice[{slot}]"),
            vk::BufferUsageFlags::STORAGE_BUFFER,
            bytemuck::cast_slice(&vec![0u32; words]),
        )?;
        // A node holds at least 2x2 patches: at most a quarter as many
        // nodes as patches, four indices each.
        let merged_indices = device.create_host_buffer(
            &format!("terrain.merged_indices[{slot}]"),
            vk::BufferUsageFlags::INDEX_BUFFER,
            bytemuck::cast_slice(&vec![0u32; patches.max(4)]),
        )?;
        let errors = device.create_host_buffer(
            &format!("terrain.view_errors[{slot}]"),
            vk::BufferUsageFlags::STORAGE_BUFFER,
            bytemuck::cast_slice(bound.as_slice()),
        )?;
        for (binding, buffer) in [
            (BINDING_ERROR_TABLE, &errors),
            (BINDING_FULL_RESOLUTION, &choice),
            (BINDING_VISIBILITY, visibility),
            (BINDING_FRAME_STORAGE, frame),
        ] {
            let size = buffer.desc.size;
            device.write_buffer(
                set,
                binding,
                vk::DescriptorType::STORAGE_BUFFER,
                buffer,
                size,
            );
        }
        Ok(ChoiceBuffers {
            errors,
            choice,
            merged_indices,
            written_rows: Vec::new(),
            full_bits: vec![0; patches.div_ceil(32)],
            full_words: Vec::new(),
            merged: Vec::new(),
            chosen: Vec::new(),
        })
    }

    /// Puts the last frame's writes back and writes `plan`: the rows of
    /// its patches whose own table is not `bound` (`table`, measured for
    /// this view), its merged nodes' rows, its full-resolution bits, its
    /// merged nodes' level bytes and control point indices, and its chosen
    /// blocks' level bytes. Returns the number of merged nodes' indices
    /// written.
    pub(super) fn write(
        &mut self,
        plan: &FramePlan,
        (bound, table): (&ErrorTable, &ErrorTable),
        terrain: &Terrain,
    ) -> Result<u32> {
        let levels = ErrorTable::LEVELS;
        let grid = terrain.grid();
        let cols = grid.patch_cols();
        let patches = grid.patch_count();
        let measured = !std::ptr::eq(bound, table);
        {
            let errors: &mut [f32] = bytemuck::cast_slice_mut(host(&mut self.errors)?);
            for &p in &self.written_rows {
                let p = p as usize;
                errors[p * levels..(p + 1) * levels].copy_from_slice(bound.patch(p));
            }
            self.written_rows.clear();
            let mut write_row = |p: usize, row: &[f32]| {
                errors[p * levels..(p + 1) * levels].copy_from_slice(row);
                self.written_rows.push(p as u32);
            };
            if measured {
                for block in plan.blocks.iter().filter(|b| !b.chosen) {
                    for p in block.patches(grid) {
                        write_row(p, table.patch(p));
                    }
                }
            }
            for node in &plan.merged {
                write_row(node.row as usize * cols + node.col as usize, &node.errors);
            }
        }
        let words: &mut [u32] = bytemuck::cast_slice_mut(host(&mut self.choice)?);
        let (bits, bytes) = words.split_at_mut(patches.div_ceil(32));
        let (merged_levels, chosen_levels) = bytes.split_at_mut(patches.div_ceil(4));
        let merged_levels: &mut [u8] = bytemuck::cast_slice_mut(merged_levels);
        let chosen_levels: &mut [u8] = bytemuck::cast_slice_mut(chosen_levels);
        let cleared = self.full_words.len();
        for &w in &self.full_words {
            self.full_bits[w as usize] = 0;
        }
        for block in plan.blocks.iter().filter(|b| b.full_resolution) {
            for p in block.patches(grid) {
                let word = &mut self.full_bits[p / 32];
                if *word == 0 {
                    self.full_words.push((p / 32) as u32);
                }
                *word |= 1 << (p % 32);
            }
        }
        // The last frame's words (now clear, or set again) and this
        // frame's; then this frame's alone are kept.
        for &w in &self.full_words {
            bits[w as usize] = self.full_bits[w as usize];
        }
        self.full_words.drain(..cleared);
        // The first patch in the low byte of each word: the bytes in
        // memory order on a little-endian host, as the shader reads them.
        let fill = |bytes: &mut [u8], rect, value: u8| {
            for row in rect_rows(cols, rect) {
                bytes[row].fill(value);
            }
        };
        for node in &self.merged {
            fill(merged_levels, node.patch_range(grid), 0);
        }
        for node in &plan.merged {
            fill(merged_levels, node.patch_range(grid), node.level as u8);
        }
        self.merged.clear();
        self.merged.extend_from_slice(&plan.merged);
        for block in &self.chosen {
            fill(chosen_levels, block.patch_range(grid), 0);
        }
        self.chosen.clear();
        for block in plan.blocks.iter().filter(|b| b.chosen) {
            let value = ChosenLevel::of(block.patch_level);
            fill(chosen_levels, block.patch_range(grid), value);
            self.chosen.push(*block);
        }
        let indices = terrain.indices();
        let corner = |col: usize, row: usize, k: usize| indices[4 * (row * cols + col) + k];
        let merged: &mut [u32] = bytemuck::cast_slice_mut(host(&mut self.merged_indices)?);
        for (i, node) in plan.merged.iter().enumerate() {
            let (c, r, s) = (node.col as usize, node.row as usize, node.span() as usize);
            merged[4 * i..4 * i + 4].copy_from_slice(&[
                corner(c, r, 0),
                corner(c + s - 1, r, 1),
                corner(c, r + s - 1, 2),
                corner(c + s - 1, r + s - 1, 3),
            ]);
        }
        Ok(4 * plan.merged.len() as u32)
    }
}

/// How the choice buffer tells the control shader a level the share
/// chose: one byte a patch, 0 where the patch's own errors decide, else
/// the level index plus one. Mirror: `chosen_level` in glsl/terrain.tesc.
pub(super) struct ChosenLevel;

impl ChosenLevel {
    pub(super) fn of(level: u8) -> u8 {
        level + 1
    }
}

#[cfg(target_endian = "big")]
compile_error!("the merged level bytes are written in little-endian order");

/// A host-visible buffer's memory.
fn host(buffer: &mut Buffer) -> Result<&mut [u8]> {
    buffer
        .mapped_mut()
        .ok_or(RenderError::NotMapped("error LOD memory"))
}

/// The tess path's draws of `plan`'s blocks not drawn at full resolution
/// (see `run_batches`), nearest first (`DrawOrder`).
fn block_batches(plan: &FramePlan, order: &DrawOrder, max_patches: Option<u32>) -> Vec<(u32, u32)> {
    let marks = marked_blocks(plan, order.grid(), false);
    run_batches(order.marked_runs(&marks), max_patches)
}

/// The patches of `plan`'s blocks drawn at full resolution, or of those
/// tessellated (`full_resolution` false), marked in `grid`.
fn marked_blocks(plan: &FramePlan, grid: &PatchGrid, full_resolution: bool) -> PatchMarks {
    let mut marks = PatchMarks::new(grid);
    for block in plan
        .blocks
        .iter()
        .filter(|b| b.full_resolution == full_resolution)
    {
        let (cols, rows) = block.patch_range(grid);
        marks.mark(cols, rows);
    }
    marks
}

/// The tess path's draws of the patches `drawn` (indices in increasing
/// order), one draw per run of consecutive patches (see `run_batches`).
pub(super) fn patch_batches(
    drawn: impl IntoIterator<Item = u32>,
    max_patches: Option<u32>,
) -> Vec<(u32, u32)> {
    run_batches(drawn.into_iter().map(|p| (p, 1)), max_patches)
}

/// Draws of `runs` of consecutive patches (first, count), in their order,
/// as (first index, index count) with four indices a patch: a run that
/// continues the one before joins its draw, and draws are split into at
/// most `max_patches` (see `Workarounds::max_patches_per_draw`). Patches
/// left out never reach the control shader.
pub(super) fn run_batches(
    runs: impl IntoIterator<Item = (u32, u32)>,
    max_patches: Option<u32>,
) -> Vec<(u32, u32)> {
    let mut batches = Batches::new(max_patches);
    for (first, n) in runs {
        batches.push_run(first, n);
    }
    batches.into_indices()
}

/// `run_batches`, with each patch of `alone` (in increasing order) drawn
/// by itself: a run is cut around it, and no run joins its draw. A driver
/// that clips a whole draw wherever one of its vertices needs clipping
/// (lavapipe sends such a draw down its per-primitive path) then clips
/// that patch alone, not the dense patches drawn with it. `alone` holds
/// the patches the frustum's boundary crosses (`plan::view_patches`).
pub(super) fn run_batches_apart(
    runs: impl IntoIterator<Item = (u32, u32)>,
    alone: &[u32],
    max_patches: Option<u32>,
) -> Vec<(u32, u32)> {
    let is_alone = |p: u32| alone.binary_search(&p).is_ok();
    let mut batches = Batches::new(max_patches);
    for (first, n) in runs {
        let mut start = first;
        for p in (first..first + n).filter(|&p| is_alone(p)) {
            batches.push_run(start, p - start);
            batches.push_alone(p);
            start = p + 1;
        }
        batches.push_run(start, first + n - start);
    }
    batches.into_indices()
}

/// Draws built run by run, in patches (`run_batches`).
struct Batches {
    max_patches: u32,
    draws: Vec<(u32, u32)>,
    /// Whether the next run may join the last draw: not where that draw
    /// is a patch drawn alone.
    joinable: bool,
}

impl Batches {
    fn new(max_patches: Option<u32>) -> Batches {
        Batches {
            max_patches: max_patches.unwrap_or(u32::MAX).max(1),
            draws: Vec::new(),
            joinable: false,
        }
    }

    /// Adds the run of `n` patches from `first` (none where `n` is 0),
    /// joining the last draw where it continues it.
    fn push_run(&mut self, mut first: u32, mut n: u32) {
        if n == 0 {
            return;
        }
        let max = self.max_patches;
        if let Some(last) = self
            .draws
            .last_mut()
            .filter(|l| self.joinable && l.0 + l.1 == first)
        {
            let joined = n.min(max - last.1);
            last.1 += joined;
            (first, n) = (first + joined, n - joined);
        }
        while n > 0 {
            let taken = n.min(max);
            self.draws.push((first, taken));
            (first, n) = (first + taken, n - taken);
        }
        self.joinable = true;
    }

    /// Adds patch `p` in a draw of its own, which no run joins.
    fn push_alone(&mut self, p: u32) {
        self.draws.push((p, 1));
        self.joinable = false;
    }

    /// The draws as (first index, index count), four indices a patch.
    fn into_indices(self) -> Vec<(u32, u32)> {
        self.draws
            .into_iter()
            .map(|(first, n)| (first * 4, n * 4))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::{patch_batches, run_batches, run_batches_apart};

    fn batches(drawn: &str, max: Option<u32>) -> Vec<(u32, u32)> {
        let indices = drawn
            .chars()
            .enumerate()
            .filter(|&(_, c)| c == '#')
            .map(|(i, _)| i as u32);
        patch_batches(indices, max)
    }

    #[test]
    fn tess_draws_cover_exactly_the_drawn_patches() {
        // Runs, in indices (four a patch).
        assert_eq!(batches("##..###.#", None), vec![(0, 8), (16, 12), (32, 4)]);
        assert_eq!(batches("....", None), vec![]);
        assert_eq!(batches("", Some(8)), vec![]);
        // Split where the driver limits a draw, and runs end at gaps.
        assert_eq!(
            batches("#####.##", Some(2)),
            vec![(0, 8), (8, 8), (16, 4), (24, 8)]
        );
        let all = batches(&"#".repeat(17), Some(8));
        assert_eq!(all, vec![(0, 32), (32, 32), (64, 4)]);
    }

    #[test]
    fn patches_drawn_alone_are_cut_out_of_their_runs_and_joined_to_none() {
        // Runs nearest first, as in the test below; 5 and 9 drawn alone.
        let runs = [(2, 2), (4, 2), (0, 2), (9, 5)];
        assert_eq!(
            run_batches_apart(runs, &[5, 9], None),
            vec![(8, 12), (20, 4), (0, 8), (36, 4), (40, 16)]
        );
        // Nothing alone: the same draws as `run_batches`.
        assert_eq!(
            run_batches_apart(runs, &[], Some(3)),
            run_batches(runs, Some(3))
        );
        // Every patch alone: one draw each, in the runs' order.
        let each: Vec<(u32, u32)> = [2, 3, 4, 5, 0, 1, 9, 10, 11, 12, 13]
            .map(|p| (4 * p, 4))
            .to_vec();
        assert_eq!(
            run_batches_apart(runs, &[0, 1, 2, 3, 4, 5, 9, 10, 11, 12, 13], None),
            each
        );
    }

    #[test]
    fn ordered_runs_keep_their_order_and_join_only_what_continues() {
        // Runs nearest first: 4..6 continues 2..4, 0..2 does not.
        let runs = [(2, 2), (4, 2), (0, 2), (9, 5)];
        assert_eq!(run_batches(runs, None), vec![(8, 16), (0, 8), (36, 20)]);
        assert_eq!(
            run_batches(runs, Some(3)),
            vec![(8, 12), (20, 4), (0, 8), (36, 12), (48, 8)]
        );
    }
}
