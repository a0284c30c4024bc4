//! What a frame looks like apart from the camera: the render path, the LOD
//! metric, shading, and the rest of `RenderSettings`, with the one policy
//! that fits them to what a device can do.

use crate::lod::{PeerLod, PeerPolicy};
use crate::render::error::RenderError;
use crate::scene::{Fog, Lighting, Scene};
use crate::terrain::{DistanceLod, DistanceMode};

/// Which way the terrain is drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RenderPath {
    /// Hardware tessellation.
    #[default]
    Tess,
    /// Geomipmapping with stitched edges and geomorphing.
    Geomip,
    /// The full-resolution mesh.
    Brute,
}

/// What the device lacks changes what is drawn: without tessellation
/// shaders geomip draws the same terrain, without fillModeNonSolid it is
/// drawn filled. Says so in `notes`.
pub fn with_fallback(
    settings: RenderSettings,
    caps: &crate::gpu::Capabilities,
    notes: &mut Vec<String>,
) -> RenderSettings {
    let mut settings = settings;
    if settings.wireframe && !caps.fill_mode_non_solid {
        notes.push(format!(
            "{}: fillModeNonSolid is unavailable, drawing filled instead of wireframe",
            caps.device_name
        ));
        settings.wireframe = false;
    }
    if settings.occlusion && caps.occlusion_sample_counts.is_empty() {
        notes.push(format!(
            "{}: depth attachments cannot be sampled, drawing without occlusion culling",
            caps.device_name
        ));
        settings.occlusion = false;
    }
    if settings.path == RenderPath::Tess && !caps.tessellation_shader {
        notes.push(format!(
            "{}: tessellationShader is unavailable, falling back to the geomip path",
            caps.device_name
        ));
        return RenderSettings {
            path: RenderPath::Geomip,
            ..settings
        };
    }
    settings
}

/// Samples per pixel when none are asked for and the device can draw them.
pub const DEFAULT_SAMPLES: u32 = 4;

/// Samples per pixel for a frame: `requested` when the device can draw
/// it, an error naming what it can draw otherwise; with no request,
/// `DEFAULT_SAMPLES` where the device can draw them and 1 (said in
/// `notes`) where it cannot.
pub fn sample_count(
    requested: Option<u32>,
    caps: &crate::gpu::Capabilities,
    notes: &mut Vec<String>,
) -> crate::render::error::Result<u32> {
    match requested {
        Some(n) if caps.supports_samples(n) => Ok(n),
        Some(n) => Err(RenderError::Unsupported(format!(
            "{} cannot draw {n} samples per pixel (--samples {})",
            caps.device_name,
            caps.sample_count_list()
        ))),
        None if caps.supports_samples(DEFAULT_SAMPLES) => Ok(DEFAULT_SAMPLES),
        None => {
            notes.push(format!(
                "{}: {DEFAULT_SAMPLES} samples per pixel are unavailable (it can draw {}), drawing without anti-aliasing",
                caps.device_name,
                caps.sample_count_list()
            ));
            Ok(1)
        }
    }
}

/// How the fragment shader colours the terrain.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Shading {
    /// Height colours, one directional light plus ambient.
    #[default]
    Lit,
    /// Colour by tessellation factor.
    LodColors,
    /// Constant white, unlit.
    Flat,
}

/// How levels are chosen.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LodMetric {
    /// By distance from the eye (`lod.min_dist` is the first level's range).
    #[default]
    Distance,
    /// By the projected error of each level, at most this many pixels.
    Error(f32),
    /// A peer's policy with its published parameters
    /// (`RenderSettings::peer`): SaschaWillems's screen-space edge spheres,
    /// Dupuy's target edge length, or CDLOD's doubling distance ranges from
    /// `lod.min_dist`. Tess path; geomip draws them by distance.
    Peer(PeerPolicy),
}

/// What the error LOD holds within its tolerance.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum ErrorMeasure {
    /// The frame's 99th percentile error from the terrain's precomputed
    /// view model (`terrain::sight`, `lod::plan`): 1 % of the terrain's
    /// pixels may be over, half of it spent where it saves the most
    /// triangles. Chosen in well under a millisecond. Patches without a
    /// model (the far remainders, a terrain whose heights the CPU does not
    /// hold) keep `Bound`.
    #[default]
    Sight,
    /// The frame's 99th percentile error, as the view sees each level,
    /// measured sample by sample every frame (`lod::view_measure`): the
    /// fewest triangles, at tens of milliseconds to seconds of CPU a
    /// frame. For stills. Terrains whose heights stream use `Bound`.
    View,
    /// Every patch's largest vertical error anywhere, projected face-on
    /// from its nearest point (the error table's bound).
    Bound,
}

