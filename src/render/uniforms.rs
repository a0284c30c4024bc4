//! The per-frame uniform block shared with GLSL (`Frame` in
//! glsl/terrain_common.glsl), std140, with its layout checked at compile time.

use std::mem::{offset_of, size_of};

use glam::{DVec3, Mat4, Vec3, Vec4};

use super::renderer::RenderPath;
use crate::scene::{Fog, Lighting, Scene, MAX_LIGHTS};
use crate::shader_constants::{
    LOD_METRIC_CDLOD, LOD_METRIC_DISTANCE, LOD_METRIC_EDGE_LENGTH, LOD_METRIC_ERROR,
    LOD_METRIC_SPHERE, LOD_MODE_DEBUG, LOD_MODE_SMOOTH, SHADE_FLAT, SHADE_LIT, SHADE_LOD_COLORS,
};
use crate::terrain::camera::{clip_planes_for_box, Camera, Frustum};
use crate::terrain::lod::{PeerLod, PeerPolicy, ScreenParams};
use crate::terrain::{DistanceLod, DistanceMode, Terrain};

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
    pub height_range: [f32; 4],
    pub modes: [u32; 4],
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
}

// std140: mat4 at 0, vec4[6] at 64, then one vec4 per field.
const _: () = assert!(size_of::<FrameUniforms>() == 464);
const _: () = assert!(offset_of!(FrameUniforms, frustum) == 64);
const _: () = assert!(offset_of!(FrameUniforms, eye_local) == 160);
const _: () = assert!(offset_of!(FrameUniforms, lod) == 176);
const _: () = assert!(offset_of!(FrameUniforms, grid) == 192);
const _: () = assert!(offset_of!(FrameUniforms, spacing_size) == 208);
const _: () = assert!(offset_of!(FrameUniforms, ambient) == 224);
const _: () = assert!(offset_of!(FrameUniforms, height_range) == 240);
const _: () = assert!(offset_of!(FrameUniforms, modes) == 256);
const _: () = assert!(offset_of!(FrameUniforms, light_dir) == 288);
const _: () = assert!(offset_of!(FrameUniforms, light_color) == 336);
const _: () = assert!(offset_of!(FrameUniforms, fog) == 384);
const _: () = assert!(offset_of!(FrameUniforms, fog_color) == 400);
const _: () = assert!(offset_of!(FrameUniforms, error_lod) == 272);
const _: () = assert!(offset_of!(FrameUniforms, peer) == 416);
const _: () = assert!(offset_of!(FrameUniforms, viewport) == 432);
const _: () = assert!(offset_of!(FrameUniforms, camera_right) == 448);

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

/// What a frame looks like, apart from the camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    pub path: RenderPath,
    /// How the geomip path picks levels.
    pub lod_metric: LodMetric,
    /// Geomip path: glide vertices between levels instead of popping.
    pub geomorph: bool,
    pub lod: DistanceLod,
    pub lod_mode: DistanceMode,
    pub shading: Shading,
    pub wireframe: bool,
    pub clear_color: [f32; 3],
    /// GPU frustum culling of patches.
    pub cull: bool,
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
            geomorph: true,
            lod: DistanceLod::default(),
            lod_mode: DistanceMode::Smooth,
            shading: Shading::Lit,
            wireframe: false,
            clear_color: [0.52, 0.68, 0.86],
            cull: true,
            lighting: Lighting::default(),
            fog: None,
            peer: PeerLod::default(),
        }
    }
}

impl RenderSettings {
    /// The defaults with a scene's LOD (for its terrain), lights and fog; with fog, the sky
    /// behind the terrain takes the fog's colour, so distant ground fades
    /// into it.
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
            ..defaults
        }
    }
}

/// The matrices and planes of one frame, camera-relative.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameView {
    pub view_proj: Mat4,
    pub frustum: Frustum,
    /// The eye relative to the terrain's centre.
    pub eye_local: Vec3,
    /// Viewport height over 2 tan(fov / 2): a length L at distance d seen
    /// face-on covers L * pixels_per_radian / d pixels.
    pub pixels_per_radian: f32,
    pub near: f32,
    pub far: f32,
    /// The camera's right vector.
    pub right: Vec3,
    /// Width and height in pixels.
    pub viewport: glam::Vec2,
}

