//! Speed against error: the screen-space error measurement, the
//! benchmark's cameras and configurations, and its report; and what the
//! picture's additions cost.

pub mod cameras;
pub mod error;
pub mod look;
pub mod report;
pub mod run;
