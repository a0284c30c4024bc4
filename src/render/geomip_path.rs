//! The geomip path on the GPU: one vertex template and one index list
//! per level and stitched-side mask, shared by every patch; each frame the
//! patches in view become draws with their level and morph factors
//! (see `lod::geomip`), listed in a buffer that one indirect call draws
//! from (`GeomipList`), or pushed draw by draw where the device cannot.

use std::mem::size_of;

use ash::vk;

use super::occlusion::DRAW_COMMAND_BYTES;
use super::pipelines::{build_pipelines, PathPipelines, PipelineTarget};
use super::settings::{ErrorMeasure, LodMetric, RenderPath, RenderSettings};
use super::view::FrameView;
use super::view_measure::seen_errors;
use crate::gpu::commands::Recorder;
use crate::gpu::descriptors::DescriptorSet;
use crate::gpu::memory::Buffer;
use crate::gpu::owned::{DescriptorSetLayout, PipelineLayout};
use crate::lod::buffers::touched;
use crate::lod::geomip::{self, PatchLevels};
use crate::lod::hierarchy::{rect_bounds, rect_rows, Hierarchy, NodeId};
use crate::lod::order::DrawOrder;
use crate::lod::plan::{patches_in_view, PlanInputs, Planner, SightReading};
use crate::lod::seen::SeenPixels;
use crate::lod::view::Tau;
use crate::lod::view_measure::Diagonal;
use crate::render::error::Result;
use crate::shader_constants::OWN_PATCH_CONSTANTS;
use crate::terrain::grid::{PatchGrid, PatchId};
use crate::terrain::{ErrorTable, Terrain};

pub(super) struct GeomipGeometry {
    template: Buffer,
    indices: Buffer,
    variants: Vec<(u32, u32)>,
    /// (first index, count) of the unstitched full-resolution list of each
    /// patch size (cells x, z) the grid has: remainder patches at the far
    /// edges draw only their own cells.
    full_resolution: Vec<([usize; 2], (u32, u32))>,
    pub(super) pipelines: PathPipelines,
    /// The shared layout plus the per-patch push constants.
    layout: PipelineLayout,
    /// Per-patch errors of each level, for choosing levels by projected error.
    errors: ErrorTable,
    /// How far stitched sides stray, for the error LOD's balancing; None
    /// where the terrain's samples are not held.
    stitch: Option<geomip::StitchErrors>,
    /// Levels set from outside (`set_geomip_levels`) instead of chosen,
    /// balanced, with no morph.
    pub(super) given: Option<geomip::PatchLevels>,
}

/// A choice of levels for every patch (`GeomipGeometry::choose`), read by
/// `GeomipGeometry::emit`: a frame slot's, kept from its last frame so
/// that a choice fills memory it filled before.
#[derive(Debug, Default)]
pub(super) struct ChosenPatches {
    /// Every patch's level and morph factor.
    levels: geomip::PatchLevels,
    /// One flag per patch: whether it is drawn.
    drawn: Vec<bool>,
    /// The drawn patches, in grid order.
    visible: Vec<u32>,
    /// The error LOD's blocks as columns and rows of patches.
    rects: Vec<Rect>,
    /// Per block of `rects`, the sides a drawn neighbour may be one level
    /// coarser beyond (`geomip::stitchable_sides`).
    stitched: Vec<[bool; geomip::BLOCK_SIDES]>,
    /// The distance LOD's distances, one per drawn patch in grid order.
    distances: Vec<f32>,
    /// Where the last choice may have left entries unlike `reset`'s;
    /// None: anywhere.
    written: Option<Written>,
}

/// Patches of a grid as columns and rows, end exclusive.
type Rect = ([usize; 2], [usize; 2]);

/// The patches a choice may have changed from `ChosenPatches::reset`'s
/// state, on the grid it was sized for (its columns, its coarsest level).
#[derive(Clone, Copy, Debug)]
struct Written {
    cols: usize,
    coarsest: u8,
    rect: Rect,
}

