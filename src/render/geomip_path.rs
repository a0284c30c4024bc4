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
use crate::lod::geomip;
use crate::lod::geomip_choice::ChosenPatches;
use crate::lod::hierarchy::{Hierarchy, NodeId};
use crate::lod::order::DrawOrder;
use crate::lod::plan::{patches_in_view, PlanInputs, Planner, SightReading};
use crate::lod::seen::SeenPixels;
use crate::lod::view::Tau;
use crate::lod::view_measure::Diagonal;
use crate::render::error::Result;
use crate::shader_constants::OWN_PATCH_CONSTANTS;
use crate::terrain::grid::PatchId;
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
        let tau = match settings.lod_metric {
            LodMetric::Error(pixels) => Some(pixels),
            _ => None,
        };
        let lod_view = view.lod_view(tau.and_then(|t| Tau::new(t).ok()).unwrap_or_default());
        if let Some(given) = &self.given {
            let (visible, _) = patches_in_view(terrain, hierarchy, &lod_view, settings.cull);
            let mut levels = given.clone();
            let mut drawn = vec![false; grid.patch_count()];
            for &p in &visible {
                drawn[p as usize] = true;
            }
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
        let over_share = match tau {
            None => {
                chosen.by_distance(
                    terrain,
                    hierarchy,
                    &lod_view,
                    (settings.cull, settings.lod.min_dist),
                );
                None
            }
            Some(_) => {
                let sight = match settings.error_measure {
                    ErrorMeasure::Sight => terrain.sight_table(),
                    _ => None,
                };
                let inputs = PlanInputs {
                    table: &self.errors,
                    sight,
                    merge: false,
                    cull: settings.cull,
                    reading: SightReading::Template,
                    seen,
                };
                chosen.by_error(
                    terrain,
                    hierarchy,
                    &lod_view,
                    (planner, &inputs),
                    self.stitch.as_ref(),
                )
            }
        };
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
            (chosen.visible(), chosen.levels()),
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
