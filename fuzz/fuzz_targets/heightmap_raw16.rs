//! The raw16 heightmap loader on arbitrary bytes: it returns a heightmap
//! or an error, never panics, and never allocates past its sample limit.
#![no_main]

use libfuzzer_sys::fuzz_target;
use vkterrain::terrain::HeightmapFormat;

fuzz_target!(|data: &[u8]| {
    vkterrain::terrain::heightmap::fuzz_load(data, HeightmapFormat::Raw16);
});