impl ChosenPatches {
    /// Room for the levels, morph factors and flags of `patches` patches,
    /// the list of those drawn, and `blocks` blocks, their memory written
    /// once (`buffers::touched`): the first choice's `reset` sizes them to
    /// the grid, and finds its pages already the process's.
    pub(super) fn with_capacity(patches: usize, blocks: usize) -> Self {
        let mut chosen = ChosenPatches::default();
        touched(&mut chosen.levels.levels, patches);
        touched(&mut chosen.levels.morph, patches);
        touched(&mut chosen.drawn, patches);
        touched(&mut chosen.visible, patches);
        touched(&mut chosen.rects, blocks);
        touched(&mut chosen.stitched, blocks);
        chosen
    }

    /// Every patch of `grid` at level `coarsest`, with no morph and not
    /// drawn. Where the last choice was on the same grid, only the patches
    /// it wrote are reset (`Written`), so a frame's choice costs what is
    /// in view, not the grid.
    fn reset(&mut self, grid: &PatchGrid, coarsest: u8) {
        let (patches, cols) = (grid.patch_count(), grid.patch_cols());
        let PatchLevels { levels, morph } = &mut self.levels;
        match self.written.take() {
            Some(w) if w.cols == cols && w.coarsest == coarsest && levels.len() == patches => {
                for row in rect_rows(cols, w.rect) {
                    levels[row.clone()].fill(coarsest);
                    morph[row.clone()].fill(0.0);
                    self.drawn[row].fill(false);
                }
            }
            _ => {
                levels.clear();
                levels.resize(patches, coarsest);
                morph.clear();
                morph.resize(patches, 0.0);
                self.drawn.clear();
                self.drawn.resize(patches, false);
            }
        }
        self.visible.clear();
        self.rects.clear();
        self.stitched.clear();
        self.distances.clear();
    }

    /// Notes what a choice on `grid` drew (`drawn`: the bounds of its drawn
    /// patches, None for none) for the next `reset`: those patches, and
    /// those refining and balancing can have lowered around them
    /// (`geomip::balance_reach`).
    fn wrote(&mut self, grid: &PatchGrid, coarsest: u8, drawn: Option<Rect>) {
        let reach = geomip::balance_reach(grid.cells_per_patch());
        let rect = drawn.map_or(([0, 0], [0, 0]), |([c0, c1], [r0, r1])| {
            (
                [
                    c0.saturating_sub(reach),
                    (c1 + reach).min(grid.patch_cols()),
                ],
                [
                    r0.saturating_sub(reach),
                    (r1 + reach).min(grid.patch_rows()),
                ],
            )
        });
        self.written = Some(Written {
            cols: grid.patch_cols(),
            coarsest,
            rect,
        });
    }

    /// `visible` from the drawn flags of the patches in `within` (of a grid
    /// `cols` patches wide; none are drawn outside it), in grid order,
    /// eight flags at a time: a run of eight patches all drawn or none
    /// drawn costs one test.
    fn list_drawn(&mut self, cols: usize, within: Rect) {
        let visible = &mut self.visible;
        visible.clear();
        for row in rect_rows(cols, within) {
            let flags: &[u8] = bytemuck::cast_slice(&self.drawn[row.clone()]);
            let words = flags.chunks_exact(8);
            let rest = words.remainder();
            let mut first = row.start as u32;
            for word in words {
                let bits = u64::from_le_bytes(word.try_into().expect("eight flags"));
                match bits {
                    0 => {}
                    ALL_DRAWN => visible.extend(first..first + 8),
                    _ => push_flagged(visible, first, word),
                }
                first += 8;
            }
            push_flagged(visible, first, rest);
        }
    }
}

/// Pushes `first + i` for each flag `i` of `flags` that is set.
fn push_flagged(out: &mut Vec<u32>, first: u32, flags: &[u8]) {
    out.extend(
        (first..)
            .zip(flags)
            .filter(|(_, &flag)| flag != 0)
            .map(|(p, _)| p),
    );
}

/// Eight drawn flags (`true` is 1) read as one little-endian word.
const ALL_DRAWN: u64 = 0x0101_0101_0101_0101;

/// One patch of the geomip path: its index list and constants.
#[derive(Clone, Copy, Debug)]
pub(super) struct GeomipDraw {
    /// The patch's index in the grid.
    pub(super) patch: u32,
    pub(super) first: u32,
    pub(super) count: u32,
    pub(super) constants: GeomipConstants,
}