/// What a frame looks like, apart from the camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    pub path: RenderPath,
    /// How the geomip path picks levels.
    pub lod_metric: LodMetric,
    /// What the error LOD holds within its tolerance.
    pub error_measure: ErrorMeasure,
    /// Geomip path: glide vertices between levels instead of popping.
    pub geomorph: bool,
    pub lod: DistanceLod,
    pub lod_mode: DistanceMode,
    pub shading: Shading,
    pub wireframe: bool,
    /// The background: the sky's colour at the horizon.
    pub clear_color: [f32; 3],
    /// Draw a sky behind the terrain (a gradient from `clear_color` up,
    /// and the first light's sun); otherwise a flat `clear_color`.
    pub sky: bool,
    /// GPU frustum culling of patches.
    pub cull: bool,
    /// Occlusion culling of patches (tess and geomip paths), where the
    /// device can read depth attachments.
    pub occlusion: bool,
    /// Cull every frame, also the frames after one that found too few
    /// patches hidden, or took longer than a frame drawn without culling,
    /// which otherwise sit culling out a while, and the frames that time
    /// the view unculled (`occlusion::CullingTurns`): for checking culling
    /// itself.
    pub occlusion_every_frame: bool,
    /// Draw the patches occlusion culled over the frame, in one colour
    /// (tess path).
    pub show_culled: bool,
    /// Tess path, error LOD: draw blocks of patches whose every factor is
    /// 1 as one larger patch (`lod::patch_merge`).
    pub merge_patches: bool,
    pub lighting: Lighting,
    pub fog: Option<Fog>,
    /// The peers' published parameters.
    pub peer: PeerLod,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            path: RenderPath::Tess,
            lod_metric: LodMetric::Distance,
            error_measure: ErrorMeasure::Sight,
            geomorph: true,
            lod: DistanceLod::default(),
            lod_mode: DistanceMode::Smooth,
            shading: Shading::Lit,
            wireframe: false,
            clear_color: [0.52, 0.68, 0.86],
            sky: false,
            cull: true,
            occlusion: true,
            occlusion_every_frame: false,
            show_culled: false,
            merge_patches: true,
            lighting: Lighting::default(),
            fog: None,
            peer: PeerLod::default(),
        }
    }
}

impl RenderSettings {
    /// The defaults with a scene's LOD (for its terrain), lights, fog and
    /// sky; with fog, the sky's horizon takes the fog's colour, so distant
    /// ground fades into it.
    pub fn for_scene(scene: &Scene, info: &crate::terrain::TerrainInfo) -> Self {
        let defaults = RenderSettings::default();
        RenderSettings {
            lod: scene.distance_lod(info),
            lod_metric: scene
                .pixel_error
                .map_or(LodMetric::Distance, LodMetric::Error),
            lighting: scene.lighting,
            fog: scene.fog,
            clear_color: scene
                .fog
                .map_or(defaults.clear_color, |f| f.color.to_array()),
            sky: true,
            ..defaults
        }
    }
}

/// What this device cannot measure, filter for `appearance` or draw in one
/// call: notes for the user, beside those of `with_fallback`.
pub fn measurement_notes(
    caps: &crate::gpu::Capabilities,
    appearance: &crate::appearance::Appearance,
) -> Vec<String> {
    let mut notes = Vec::new();
    let name = &caps.device_name;
    if !caps.pipeline_statistics_query {
        notes.push(format!(
            "{name}: pipelineStatisticsQuery is unavailable, so triangle counts are not measured"
        ));
    }
    if caps.timestamp_period_ns.is_none() {
        notes.push(format!(
            "{name}: timestamp queries are unavailable, so GPU time is not measured"
        ));
    }
    if !caps.multi_draw_indirect {
        notes.push(format!(
            "{name}: multiDrawIndirect is unavailable, so each patch batch is its own draw call"
        ));
    } else if !caps.draw_indirect_first_instance {
        notes.push(format!(
            "{name}: drawIndirectFirstInstance is unavailable, so each geomip patch is its own draw call"
        ));
    }
    let with_feature = crate::gpu::Capabilities {
        sampler_anisotropy: true,
        ..caps.clone()
    };
    let asked = appearance.material.as_ref().map(|m| m.anisotropy);
    if let Some(asked) = asked {
        if !caps.sampler_anisotropy
            && super::appearance::anisotropy_for(asked, &with_feature).is_some()
        {
            notes.push(format!(
                "{name}: samplerAnisotropy is unavailable, so textures are filtered without anisotropy"
            ));
        }
    }
    notes
}
