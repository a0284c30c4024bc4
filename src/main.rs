use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
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