/// One patch's constants in glsl/geomip.vert (`PatchConstants`), as
/// listed (std430) and as pushed.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GeomipConstants {
    pub origin: [i32; 2],
    pub level: i32,
    pub interior: f32,
    pub sides: [f32; 4],
}
const _: () = assert!(size_of::<GeomipConstants>() == 32);
const _: () = assert!(std::mem::offset_of!(GeomipConstants, sides) == 16);

/// Push constants of glsl/geomip.vert (`DrawConstants`): a draw's own
/// constants, or where its listed ones start.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
struct GeomipPush {
    own: GeomipConstants,
    /// `OWN_PATCH_CONSTANTS`, or the list index that the draw's instance
    /// index counts from.
    first_listed: u32,
}
const _: () = assert!(size_of::<GeomipPush>() == 36);
const _: () = assert!(std::mem::offset_of!(GeomipPush, first_listed) == 32);
impl GeomipGeometry {
    /// The path's vertex template, index lists and pipelines for
    /// `terrain`, on the renderer's set layout; `errors` is its error
    /// table (the reference's diagonal).
    pub(super) fn new(
        target: &PipelineTarget,
        set_layout: &DescriptorSetLayout,
        terrain: &Terrain,
        errors: ErrorTable,
        wireframe: bool,
    ) -> Result<GeomipGeometry> {
        let device = target.device;
        let n = terrain.grid().cells_per_patch();
        let mut variants = geomip::IndexVariants::build(n);
        let grid = terrain.grid();
        let mut full_resolution: Vec<([usize; 2], (u32, u32))> = Vec::new();
        for p in 0..grid.patch_count() {
            let rect = grid.sample_rect(grid.patch_id(p));
            let cells = [rect.cells_x(), rect.cells_z()];
            if full_resolution.iter().all(|(c, _)| *c != cells) {
                let list = geomip::full_resolution_indices(n, cells);
                let range = (variants.indices.len() as u32, list.len() as u32);
                variants.indices.extend(list);
                full_resolution.push((cells, range));
            }
        }
        let layout = device.create_pipeline_layout_with_push(
            &[set_layout],
            vk::ShaderStageFlags::VERTEX,
            size_of::<GeomipPush>() as u32,
            "terrain.pipeline_layout.geomip",
        )?;
        Ok(GeomipGeometry {
            template: device.upload_buffer(
                "terrain.geomip_vertex_template",
                vk::BufferUsageFlags::VERTEX_BUFFER,
                bytemuck::cast_slice(&geomip::vertex_template(n)),
            )?,
            indices: device.upload_buffer(
                "terrain.geomip_indices",
                vk::BufferUsageFlags::INDEX_BUFFER,
                bytemuck::cast_slice(&variants.indices),
            )?,
            variants: variants.ranges,
            full_resolution,
            pipelines: build_pipelines(target, &layout, (RenderPath::Geomip, false), wireframe)?,
            layout,
            stitch: terrain
                .info()
                .heightmap()
                .map(|map| geomip::StitchErrors::compute(map, grid, &errors)),
            errors,
            given: None,
        })
    }
}

