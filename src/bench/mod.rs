//! Speed against error: the screen-space error measurement, the
//! benchmark's cameras and configurations, and its report.

pub mod cameras;
pub mod error;
pub mod report;
pub mod run;
