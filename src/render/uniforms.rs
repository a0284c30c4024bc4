//! The per-frame uniform block shared with GLSL (`Frame` in
//! glsl/terrain_common.glsl), std140, with its layout checked at compile time.

use glam::{Vec3, Vec4};

use super::settings::{LodMetric, RenderSettings, Shading};
use super::view::FrameView;
use crate::lod::PeerPolicy;
use crate::scene::MAX_LIGHTS;
use crate::shader_constants::{
    LOD_METRIC_CDLOD, LOD_METRIC_DISTANCE, LOD_METRIC_EDGE_LENGTH, LOD_METRIC_ERROR,
    LOD_METRIC_SPHERE, LOD_MODE_DEBUG, LOD_MODE_SMOOTH, SHADE_FLAT, SHADE_LIT, SHADE_LOD_COLORS,
};
use crate::terrain::{DistanceMode, Terrain};

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct FrameUniforms {
    pub view_proj: [[f32; 4]; 4],
    pub frustum: [[f32; 4]; 6],
    pub eye_local: [f32; 4],
    pub lod: [f32; 4],
    pub grid: [f32; 4],
    pub spacing_size: [f32; 4],
    /// rgb ambient, w: directional light count.
    pub ambient: [f32; 4],
    /// Lowest and highest height.
    pub height_min: f32,
    pub height_max: f32,
    /// 1 when frustum culling is on.
    pub cull: u32,
    pub pad0: u32,
    /// LOD_MODE_*, SHADE_*, cells per patch, LOD_METRIC_*.
    pub lod_mode: u32,
    pub shading: u32,
    pub cells_per_patch: u32,
    pub lod_metric: u32,
    pub error_lod: [f32; 4],
    pub light_dir: [[f32; 4]; MAX_LIGHTS],
    pub light_color: [[f32; 4]; MAX_LIGHTS],
    /// start, 1 / range (0: no fog).
    pub fog: [f32; 4],
    pub fog_color: [f32; 4],
    /// The peers' policies: sphere edge px, sphere factor, edge target px,
    /// CDLOD morph start.
    pub peer: [f32; 4],
    /// Viewport width and height in pixels.
    pub viewport: [f32; 4],
    /// The camera's right vector (unit).
    pub camera_right: [f32; 4],
    /// Inverse of `view_proj`, for the sky's view rays.
    pub sky_ray: [[f32; 4]; 4],
    /// rgb: the sky at the horizon; w: cosine of the sun disc's radius.
    pub sky_horizon: [f32; 4],
    /// rgb: the sky overhead.
    pub sky_zenith: [f32; 4],
}

// Every member of the GLSL frame block at the offset the shader compiler
// gave it, and the block's size, read from the compiled SPIR-V by build.rs.
include!(concat!(env!("OUT_DIR"), "/frame_block.rs"));

/// Angular radius of the sun disc the sky draws, in degrees: about twice
/// the real sun's, so that it reads at screen resolutions.
pub const SUN_RADIUS_DEGREES: f32 = 0.6;

/// The sky overhead for a horizon colour: the same light, deeper and bluer,
/// as clear air scatters it.
pub fn zenith_color(horizon: Vec3) -> Vec3 {
    horizon * Vec3::new(0.55, 0.7, 1.0)
}

impl FrameUniforms {
    pub fn new(terrain: &Terrain, view: &FrameView, settings: &RenderSettings) -> Self {
        let info = terrain.info();
        let (lo, hi) = info.min_max();
        let sp = info.spacing();
        let lighting = &settings.lighting;
        let lights = lighting.active();
        let lod = settings.lod;
        FrameUniforms {
            view_proj: view.view_proj.to_cols_array_2d(),
            frustum: view.frustum.planes.map(|p: Vec4| p.to_array()),
            eye_local: view.eye_local.extend(0.0).to_array(),
            lod: [lod.min_dist, lod.max_dist, lod.min_exp, lod.max_exp],
            grid: [
                info.local_x(0) as f32,
                info.local_z(0) as f32,
                (1.0 / sp.x) as f32,
                (1.0 / sp.y) as f32,
            ],
            spacing_size: [
                sp.x as f32,
                sp.y as f32,
                info.cols() as f32,
                info.rows() as f32,
            ],
            ambient: lighting.ambient.extend(lights.len() as f32).to_array(),
            height_min: lo,
            height_max: hi,
            cull: u32::from(settings.cull),
            pad0: 0,
            lod_mode: match settings.lod_mode {
                DistanceMode::Smooth => LOD_MODE_SMOOTH,
                DistanceMode::Debug => LOD_MODE_DEBUG,
            },
            shading: match settings.shading {
                Shading::Lit => SHADE_LIT,
                Shading::LodColors => SHADE_LOD_COLORS,
                Shading::Flat => SHADE_FLAT,
            },
            cells_per_patch: info.cells_per_patch(),
            lod_metric: match settings.lod_metric {
                LodMetric::Distance => LOD_METRIC_DISTANCE,
                LodMetric::Error(_) => LOD_METRIC_ERROR,
                LodMetric::Peer(PeerPolicy::Sphere) => LOD_METRIC_SPHERE,
                LodMetric::Peer(PeerPolicy::EdgeLength) => LOD_METRIC_EDGE_LENGTH,
                LodMetric::Peer(PeerPolicy::Cdlod) => LOD_METRIC_CDLOD,
            },
            error_lod: [
                match settings.lod_metric {
                    LodMetric::Error(pixels) => pixels,
                    _ => 0.0,
                },
                view.pixels_per_radian,
                terrain.grid().patch_cols() as f32,
                terrain.grid().patch_rows() as f32,
            ],
            light_dir: std::array::from_fn(|i| {
                lights.get(i).map_or([0.0; 4], |l| {
                    l.direction
                        .try_normalize()
                        .unwrap_or(Vec3::Y)
                        .extend(0.0)
                        .to_array()
                })
            }),
            light_color: std::array::from_fn(|i| {
                lights
                    .get(i)
                    .map_or([0.0; 4], |l| l.radiance.extend(0.0).to_array())
            }),
            fog: settings
                .fog
                .map_or([0.0; 4], |f| [f.start, 1.0 / f.range, 0.0, 0.0]),
            fog_color: settings
                .fog
                .map_or([0.0; 4], |f| f.color.extend(1.0).to_array()),
            peer: [
                settings.peer.sphere_edge_px,
                settings.peer.sphere_factor,
                settings.peer.edge_target_px,
                settings.peer.cdlod_morph_start,
            ],
            viewport: [view.viewport.x, view.viewport.y, 0.0, 0.0],
            camera_right: view.right.extend(0.0).to_array(),
            sky_ray: view.view_proj.inverse().to_cols_array_2d(),
            sky_horizon: Vec3::from(settings.clear_color)
                .extend(SUN_RADIUS_DEGREES.to_radians().cos())
                .to_array(),
            sky_zenith: zenith_color(Vec3::from(settings.clear_color))
                .extend(0.0)
                .to_array(),
        }
    }
}