impl GeomipGeometry {
    /// Levels by distance or error for the patches in view, balanced, with
    /// their morph factors: the level choice, which the renderer times.
    /// `draws` gets the frame's draws where they come with the choice (the
    /// given levels' and the view measure's).
    pub(super) fn choose(
        &mut self,
        terrain: &Terrain,
        (hierarchy, seen): (&Hierarchy, Option<&SeenPixels>),
        view: &FrameView,
        settings: &RenderSettings,
        (draws, planner, chosen): (&mut Vec<GeomipDraw>, &mut Planner, &mut ChosenPatches),
    ) -> GeomipChoice {
        let grid = terrain.grid();
        let count = geomip::level_count(grid.cells_per_patch());
        let tau = match settings.lod_metric {
            LodMetric::Error(pixels) => Some(pixels),
            _ => None,
        };
        let lod_view = view.lod_view(tau.and_then(|t| Tau::new(t).ok()).unwrap_or_default());
        if let Some(given) = &self.given {
            let (visible, _) = patches_in_view(terrain, hierarchy, &lod_view, settings.cull);
            let mut levels = given.clone();
            let mut drawn = vec![false; grid.patch_count()];
            mark_drawn(&mut drawn, &visible);
            let edges: Vec<PatchId> = visible.iter().map(|&p| grid.patch_id(p as usize)).collect();
            let lowered = geomip::refine_beside(&mut levels.levels, grid, &drawn, &edges);
            geomip::balance_from(&mut levels.levels, grid, &lowered);
            self.set_draws(terrain, (view, settings), (&visible, &levels), draws, None);
            return GeomipChoice::Drawn(None);
        }
        if let (Some(pixels), ErrorMeasure::View) = (tau, settings.error_measure) {
            let predicted = self.choose_by_view_measure(terrain, view, settings, pixels, draws);
            return GeomipChoice::Drawn(Some(predicted));
        }
        // Every patch starts at the coarsest level, and those in view get
        // theirs; the coarsest constrains no neighbour.
        let coarsest = (count - 1) as u8;
        chosen.reset(grid, coarsest);
        let mut over_share = None;
        let PatchLevels { levels, morph } = &mut chosen.levels;
        match tau {
            None => {
                let visible = patches_in_view(terrain, hierarchy, &lod_view, settings.cull).0;
                let edges: Vec<PatchId> =
                    visible.iter().map(|&p| grid.patch_id(p as usize)).collect();
                let distances = &mut chosen.distances;
                distances.extend(
                    edges
                        .iter()
                        .map(|&id| patch_distance(hierarchy, id, view.eye_local)),
                );
                for (&p, &d) in visible.iter().zip(distances.iter()) {
                    levels[p as usize] =
                        geomip::level_for_distance(d, settings.lod.min_dist, count) as u8;
                }
                mark_drawn(&mut chosen.drawn, &visible);
                // Every drawn patch can lower a neighbour; the morph
                // factors follow the balanced levels.
                geomip::refine_and_balance(levels, grid, &chosen.drawn, &edges);
                for (&p, &d) in visible.iter().zip(distances.iter()) {
                    let level = usize::from(levels[p as usize]);
                    if level + 1 < count {
                        morph[p as usize] = geomip::morph_factor(d, settings.lod.min_dist, level);
                    }
                }
                let cols = grid.patch_cols();
                let drawn = rect_bounds(
                    visible
                        .iter()
                        .map(|&p| (p as usize % cols, p as usize / cols))
                        .map(|(c, r)| ([c, c + 1], [r, r + 1])),
                );
                chosen.visible = visible;
                chosen.wrote(grid, coarsest, drawn);
            }
            Some(_) => {
                let sight = match settings.error_measure {
                    ErrorMeasure::Sight => terrain.sight_table(),
                    _ => None,
                };
                let frame_plan = planner.plan(
                    terrain,
                    hierarchy,
                    &lod_view,
                    &PlanInputs {
                        table: &self.errors,
                        sight,
                        merge: false,
                        cull: settings.cull,
                        reading: SightReading::Template,
                        seen,
                    },
                );
                // A block's patches take its level (`geomip::level_of_index`),
                // and glide towards the next coarser one (`geomip::block_glide`).
                let cols = grid.patch_cols();
                for block in &frame_plan.blocks {
                    let k = usize::from(block.patch_level).min(count - 1);
                    let level = geomip::level_of_index(k, count);
                    let glide = geomip::block_glide(block, k, hierarchy, &lod_view);
                    let rect = block.patch_range(grid);
                    for row in rect_rows(cols, rect) {
                        levels[row.clone()].fill(level as u8);
                        // Every morph factor starts at none.
                        if glide > 0.0 {
                            morph[row.clone()].fill(glide);
                        }
                        chosen.drawn[row].fill(true);
                    }
                    chosen.rects.push(rect);
                    chosen.stitched.push(geomip::stitchable_sides(
                        (block, k),
                        (hierarchy, grid),
                        &lod_view,
                        self.stitch.as_ref(),
                    ));
                }
                over_share = frame_plan.predicted_over_share;
                // A block's patches share its level: only its sides can
                // lower a neighbour.
                geomip::refine_and_balance_blocks(
                    levels,
                    grid,
                    &chosen.drawn,
                    &chosen.rects,
                    &chosen.stitched,
                );
                let drawn = rect_bounds(chosen.rects.iter().copied());
                chosen.list_drawn(cols, drawn.unwrap_or_default());
                chosen.wrote(grid, coarsest, drawn);
            }
        }
        GeomipChoice::Levels {
            error_lod: tau.is_some(),
            over_share,
        }
    }

