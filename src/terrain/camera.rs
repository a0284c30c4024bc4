//! Camera maths shared by the CPU and the shaders: view and projection
//! matrices for Vulkan's clip space, frustum planes, and the AABB test.
//!
//! Conventions: right-handed world with y up; the view looks down -z; clip
//! space is Vulkan's (x right, y down, depth 0 at the near plane and 1 at the
//! far plane).

use glam::{Mat4, Vec3, Vec4};

/// A view matrix looking from `eye` towards `target`.
///
/// Stays valid in the cases `Mat4::look_at_rh` breaks down on: when the view
/// direction is parallel to `up` (looking straight down or up) the screen's
/// up becomes -z when looking down and +z when looking up, which is where a
/// camera facing -z ends up when it pitches that far; when `eye == target`
/// (or either is not finite) it looks down -z.
pub fn look_at(eye: Vec3, target: Vec3, up: Vec3) -> Mat4 {
    let forward = (target - eye).try_normalize().unwrap_or(Vec3::NEG_Z);
    let up = up.try_normalize().unwrap_or(Vec3::Y);
    // sin of the angle between forward and up; below this the cross product
    // is too short to give a stable right vector.
    const PARALLEL: f32 = 1e-4;
    let up = if forward.cross(up).length() < PARALLEL {
        if forward.y < 0.0 {
            Vec3::NEG_Z
        } else {
            Vec3::Z
        }
    } else {
        up
    };
    let eye = if eye.is_finite() { eye } else { Vec3::ZERO };
    Mat4::look_to_rh(eye, forward, up)
}

/// Perspective projection into Vulkan clip space: depth 0..1 and y pointing
/// down. `fov_y` is the vertical field of view in radians.
pub fn perspective(fov_y: f32, aspect: f32, near: f32, far: f32) -> Mat4 {
    let mut m = Mat4::perspective_rh(fov_y, aspect, near, far);
    m.y_axis.y = -m.y_axis.y;
    m
}

/// Six normalised planes `(n, d)` with `dot(n, p) + d >= 0` inside, in the
/// order left, right, bottom (clip y = -w), top (clip y = +w), near, far.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frustum {
    pub planes: [Vec4; 6],
}

impl Frustum {
    /// Extracts the planes of a view-projection matrix (column vectors:
    /// clip = M * p). For Vulkan's 0..1 depth the near plane is `z_clip >= 0`
    /// rather than OpenGL's `z_clip >= -w_clip`. A plane that degenerates
    /// (an infinite far plane, say) becomes `(0, 0, 0, 1)`, which culls
    /// nothing.
    pub fn from_view_proj(m: Mat4) -> Frustum {
        let row = |i: usize| Vec4::new(m.x_axis[i], m.y_axis[i], m.z_axis[i], m.w_axis[i]);
        let (r0, r1, r2, r3) = (row(0), row(1), row(2), row(3));
        let planes = [r3 + r0, r3 - r0, r3 + r1, r3 - r1, r2, r3 - r2].map(|p| {
            let len = p.truncate().length();
            if len > f32::MIN_POSITIVE && len.is_finite() {
                p / len
            } else {
                Vec4::W
            }
        });
        Frustum { planes }
    }

    /// True when the box lies entirely outside the frustum. Conservative: a
    /// box near a frustum corner may be kept although it is outside.
    pub fn aabb_outside(&self, center: Vec3, extents: Vec3) -> bool {
        aabb_outside_frustum(center, extents, &self.planes)
    }

    /// True when the box lies entirely inside the frustum: in front of
    /// every plane, so every box within it is too.
    pub fn aabb_inside(&self, center: Vec3, extents: Vec3) -> bool {
        self.planes.iter().all(|&plane| {
            let n = plane.truncate();
            n.dot(center) + plane.w >= extents.dot(n.abs())
        })
    }
}

/// True when the box is entirely in the negative half-space of `plane`:
/// the signed distance of its centre is below minus its projected radius.
/// No branches: the radius comes from the absolute normal.
#[inline]
pub fn aabb_behind_plane(center: Vec3, extents: Vec3, plane: Vec4) -> bool {
    let n = plane.truncate();
    let radius = extents.dot(n.abs());
    let distance = n.dot(center) + plane.w;
    distance + radius < 0.0
}

/// True when the box is behind any of the planes. The per-plane results are
/// combined with `|` rather than an early exit, as the shader does.
#[inline]
pub fn aabb_outside_frustum(center: Vec3, extents: Vec3, planes: &[Vec4; 6]) -> bool {
    planes
        .iter()
        .fold(false, |out, &p| out | aabb_behind_plane(center, extents, p))
}

/// A perspective camera in world coordinates (f64, so it can sit far from
/// the world origin). Everything that reaches the GPU is relative to the eye.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: glam::DVec3,
    pub target: glam::DVec3,
    /// Vertical field of view in degrees.
    pub fov_y_deg: f32,
}

/// Near and far planes that enclose a box of the given half extents around
/// `centre`, seen from `eye`: far reaches the farthest corner, near is a
/// small fraction of it (reversed Z keeps depth precise all the same).
pub fn clip_planes_for_box(eye: glam::DVec3, centre: glam::DVec3, half: glam::DVec3) -> (f32, f32) {
    let mut far = 0.0f64;
    for corner in 0..8 {
        let sign = glam::DVec3::new(
            if corner & 1 == 0 { -1.0 } else { 1.0 },
            if corner & 2 == 0 { -1.0 } else { 1.0 },
            if corner & 4 == 0 { -1.0 } else { 1.0 },
        );
        far = far.max((centre + sign * half - eye).length());
    }
    let far = (far * 1.01).max(1.0);
    let near = (far * 1e-5).max(0.01);
    (near as f32, far as f32)
}

impl Camera {
    /// The view's rotation only: the eye is the origin of camera-relative
    /// coordinates.
    pub fn relative_view(&self) -> Mat4 {
        let dir = (self.target - self.eye).as_vec3();
        look_at(Vec3::ZERO, dir, Vec3::Y)
    }

    /// Projection times the rotation-only view, with reversed Z: depth 1 at
    /// `near`, 0 at `far`.
    pub fn relative_view_proj(&self, aspect: f32, near: f32, far: f32) -> Mat4 {
        let fov = self.fov_y_deg.to_radians();
        perspective_reversed(fov, aspect, near, far) * self.relative_view()
    }
}

/// Perspective projection into Vulkan clip space with reversed Z: depth 1 at
/// `near` and 0 at `far`, y pointing down. Floating-point depth then has
/// nearly even relative precision over the whole range.
pub fn perspective_reversed(fov_y: f32, aspect: f32, near: f32, far: f32) -> Mat4 {
    perspective(fov_y, aspect, far, near)
}
