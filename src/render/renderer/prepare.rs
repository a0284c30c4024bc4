//! Setting a frame slot up for its frame: the path built, the uniforms
//! written, the last frame's counts and culling taken in, and this frame's
//! levels chosen (the geomip path's, the tess path's error LOD plan); and
//! what the last prepared frame's choice reports.

use std::time::Instant;

use super::TerrainRenderer;
use crate::lod::geomip;
use crate::lod::order::DrawOrder;
use crate::lod::plan::view_patches;
use crate::lod::seen::SeenPixels;
use crate::lod::view::Tau;
use crate::render::error::{RenderError, Result};
use crate::render::frame::FrameSlot;
use crate::render::geomip_path::GeomipChoice;
use crate::render::occlusion::LastFrame;
use crate::render::pipelines::{create_culled_pipeline, CulledPipelines};
use crate::render::seen::CountKey;
use crate::render::settings::{ErrorMeasure, LodMetric, RenderPath, RenderSettings};
use crate::render::tess_path::run_batches_apart;
use crate::render::uniforms::FrameUniforms;
use crate::render::view::FrameView;
use crate::terrain::{PatchGrid, Terrain};

impl TerrainRenderer {
    /// Sets frame slot `slot` up for a frame of `settings` (its previous
    /// frame must have completed): builds the path if this renderer lacks
    /// it, writes the uniforms and, for the geomip path and the tess
    /// path's error LOD, chooses this frame's patch levels. `record` then
    /// draws exactly this.
    pub fn prepare(
        &mut self,
        slot: usize,
        terrain: &Terrain,
        view: &FrameView,
        settings: &RenderSettings,
    ) -> Result<()> {
        self.ensure(terrain, settings.path, settings.wireframe)?;
        self.build_view_model(terrain, settings);
        if settings.show_culled && self.culled_pipelines.is_none() && self.tess.is_some() {
            let target = self.pipeline_target();
            self.culled_pipelines = Some(CulledPipelines {
                fractional: create_culled_pipeline(&target, &self.pipeline_layout, false)?,
                equal: create_culled_pipeline(&target, &self.pipeline_layout, true)?,
            });
        }
        self.frames[slot].settings = Some(*settings);
        // What this slot's last frame found hidden, if it was culled, and
        // its GPU time: it completed before this one is prepared.
        let last = &self.frames[slot];
        let gpu_ms = || -> Result<Option<f32>> { Ok(last.queries.gpu_ms()?.map(|ms| ms as f32)) };
        let last = match (last.culled, last.asked_to_cull) {
            (true, _) => LastFrame::Culled {
                hidden: self.occlusion.hidden(slot)?,
                gpu_ms: gpu_ms()?,
            },
            (false, true) => LastFrame::Plain { gpu_ms: gpu_ms()? },
            (false, false) => LastFrame::Unasked,
        };
        self.occlusion.look_from(view.eye_local, last);
        // What the slot's last frame counted, taken in before the choice;
        // timed with it.
        let seen_start = Instant::now();
        let counts = match (settings.path, settings.lod_metric) {
            (RenderPath::Tess | RenderPath::Geomip, LodMetric::Error(tau))
                if settings.error_measure == ErrorMeasure::Sight =>
            {
                Some(CountKey {
                    path: settings.path,
                    tau,
                })
            }
            _ => None,
        };
        self.seen
            .prepare(terrain.grid(), &mut self.frames[slot].seen, view, counts)?;
        let seen_s = seen_start.elapsed().as_secs_f64();
        if let Some(streamer) = self.streamer.as_mut() {
            streamer.prepare(slot, view)?;
        }
        let uniforms = FrameUniforms::new(terrain, view, settings);
        self.frames[slot]
            .uniforms
            .mapped_mut()
            .ok_or(RenderError::NotMapped("uniform memory"))?
            .copy_from_slice(bytemuck::bytes_of(&uniforms));
        self.last_prepared = slot;
        let frame = &mut self.frames[slot];
        frame.tess_batches.clear();
        frame.merged_batches.clear();
        frame.prepared.exact.clear();
        frame.prepared.geomip.clear();
        let prepared = &mut frame.prepared;
        (
            prepared.lod_ms,
            prepared.predicted_max_px,
            prepared.predicted_p99_px,
            prepared.predicted_over_share,
        ) = (None, None, None, None);
        prepared.merged_nodes = 0;
        match (settings.path, settings.lod_metric) {
            (RenderPath::Geomip, _) => {
                if let (Some(geomip), Some(hierarchy)) =
                    (self.geomip.as_mut(), self.hierarchy.as_ref())
                {
                    let start = Instant::now();
                    let frame = &mut self.frames[slot];
                    let prepared = &mut frame.prepared;
                    let choice = geomip.choose(
                        terrain,
                        (hierarchy, self.seen.pixels()),
                        view,
                        settings,
                        (
                            &mut prepared.geomip,
                            &mut frame.planner,
                            &mut frame.geomip_choice,
                        ),
                    );
                    prepared.lod_ms = Some((start.elapsed().as_secs_f64() + seen_s) * 1e3);
                    let planned = matches!(
                        choice,
                        GeomipChoice::Levels {
                            error_lod: true,
                            ..
                        }
                    );
                    if let GeomipChoice::Levels { over_share, .. } = choice {
                        prepared.predicted_over_share = over_share;
                    }
                    let predicted = geomip.emit(
                        terrain,
                        hierarchy,
                        view,
                        settings,
                        (choice, &frame.geomip_choice),
                        &mut prepared.geomip,
                    );
                    prepared.predicted_max_px = predicted.map(|p| p.0);
                    prepared.predicted_p99_px = predicted.and_then(|p| p.1);
                    prepared.patches_in_view = prepared.geomip.len();
                    // Its plan's levels, where its error LOD planned them
                    // (balancing only refines them).
                    if planned {
                        keep_counted_levels(frame, terrain.grid());
                    }
                }
            }
            (RenderPath::Tess, LodMetric::Error(pixels)) => {
                self.prepare_tess_error(slot, terrain, view, settings, pixels)?;
                let prepared = &mut self.frames[slot].prepared;
                prepared.lod_ms = prepared.lod_ms.map(|ms| ms + seen_s * 1e3);
            }
            (RenderPath::Tess, _) => {
                let hierarchy = self
                    .hierarchy
                    .as_ref()
                    .ok_or(RenderError::NotBuilt("the tess path"))?;
                let start = Instant::now();
                let lod_view = view.lod_view(Tau::DEFAULT);
                let in_view = view_patches(terrain, hierarchy, &lod_view, settings.cull);
                let frame = &mut self.frames[slot];
                frame.prepared.lod_ms = Some(start.elapsed().as_secs_f64() * 1e3);
                frame.prepared.patches_in_view = in_view.patches.len();
                let order = DrawOrder::new(terrain.info(), terrain.grid(), view.eye_local);
                // The patches the frustum's boundary crosses are drawn one
                // a draw (`run_batches_apart`).
                frame.tess_batches = run_batches_apart(
                    order.runs(in_view.patches),
                    &in_view.crossing,
                    self.max_patches_per_draw,
                );
            }
            (RenderPath::Brute, _) => {
                self.frames[slot].prepared.patches_in_view = terrain.grid().patch_count()
            }
        }
        let frame = &mut self.frames[slot];
        frame.batch_commands.write_batches(&frame.tess_batches)?;
        let geomip_draws = match settings.path {
            RenderPath::Geomip => frame.prepared.geomip.as_slice(),
            RenderPath::Tess => frame.prepared.exact.as_slice(),
            RenderPath::Brute => &[],
        };
        frame.geomip_list.write(geomip_draws)?;
        // A streamed tile drawn from a coarser page than its level needs
        // is off by up to that page's error besides the level's.
        if let Some(streamer) = &self.streamer {
            let missing = streamer.stats().missing_px;
            let prepared = &mut self.frames[slot].prepared;
            prepared.predicted_max_px = prepared.predicted_max_px.map(|px| px + missing);
        }
        Ok(())
    }