    /// The draws of a choice of levels, and the largest error the error
    /// LOD expects on screen (and its 99th percentile where the view
    /// measured it).
    pub(super) fn emit(
        &self,
        terrain: &Terrain,
        hierarchy: &Hierarchy,
        view: &FrameView,
        settings: &RenderSettings,
        (choice, chosen): (GeomipChoice, &ChosenPatches),
        draws: &mut Vec<GeomipDraw>,
    ) -> Option<(f32, Option<f32>)> {
        let error_lod = match choice {
            GeomipChoice::Drawn(predicted) => return predicted,
            GeomipChoice::Levels { error_lod, .. } => error_lod,
        };
        let predict = error_lod.then_some(hierarchy);
        self.set_draws(
            terrain,
            (view, settings),
            (&chosen.visible, &chosen.levels),
            draws,
            predict,
        )
        .map(|max| (max, None))
    }

    /// The error LOD's levels from the view measure's table (every patch,
    /// sample by sample): the patches in the frustum become the draws.
    fn choose_by_view_measure(
        &mut self,
        terrain: &Terrain,
        view: &FrameView,
        settings: &RenderSettings,
        pixels: f32,
        draws: &mut Vec<GeomipDraw>,
    ) -> (f32, Option<f32>) {
        let drawn = view.patches_drawn(terrain, settings.cull);
        let seen = seen_errors(
            terrain,
            &self.errors,
            Diagonal::Reference,
            view,
            (settings, pixels),
            &drawn,
        );
        let table = seen.as_ref().map_or(&self.errors, |s| &s.table);
        let mut chosen = geomip::select_levels_by_error(
            terrain,
            table,
            view.eye_local,
            view.pixels_per_radian,
            pixels,
            &drawn,
            self.stitch.as_ref(),
        );
        if let Some(v) = &seen {
            geomip::limit_morph(&mut chosen, &v.morph_limits, &drawn, terrain.grid());
        }
        let visible: Vec<u32> = (0..drawn.len() as u32)
            .filter(|&p| drawn[p as usize])
            .collect();
        self.set_draws(terrain, (view, settings), (&visible, &chosen), draws, None);
        match seen {
            Some(v) => (v.predicted_max_px, Some(v.predicted_p99_px)),
            None => (0.0, None),
        }
    }

    /// The unstitched full-resolution index list of a patch of `cells`.
    pub(super) fn full_resolution_range(&self, cells: [usize; 2]) -> (u32, u32) {
        self.full_resolution
            .iter()
            .find(|(c, _)| *c == cells)
            .map_or(self.variants[0], |&(_, range)| range)
    }

    /// Binds the geomip pipeline and geometry, for this path's patches or
    /// the tess path's full-resolution ones (`push_listed`, `draw_own`).
    pub(super) fn bind(&self, rec: &Recorder, set: DescriptorSet, wireframe: bool) -> Result<()> {
        rec.bind_graphics(self.pipelines.select(wireframe)?, &self.layout, set);
        rec.bind_geometry(&self.template, &self.indices);
        Ok(())
    }

    /// After `bind`: the draws that follow read their constants from the
    /// frame's list, draw i's at list index i (its first instance).
    pub(super) fn push_listed(&self, rec: &Recorder) {
        let push = GeomipPush {
            first_listed: 0,
            ..GeomipPush::default()
        };
        rec.push_constants(
            &self.layout,
            vk::ShaderStageFlags::VERTEX,
            bytemuck::bytes_of(&push),
        );
    }

    /// After `bind`: `draws` one call each, each pushing its own
    /// constants; with `indirect`, draw i reads its instance count (0 or
    /// 1, set by the occlusion state) from command `first + i` of the
    /// buffer.
    pub(super) fn draw_own(
        &self,
        rec: &Recorder,
        draws: &[GeomipDraw],
        indirect: Option<(&Buffer, u64)>,
    ) {
        for (i, draw) in draws.iter().enumerate() {
            let push = GeomipPush {
                own: draw.constants,
                first_listed: OWN_PATCH_CONSTANTS,
            };
            rec.push_constants(
                &self.layout,
                vk::ShaderStageFlags::VERTEX,
                bytemuck::bytes_of(&push),
            );
            match indirect {
                Some((commands, first)) => {
                    rec.draw_indexed_indirect(commands, (first + i as u64) * DRAW_COMMAND_BYTES, 1)
                }
                None => rec.draw_indexed(draw.first, draw.count),
            }
        }
    }

