//! The camera's view of one frame: camera-relative matrices, frustum
//! planes, the projection scale the LOD uses, and CPU frustum culling.

use glam::{DVec3, Mat4, Vec3, Vec4};

use crate::lod::ScreenParams;
use crate::terrain::camera::{clip_planes_for_box, Camera, Frustum};
use crate::terrain::Terrain;

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

    /// What the level choice needs of this view, with the error LOD's
    /// tolerance `tau`.
    pub fn lod_view(&self, tau: crate::lod::view::Tau) -> crate::lod::view::LodView {
        crate::lod::view::LodView {
            eye_local: self.eye_local,
            pixels_per_radian: self.pixels_per_radian,
            frustum: self.frustum,
            viewport: self.viewport,
            tau,
        }
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
