//! Recording a prepared frame into a target: one pass, or two with
//! occlusion culling between them, timed and counted by the slot's
//! queries.

use ash::vk;

use super::{FrameMeasurements, OcclusionMeasurements, TerrainRenderer};
use crate::gpu::commands::{Recorder, RenderingSpan};
use crate::gpu::memory::Buffer;
use crate::gpu::owned::Pipeline;
use crate::gpu::target::TargetViews;
use crate::render::error::{RenderError, Result};
use crate::render::frame::{FrameSlot, COUNTED_PARTS};
use crate::render::geomip_path::GeomipDraw;
use crate::render::occlusion::{ListedDraw, DRAW_COMMAND_BYTES};
use crate::render::settings::{LodMetric, RenderPath, RenderSettings};
use crate::render::tess_path::TessGeometry;
use crate::shader_constants::{
    OCCLUSION_PHASE_ALL, OCCLUSION_PHASE_CULLED, OCCLUSION_PHASE_FIRST, OCCLUSION_PHASE_SECOND,
};

impl TerrainRenderer {
    /// Records the frame `prepare` set slot `slot` up for into `target`
    /// (already in attachment layouts), timed and counted by the slot's
    /// queries: in one pass, or with occlusion culling in two.
    pub fn record(&mut self, rec: &Recorder, slot: usize, target: &TargetViews) -> Result<()> {
        let settings = self.frames[slot].settings.ok_or_else(|| {
            RenderError::Unsupported(format!(
                "frame slot {slot} was recorded before it was prepared"
            ))
        })?;
        if target.samples != self.samples || target.color_format != self.color_format {
            return Err(RenderError::Unsupported(format!(
                "a target of {:?} with {:?} samples per pixel, for a renderer built for {:?} with {:?}",
                target.color_format, target.samples, self.color_format, self.samples
            )));
        }
        // Culling sits out a while after a frame where it found too little
        // hidden, or took longer than without it, and now and then a frame
        // is drawn unculled to time it (`CullingTurns`),
        // unless asked to run every frame or the culled patches are shown.
        let asked = settings.occlusion
            && settings.path != RenderPath::Brute
            && target.depth_readable
            && self.occlusion.can_cull();
        let mut cull = asked
            && (settings.occlusion_every_frame
                || settings.show_culled
                || self.occlusion.takes_turn());
        if cull {
            // Every draw is indirect (the geomip path's patches, the tess
            // path's batches and its full-resolution patches), each pass
            // drawing those that hold a patch the occlusion state keeps.
            // A listed geomip draw keeps its place in the list as its first
            // instance (`GeomipList`).
            let listed = self.frames[slot].geomip_list.listed().is_some();
            let patch_draws = |draws: &[GeomipDraw]| -> Vec<ListedDraw> {
                draws
                    .iter()
                    .enumerate()
                    .map(|(i, d)| ListedDraw {
                        patches: [d.patch, 1],
                        first_index: d.first,
                        index_count: d.count,
                        first_instance: if listed { i as u32 } else { 0 },
                    })
                    .collect()
            };
            let commands: Vec<ListedDraw> = match (settings.path, &self.tess, &self.geomip) {
                (RenderPath::Geomip, _, Some(_)) => patch_draws(&self.frames[slot].prepared.geomip),
                (RenderPath::Tess, Some(_), _) => {
                    // Four indices per patch.
                    let mut list: Vec<ListedDraw> = self.frames[slot]
                        .tess_batches
                        .iter()
                        .map(|&(first, count)| ListedDraw {
                            patches: [first / 4, count / 4],
                            first_index: first,
                            index_count: count,
                            first_instance: 0,
                        })
                        .collect();
                    if matches!(settings.lod_metric, LodMetric::Error(_)) {
                        list.extend(patch_draws(&self.frames[slot].prepared.exact));
                    }
                    list
                }
                _ => Vec::new(),
            };
            // A frame of more draws than the lists hold is drawn in one
            // pass; culling is conservative, so the next frame's first
            // pass may start from an older visible set.
            if commands.len() > self.occlusion.list_capacity() {
                cull = false;
            } else {
                self.occlusion
                    .prepare_target(&self.device, slot, target, &self.sampler)?;
                self.occlusion.write_draws(slot, &commands)?;
            }
        }
        self.frames[slot].culled = cull;
        self.frames[slot].asked_to_cull = asked;
        let frame = &self.frames[slot];
        let clear_color = settings.clear_color;
        frame.queries.reset(rec);
        frame.queries.begin_timing(rec);
        if let Some(streamer) = &self.streamer {
            streamer.record(rec, slot);
        }
        if cull {
            let occlusion = &self.occlusion;
            occlusion.record_start(rec, slot)?;
            rec.begin_rendering(target, RenderingPart::First { clear_color }.span());
            frame.queries.begin_counting(rec, 0);
            self.draw_terrain(rec, slot, &settings, OCCLUSION_PHASE_FIRST)?;
            frame.queries.end_counting(rec, 0);
            rec.end_rendering();
            // The marks come before barriers: lavapipe takes a timestamp
            // when it next flushes, and a barrier flushes.
            frame.queries.mark_span_start(rec);
            occlusion.record_cull(rec, slot, target)?;
            frame.queries.mark_span_end(rec);
            occlusion.record_resume(rec, target);
            rec.begin_rendering(target, RenderingPart::Last.span());
            frame.queries.begin_counting(rec, 1);
            self.draw_terrain(rec, slot, &settings, OCCLUSION_PHASE_SECOND)?;
            frame.queries.end_counting(rec, 1);
            if settings.show_culled {
                self.draw_culled(rec, frame, &settings)?;
            }
        } else {
            rec.begin_rendering(target, RenderingPart::Whole { clear_color }.span());
            frame.queries.begin_counting(rec, 0);
            self.draw_terrain(rec, slot, &settings, OCCLUSION_PHASE_ALL)?;
            frame.queries.end_counting(rec, 0);
        }
        // The sky is timed with the terrain but not counted: the frame's
        // triangle counts stay the terrain's.
        if settings.sky {
            rec.bind_graphics(&self.sky, &self.pipeline_layout, frame.set);
            rec.draw(3);
        }
        frame.queries.end_timing(rec);
        rec.end_rendering();
        if frame.seen.counting() {
            use vk::{AccessFlags2 as A, PipelineStageFlags2 as S};
            rec.memory_barrier(
                (S::FRAGMENT_SHADER, A::SHADER_STORAGE_WRITE),
                (S::HOST, A::HOST_READ),
            );
        }
        // The page loads the frame asked for start once it is recorded,
        // not while it chooses and records (`Streamer::dispatch`).
        if let Some(streamer) = self.streamer.as_mut() {
            streamer.dispatch()?;
        }
        Ok(())
    }