    /// The patches `visible` this frame (in grid order), at their
    /// `chosen` levels, become `draws`, front to back in the runs of
    /// `DrawOrder` (a run's patches in index order): ordered a run at a
    /// time, not a draw at a time. With `predict`, returns the largest
    /// error they are expected to show from `view`
    /// (`geomip::predicted_px`, each patch's box its node's in the
    /// hierarchy).
    fn set_draws(
        &self,
        terrain: &Terrain,
        (view, settings): (&FrameView, &RenderSettings),
        (visible, chosen): (&[u32], &geomip::PatchLevels),
        draws: &mut Vec<GeomipDraw>,
        predict: Option<&Hierarchy>,
    ) -> Option<f32> {
        let grid = terrain.grid();
        let levels = geomip::level_count(grid.cells_per_patch());
        let mut predicted = 0.0f32;
        draws.clear();
        draws.reserve(visible.len());
        let order = DrawOrder::new(terrain.info(), grid, view.eye_local);
        let runs = order.runs(visible.iter().copied());
        for p in runs.iter().flat_map(|&(first, n)| first..first + n) {
            let p = p as usize;
            let id = grid.patch_id(p);
            let level = usize::from(chosen.levels[p]);
            let (coarser, _) = geomip::neighbour_masks(&chosen.levels, grid, id);
            let rect = grid.sample_rect(id);
            let (first, count) = if level == 0 && coarser == 0 {
                self.full_resolution_range([rect.cells_x(), rect.cells_z()])
            } else {
                self.variants[level * 16 + usize::from(coarser)]
            };
            let (interior, sides) = if settings.geomorph {
                geomip::patch_morph(chosen, grid, id)
            } else {
                (0.0, [0.0; 4])
            };
            if let Some(hierarchy) = predict {
                let node = hierarchy.node(NodeId::patch(id));
                let (lo, hi) = node.aabb();
                let holds_eye = node.distance(view.eye_local) <= 0.0;
                let ground = match holds_eye && level > 0 {
                    true => terrain
                        .surface_distances(id, view.eye_local, &[0.0])
                        .map(|[d]| d),
                    false => None,
                };
                let patch = geomip::DrawnPatch {
                    ground,
                    lo,
                    hi,
                    level,
                    morph: sides.iter().fold(interior, |a, &b| a.max(b)),
                    coarser,
                    fans: std::array::from_fn(|bit| match &self.stitch {
                        Some(s) if coarser & (1 << bit) != 0 => s.excess(p, level, 1 << bit),
                        _ => 0.0,
                    }),
                };
                // Level 0 is the reference.
                let error = |l: usize| match l {
                    0 => 0.0,
                    l => self
                        .errors
                        .error(p, geomip::table_index(l.min(levels - 1), levels)),
                };
                predicted = predicted.max(geomip::predicted_px(
                    error,
                    &patch,
                    view.eye_local,
                    view.pixels_per_radian,
                ));
            }
            draws.push(GeomipDraw {
                patch: p as u32,
                first,
                count,
                constants: GeomipConstants {
                    origin: [rect.col0 as i32, rect.row0 as i32],
                    level: level as i32,
                    interior,
                    sides,
                },
            });
        }
        predict.map(|_| predicted)
    }
}

/// What the geomip path's level choice made: the levels of the patches in
/// view, or (given levels, the view measure) the draws themselves, with
/// what the choice expects.
#[derive(Clone, Copy, Debug)]
pub(super) enum GeomipChoice {
    /// Levels for every patch, kept in the geometry (`ChosenPatches`).
    Levels {
        /// Chosen by the error LOD (it reports what it expects).
        error_lod: bool,
        /// The view model's share of pixels over tau at those levels
        /// (`FramePlan::predicted_over_share`).
        over_share: Option<f32>,
    },
    Drawn(Option<(f32, Option<f32>)>),
}

