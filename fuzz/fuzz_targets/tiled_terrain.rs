//! The tiled terrain reader on arbitrary bytes: opening, reading every
//! tile level and querying heights return a value or an error naming the
//! tile, never a panic, and never allocate more than the input implies.
//! Each input is tried as it is and with its checksums made to match, so
//! mutations also reach the checks behind the checksums.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    vkterrain::terrain::tiled::fuzz_open(data);
    vkterrain::terrain::tiled::fuzz_open_resealed(data);
});