    /// Draws the patches of `phase` (`OCCLUSION_PHASE_*`) by the frame's
    /// path.
    fn draw_terrain(
        &self,
        rec: &Recorder,
        slot: usize,
        settings: &RenderSettings,
        phase: u32,
    ) -> Result<()> {
        let frame = &self.frames[slot];
        let not_built = || {
            RenderError::Unsupported(format!(
                "the {:?} path was not built for this renderer",
                settings.path
            ))
        };
        match settings.path {
            RenderPath::Tess => {
                let tess = self.tess.as_ref().ok_or_else(not_built)?;
                let pipelines = match settings.lod_metric {
                    LodMetric::Error(_) => &tess.error_pipelines,
                    _ => &tess.pipelines,
                };
                let indirect = self.indirect_draws(slot, phase)?;
                let pipeline = pipelines.select(settings.wireframe)?;
                // The full-resolution patches lie nearest the eye: drawn
                // first, they hide what is behind them before it is shaded
                // (see `lod::order`). They are listed after the batches.
                if matches!(settings.lod_metric, LodMetric::Error(_))
                    && !frame.prepared.exact.is_empty()
                {
                    let batches = frame.tess_batches.len() as u64;
                    let exact = indirect.map(|(commands, base)| (commands, base + batches));
                    self.draw_geomip(rec, frame, settings, &frame.prepared.exact, exact)?;
                }
                self.draw_patches(rec, frame, (tess, pipeline), phase, indirect);
                // Merged nodes go in the first pass, untested for occlusion.
                if let (Some(choice), OCCLUSION_PHASE_ALL | OCCLUSION_PHASE_FIRST) =
                    (&frame.choice, phase)
                {
                    if !frame.merged_batches.is_empty() {
                        rec.bind_geometry(&tess.control_points, &choice.merged_indices);
                        for &(first, count) in &frame.merged_batches {
                            rec.draw_indexed(first, count);
                        }
                    }
                }
            }
            RenderPath::Geomip => {
                let indirect = self.indirect_draws(slot, phase)?;
                self.draw_geomip(rec, frame, settings, &frame.prepared.geomip, indirect)?;
            }
            RenderPath::Brute => {
                let brute = self.brute.as_ref().ok_or_else(not_built)?;
                rec.bind_graphics(
                    brute.pipelines.select(settings.wireframe)?,
                    &self.pipeline_layout,
                    frame.set,
                );
                rec.draw(brute.vertex_count);
            }
        }
        Ok(())
    }

