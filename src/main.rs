#![forbid(unsafe_code)]

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    // Warnings (validation messages among them) show unless RUST_LOG says
    // otherwise, and so does what the window says about its keys.
    env_logger::Builder::from_env(
        env_logger::Env::default().default_filter_or("warn,vkterrain::app=info"),
    )
    .init();
    let cli = vkterrain::cli::Cli::parse();
    let stdout = std::io::stdout();
    match vkterrain::cli::run(cli, &mut stdout.lock()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            // `{:#}` prints the whole context chain on one line.
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
