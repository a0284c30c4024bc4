//! The view measure (`lod::view_measure`) as a frame asks for it.

use super::settings::{ErrorMeasure, RenderSettings};
use super::view::FrameView;
use crate::lod::view_measure::{view_error_table, Diagonal, ViewErrors, ViewLod};
use crate::terrain::{ErrorTable, Terrain};

/// The error table `bound` as `view` sees it for the patches `drawn`
/// (`lod::view_measure`), where `settings` measure the view and the CPU
/// holds the heights; None keeps the bounds (a streamed terrain's too),
/// with no expectation to report.
pub(super) fn seen_errors(
    terrain: &Terrain,
    bound: &ErrorTable,
    diagonal: Diagonal,
    view: &FrameView,
    (settings, pixel_error): (&RenderSettings, f32),
    drawn: &[bool],
) -> Option<ViewErrors> {
    if settings.error_measure != ErrorMeasure::View {
        return None;
    }
    let heightmap = terrain.info().heightmap()?;
    Some(view_error_table(
        terrain,
        heightmap,
        bound,
        diagonal,
        &ViewLod {
            eye_local: view.eye_local,
            pixels_per_radian: view.pixels_per_radian,
            viewport_pixels: f64::from(view.viewport.x) * f64::from(view.viewport.y),
            frustum: view.frustum,
            pixel_error,
        },
        drawn,
    ))
}
