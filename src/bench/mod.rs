//! Speed against error: measuring the screen-space error of a render
//! against the brute reference.

pub mod error;