    /// The frame's geomip draws `draws` (the geomip path's patches, or the
    /// tess path's full-resolution ones) through the geomip pipeline: in
    /// one indirect call where the frame listed them (`GeomipList`), from
    /// `indirect`'s commands (the occlusion pass's, each draw's instance
    /// count 0 or 1) or the list's own; else one call a draw, each
    /// pushing its constants.
    fn draw_geomip(
        &self,
        rec: &Recorder,
        frame: &FrameSlot,
        settings: &RenderSettings,
        draws: &[GeomipDraw],
        indirect: Option<(&Buffer, u64)>,
    ) -> Result<()> {
        let geomip = self.geomip.as_ref().ok_or_else(|| {
            RenderError::Unsupported("the geomip path was not built for this renderer".into())
        })?;
        geomip.bind(rec, frame.set, settings.wireframe)?;
        match (frame.geomip_list.listed(), indirect) {
            (Some(_), Some((commands, first))) => {
                geomip.push_listed(rec);
                self.draw_commands(rec, commands, first, draws.len() as u32);
            }
            (Some((commands, listed)), None) => {
                geomip.push_listed(rec);
                self.draw_commands(rec, commands, 0, listed);
            }
            (None, indirect) => geomip.draw_own(rec, draws, indirect),
        }
        Ok(())
    }

    /// Where the CPU-listed draws of `phase` read their commands: none for
    /// a frame drawn in one pass.
    fn indirect_draws(&self, slot: usize, phase: u32) -> Result<Option<(&Buffer, u64)>> {
        if phase == OCCLUSION_PHASE_ALL {
            return Ok(None);
        }
        Ok(Some(self.occlusion.draw_commands(slot, phase)?))
    }

    /// The frame's tess patches through `pipeline`, for `phase`, in the
    /// draws of its `tess_batches`; with `indirect`, draw b reads its
    /// instance count from command `first + b` (see `indirect_draws`).
    fn draw_patches(
        &self,
        rec: &Recorder,
        frame: &FrameSlot,
        (tess, pipeline): (&TessGeometry, &Pipeline),
        phase: u32,
        indirect: Option<(&Buffer, u64)>,
    ) {
        rec.bind_graphics(pipeline, &self.pipeline_layout, frame.set);
        rec.push_constants(
            &self.pipeline_layout,
            vk::ShaderStageFlags::TESSELLATION_CONTROL,
            bytemuck::bytes_of(&phase),
        );
        rec.bind_geometry(&tess.control_points, &tess.indices);
        let batches = frame.tess_batches.len() as u32;
        match (indirect, frame.batch_commands.written()) {
            (Some((commands, base)), _) => self.draw_commands(rec, commands, base, batches),
            (None, Some((commands, written))) => self.draw_commands(rec, commands, 0, written),
            (None, None) => {
                for &(first, count) in &frame.tess_batches {
                    rec.draw_indexed(first, count);
                }
            }
        }
    }

