//! The scene parser on arbitrary text: a scene or an error naming the
//! file, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = vkterrain::scene::Scene::from_toml(text, std::path::Path::new("fuzz.toml"));
    }
});