    /// The tess path's error LOD for slot `slot` (see
    /// `TessGeometry::plan_error_frame`).
    fn prepare_tess_error(
        &mut self,
        slot: usize,
        terrain: &Terrain,
        view: &FrameView,
        settings: &RenderSettings,
        pixels: f32,
    ) -> Result<()> {
        let not_built = || RenderError::NotBuilt("the tess path's error LOD");
        let (Some(tess), Some(hierarchy), Some(geomip)) = (
            self.tess.as_mut(),
            self.hierarchy.as_ref(),
            self.geomip.as_ref(),
        ) else {
            return Err(not_built());
        };
        let frame = &mut self.frames[slot];
        let choice = frame.choice.as_mut().ok_or_else(not_built)?;
        let planned = tess.plan_error_frame(
            terrain,
            (hierarchy, self.seen.pixels()),
            geomip,
            (view, settings, pixels),
            (choice, &mut frame.prepared.exact, &mut frame.planner),
            self.max_patches_per_draw,
        )?;
        frame.tess_batches = planned.tess_batches;
        frame.merged_batches = planned.merged_batches;
        keep_counted_levels(frame, terrain.grid());
        let prepared = &mut frame.prepared;
        prepared.lod_ms = Some(planned.lod_ms);
        prepared.predicted_max_px = Some(planned.predicted_max_px);
        prepared.predicted_p99_px = planned.predicted_p99_px;
        prepared.predicted_over_share = planned.predicted_over_share;
        prepared.merged_nodes = planned.merged_nodes;
        prepared.patches_in_view = planned.patches_in_view;
        Ok(())
    }