    /// Draws `count` consecutive indirect commands of `buffer` from
    /// command `first`: in as few calls as maxDrawIndirectCount allows
    /// where the device has multiDrawIndirect, one call a command
    /// otherwise.
    fn draw_commands(&self, rec: &Recorder, buffer: &Buffer, first: u64, count: u32) {
        let caps = &self.device.caps;
        let per_call = match caps.multi_draw_indirect {
            true => caps.max_draw_indirect_count.max(1),
            false => 1,
        };
        let mut drawn = 0;
        while drawn < count {
            let n = (count - drawn).min(per_call);
            rec.draw_indexed_indirect(buffer, (first + u64::from(drawn)) * DRAW_COMMAND_BYTES, n);
            drawn += n;
        }
    }

    /// The tess path's patches that occlusion culled, in one colour over
    /// the frame (the full-resolution patches of the error LOD, drawn
    /// near the eye, are not shown).
    fn draw_culled(
        &self,
        rec: &Recorder,
        frame: &FrameSlot,
        settings: &RenderSettings,
    ) -> Result<()> {
        let (Some(tess), Some(culled)) = (self.tess.as_ref(), self.culled_pipelines.as_ref())
        else {
            return Ok(());
        };
        if settings.path != RenderPath::Tess {
            return Ok(());
        }
        let pipeline = match settings.lod_metric {
            LodMetric::Error(_) => &culled.equal,
            _ => &culled.fractional,
        };
        self.draw_patches(rec, frame, (tess, pipeline), OCCLUSION_PHASE_CULLED, None);
        Ok(())
    }

    /// What slot `slot`'s last frame measured; call after its fence.
    pub fn measurements(&self, slot: usize) -> Result<FrameMeasurements> {
        let frame = &self.frames[slot];
        let occlusion = match frame.culled {
            true => Some(OcclusionMeasurements {
                patches_occluded: self.occlusion.culled(slot)?,
                found: self.occlusion.hidden(slot)?,
                culling_ms: frame.queries.span_ms()?,
            }),
            false => None,
        };
        let parts = if frame.culled { COUNTED_PARTS } else { 1 };
        Ok(FrameMeasurements {
            gpu_ms: frame.queries.gpu_ms()?,
            statistics: frame.queries.statistics(parts)?,
            occlusion,
        })
    }
}

/// Which part of a frame a rendering is: the whole frame, or, with
/// occlusion culling between them, the first or last of two.
#[derive(Clone, Copy, Debug, PartialEq)]
enum RenderingPart {
    /// The whole frame: cleared to the colour, resolved at its end.
    Whole { clear_color: [f32; 3] },
    /// The first of two: cleared, kept for the last.
    First { clear_color: [f32; 3] },
    /// The last of two: continues the first, resolved at its end.
    Last,
}

impl RenderingPart {
    /// How its rendering starts and ends.
    fn span(self) -> RenderingSpan {
        match self {
            RenderingPart::Whole { clear_color } => RenderingSpan {
                clear_color: Some(clear_color),
                resolve: true,
            },
            RenderingPart::First { clear_color } => RenderingSpan {
                clear_color: Some(clear_color),
                resolve: false,
            },
            RenderingPart::Last => RenderingSpan {
                clear_color: None,
                resolve: true,
            },
        }
    }
}
