//! The progress bar the long commands show.

/// A progress bar of `len` steps counted in `unit` (rows, frames), with
/// the time taken and left.
pub fn progress_bar(len: u64, unit: &str) -> indicatif::ProgressBar {
    indicatif::ProgressBar::new(len).with_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{{elapsed_precise}} [{{bar:40}}] {{pos}}/{{len}} {unit}, {{eta}} left"
        ))
        .expect("a valid template")
        .progress_chars("=> "),
    )
}