impl FrameView {
    /// Near and far enclose the whole terrain, from its Y bounds.
    /// For a viewport of `width` x `height` pixels.
    pub fn new(terrain: &Terrain, camera: &Camera, width: u32, height: u32) -> Self {
        let aspect = width.max(1) as f32 / height.max(1) as f32;
        let info = terrain.info();
        let origin = info.origin();
        let (lo, hi) = terrain
            .y_bounds()
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), b| {
                (lo.min(b[0]), hi.max(b[1]))
            });
        let centre = DVec3::new(origin.x, 0.5 * f64::from(lo + hi), origin.y);
        let half = DVec3::new(
            0.5 * info.world_width(),
            0.5 * f64::from(hi - lo),
            0.5 * info.world_depth(),
        );
        let (near, far) = clip_planes_for_box(camera.eye, centre, half);
        let view_proj = camera.relative_view_proj(aspect, near, far);
        // f64 subtraction first: the eye and the origin may both be far out.
        let eye_local = DVec3::new(
            camera.eye.x - origin.x,
            camera.eye.y,
            camera.eye.z - origin.y,
        )
        .as_vec3();
        // Projection y scale is 1 / tan(fov / 2); the view is a pure
        // rotation, so it is the length of the matrix's second row.
        let row1 = Vec3::new(view_proj.x_axis.y, view_proj.y_axis.y, view_proj.z_axis.y);
        let view = camera.relative_view();
        let right = Vec3::new(view.x_axis.x, view.y_axis.x, view.z_axis.x);
        FrameView {
            right,
            viewport: glam::Vec2::new(width.max(1) as f32, height.max(1) as f32),
            pixels_per_radian: 0.5 * height.max(1) as f32 * row1.length(),
            view_proj,
            frustum: Frustum::from_view_proj(view_proj),
            eye_local,
            near,
            far,
        }
    }

    /// This view with another view's frustum, re-expressed relative to this
    /// view's eye: culling stays where it was while the camera moves on.
    pub fn with_frustum_of(&self, frozen: &FrameView) -> FrameView {
        let shift = self.eye_local - frozen.eye_local;
        let planes = frozen
            .frustum
            .planes
            .map(|p| Vec4::new(p.x, p.y, p.z, p.w + p.truncate().dot(shift)));
        FrameView {
            frustum: Frustum { planes },
            ..*self
        }
    }

    /// Whether patch `p`'s box is not outside the frustum: the CPU's
    /// version of the test the control shader makes.
    pub fn patch_in_frustum(&self, terrain: &Terrain, p: usize) -> bool {
        let (centre, extents) = terrain.patch_aabb(terrain.grid().patch_id(p));
        !self.frustum.aabb_outside(centre - self.eye_local, extents)
    }

    /// Patches whose box is not outside the frustum.
    pub fn patches_in_frustum(&self, terrain: &Terrain) -> usize {
        (0..terrain.grid().patch_count())
            .filter(|&p| self.patch_in_frustum(terrain, p))
            .count()
    }

    /// Per patch, whether it is drawn this frame: culling off, or
    /// `patch_in_frustum`.
    pub fn patches_drawn(&self, terrain: &Terrain, cull: bool) -> Vec<bool> {
        (0..terrain.grid().patch_count())
            .map(|p| !cull || self.patch_in_frustum(terrain, p))
            .collect()
    }

    /// What the screen-space peers need of the camera.
    pub fn screen(&self) -> ScreenParams {
        ScreenParams {
            view_proj: self.view_proj,
            right: self.right,
            viewport: self.viewport,
            pixels_per_radian: self.pixels_per_radian,
        }
    }
}

impl FrameUniforms {
    pub fn new(terrain: &Terrain, view: &FrameView, settings: &RenderSettings) -> Self {
        let info = terrain.info();
        let (lo, hi) = info.heightmap().min_max();
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
            height_range: [lo, hi, if settings.cull { 1.0 } else { 0.0 }, 0.0],
            modes: [
                match settings.lod_mode {
                    DistanceMode::Smooth => LOD_MODE_SMOOTH,
                    DistanceMode::Debug => LOD_MODE_DEBUG,
                },
                match settings.shading {
                    Shading::Lit => SHADE_LIT,
                    Shading::LodColors => SHADE_LOD_COLORS,
                    Shading::Flat => SHADE_FLAT,
                },
                info.cells_per_patch(),
                match settings.lod_metric {
                    LodMetric::Distance => LOD_METRIC_DISTANCE,
                    LodMetric::Error(_) => LOD_METRIC_ERROR,
                    LodMetric::Peer(PeerPolicy::Sphere) => LOD_METRIC_SPHERE,
                    LodMetric::Peer(PeerPolicy::EdgeLength) => LOD_METRIC_EDGE_LENGTH,
                    LodMetric::Peer(PeerPolicy::Cdlod) => LOD_METRIC_CDLOD,
                },
            ],
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
        }
    }
}