/// Distance from `eye_local` to the nearest point of patch `p`'s box (its
/// node's in `hierarchy`: one read, where the terrain's box is three).
fn patch_distance(hierarchy: &Hierarchy, p: PatchId, eye_local: glam::Vec3) -> f32 {
    hierarchy.node(NodeId::patch(p)).distance(eye_local)
}

/// Sets the flag (one per patch) of each of `visible`.
fn mark_drawn(drawn: &mut [bool], visible: &[u32]) {
    for &p in visible {
        drawn[p as usize] = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every drawn patch is listed once, in grid order, whatever runs of
    /// drawn and not drawn the flags hold within the rectangle read, the
    /// last short word of each row included.
    #[test]
    fn list_drawn_lists_each_drawn_patch_in_grid_order() {
        let (cols, rows) = (67usize, 3usize);
        let mut chosen = ChosenPatches::default();
        for within in [
            ([0, 0], [0, 0]),
            ([0, 5], [1, 2]),
            ([3, 11], [0, 3]),
            ([0, 67], [0, 3]),
            ([30, 59], [1, 3]),
        ] {
            let ([c0, c1], [r0, r1]) = within;
            // Runs of all, none and some drawn, inside the rectangle only.
            let drawn: Vec<bool> = (0..cols * rows)
                .map(|p| {
                    let (c, r) = (p % cols, p / cols);
                    (c0..c1).contains(&c)
                        && (r0..r1).contains(&r)
                        && match (p / 8) % 3 {
                            0 => true,
                            1 => false,
                            _ => p % 3 == 0,
                        }
                })
                .collect();
            chosen.drawn = drawn.clone();
            chosen.list_drawn(cols, within);
            let expected: Vec<u32> = (0..(cols * rows) as u32)
                .filter(|&p| drawn[p as usize])
                .collect();
            assert_eq!(chosen.visible, expected, "{within:?}");
        }
    }

    /// A reset after a choice leaves every patch as a reset of a fresh
    /// choice does, where the choice wrote only within the reach of what
    /// it drew; on another grid, or at another coarsest level, the whole
    /// grid is reset.
    #[test]
    fn a_reset_restores_what_the_last_choice_wrote() {
        // 32 x 16 patches of 16 cells: levels 0 to 4.
        let grid = PatchGrid::for_size(513, 257, 16);
        let (cols, coarsest) = (grid.patch_cols(), 4u8);
        let reach = geomip::balance_reach(grid.cells_per_patch());
        let mut fresh = ChosenPatches::default();
        fresh.reset(&grid, coarsest);
        let mut chosen = ChosenPatches::default();
        chosen.reset(&grid, coarsest);
        // A block drawn at the finest level, near the grid's first
        // corner, and what refining and balancing can lower around it.
        let block: Rect = ([2, 6], [1, 3]);
        for p in 0..grid.patch_count() {
            let (c, r) = (p % cols, p / cols);
            let (dc, dr) = (
                (block.0[0].saturating_sub(c)).max(c.saturating_sub(block.0[1] - 1)),
                (block.1[0].saturating_sub(r)).max(r.saturating_sub(block.1[1] - 1)),
            );
            if dc + dr == 0 {
                chosen.levels.levels[p] = 0;
                chosen.levels.morph[p] = 0.5;
                chosen.drawn[p] = true;
            } else if dc + dr <= reach {
                chosen.levels.levels[p] = (dc + dr - 1) as u8;
            }
        }
        chosen.wrote(&grid, coarsest, Some(block));
        chosen.reset(&grid, coarsest);
        assert_eq!(chosen.levels.levels, fresh.levels.levels);
        assert_eq!(chosen.levels.morph, fresh.levels.morph);
        assert_eq!(chosen.drawn, fresh.drawn);
        // Another coarsest level, then another grid: everything anew.
        chosen.wrote(&grid, coarsest, Some(block));
        chosen.reset(&grid, 3);
        assert!(chosen.levels.levels.iter().all(|&l| l == 3));
        let other = PatchGrid::for_size(257, 257, 16);
        chosen.wrote(&grid, 3, None);
        chosen.reset(&other, 3);
        assert_eq!(chosen.levels.levels.len(), other.patch_count());
        assert_eq!(chosen.drawn.len(), other.patch_count());
    }
}