    /// The pixels each patch showed in earlier frames of the last
    /// prepared frame's view, as its level choice read them (`lod::seen`);
    /// None where no frame of that view has been counted.
    pub fn seen_pixels(&self) -> Option<&SeenPixels> {
        self.seen.pixels()
    }

    /// The largest error the last prepared frame's level choice expects on
    /// screen, in pixels: over the patches in view, each one's error bound
    /// at its level seen from its nearest point (0 where drawn at full
    /// resolution). None for the distance LOD and the brute path.
    pub fn predicted_max_px(&self) -> Option<f32> {
        self.frames[self.last_prepared].prepared.predicted_max_px
    }

    /// The frame's 99th percentile error the last prepared frame's level
    /// choice expects on screen, in pixels, where the view measured it
    /// (`lod::view_measure`): None for the distance LOD, the brute path
    /// and streamed terrains.
    pub fn predicted_p99_px(&self) -> Option<f32> {
        self.frames[self.last_prepared].prepared.predicted_p99_px
    }

    /// The share of the last prepared frame's terrain pixels that the view
    /// model puts over tau at the levels chosen (`lod::plan`): None where
    /// the error LOD did not read the model.
    pub fn predicted_over_share(&self) -> Option<f32> {
        self.frames[self.last_prepared]
            .prepared
            .predicted_over_share
    }

    /// Milliseconds the last prepared frame spent choosing its levels: the
    /// frame plan of the tess path (its frustum walk alone for the distance
    /// and peer policies), the geomip path's levels, the view measure
    /// where it runs. None for the brute path.
    pub fn lod_ms(&self) -> Option<f64> {
        self.frames[self.last_prepared].prepared.lod_ms
    }

    /// How many patches the last prepared frame found in view (all of them
    /// for the brute path): drawn on their own or in merged nodes.
    pub fn patches_in_view(&self) -> usize {
        self.frames[self.last_prepared].prepared.patches_in_view
    }

    /// How many merged nodes (`lod::patch_merge`) the last prepared
    /// frame of the tess path's error LOD draws, each instead of its block
    /// of patches (0 on other paths).
    pub fn merged_nodes(&self) -> usize {
        self.frames[self.last_prepared].prepared.merged_nodes
    }

    /// How many patches in view the last prepared frame of the tess
    /// path's error LOD draws at full resolution, with the reference's
    /// own triangles instead of the control shader (0 on other paths).
    pub fn full_resolution_patches(&self) -> usize {
        self.frames[self.last_prepared].prepared.exact.len()
    }

    /// Makes the geomip path draw every patch at the given level (one per
    /// patch, in patch order), without geomorphing, instead of choosing
    /// levels; `None` goes back to choosing. Levels are balanced first, so
    /// the stitched sides still meet. This is how the benchmark's oracle
    /// draws its per-patch levels.
    pub fn set_geomip_levels(&mut self, terrain: &Terrain, levels: Option<&[u8]>) -> Result<()> {
        self.ensure(terrain, RenderPath::Geomip, false)?;
        let geomip = self
            .geomip
            .as_mut()
            .ok_or(RenderError::NotBuilt("the geomip path"))?;
        let grid = terrain.grid();
        let count = geomip::level_count(grid.cells_per_patch());
        geomip.given = match levels {
            None => None,
            Some(levels) => {
                if levels.len() != grid.patch_count()
                    || levels.iter().any(|&l| usize::from(l) >= count)
                {
                    return Err(RenderError::Unsupported(format!(
                        "{} geomip levels given for {} patches of at most {count} levels",
                        levels.len(),
                        grid.patch_count()
                    )));
                }
                let mut levels = levels.to_vec();
                geomip::balance(&mut levels, grid);
                Some(geomip::PatchLevels {
                    morph: vec![0.0; levels.len()],
                    levels,
                })
            }
        };
        Ok(())
    }
}

/// A frame that counts its pixels keeps the levels its plan drew its
/// patches at (`FramePlan::patch_levels`), which the counts are read
/// against (`lod::seen`).
fn keep_counted_levels(frame: &mut FrameSlot, grid: &PatchGrid) {
    if let Some(levels) = frame.seen.levels_mut() {
        frame.planner.last_plan().patch_levels(grid, levels);
    }
}
