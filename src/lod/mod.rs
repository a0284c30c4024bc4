//! The level choice: which level each part of the terrain is drawn at, for
//! one view. Pure Rust, no GPU types.
//!
//! - [`factors`]: the tessellation-factor formulas the control shader
//!   mirrors (distance, error-bounded, the peers' policies).
//! - [`geomip`]: geomipmapping's levels, stitching and morphing.
//! - [`geomip_choice`]: the geomip path's levels for one view, by distance
//!   or by the error plan, in buffers kept from frame to frame.
//! - [`view`]: what a frame's choice sees: eye, frustum, pixels per radian,
//!   tau.
//! - [`hierarchy`]: the node quadtree over the patch grid, built once per
//!   terrain, with each node's bounds and largest errors.
//! - [`plan`]: the real-time error LOD: a frame plan walked down the
//!   hierarchy, levels from the bound and the terrain's view model, in a
//!   fraction of a millisecond whatever the terrain's size.
//! - [`horizon`]: ground nearer ground hides, estimated from the plan's
//!   boxes, for frames without counts.
//! - [`seen`]: the pixels each patch showed in earlier frames of a view,
//!   which the plan reads so as not to refine hidden ground.
//! - [`order`]: front-to-back draw order of the chosen patches.
//! - [`buffers`]: a choice's buffers, made ready before its first frame.
//! - [`patch_merge`]: merged nodes, blocks of flat patches drawn as one.
//! - [`view_measure`] and [`viewshed`]: the error a view sees, measured
//!   sample by sample (`--error-measure view`, for offline stills).

pub mod buffers;
pub mod factors;
pub mod geomip;
pub mod geomip_choice;
pub mod hierarchy;
pub mod horizon;
pub mod order;
pub mod patch_merge;
pub mod plan;
pub mod seen;
pub mod view;
pub mod view_measure;
pub mod viewshed;

pub use factors::*;
