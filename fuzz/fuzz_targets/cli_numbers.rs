//! Every numeric argument parser of the command line on arbitrary text,
//! and whole command lines through clap: a value or an error, never a
//! panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        vkterrain::cli::fuzz_parse(text);
    }
});
