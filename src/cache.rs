//! An on-disk cache for what every launch would otherwise recompute from
//! unchanged inputs: the lightmap bake (about 0.9 s of the default scene's
//! 1.8 s to its first picture on a 2-core machine) and the error LOD's view
//! model (`terrain::sight`, 1.2 s for the default scene). Entries live in the
//! user's cache directory (`$XDG_CACHE_HOME/vkterrain`, else
//! `~/.cache/vkterrain`), never in the repository, each named and checked
//! by a hash of everything its bytes depend on. `VKTERRAIN_CACHE=0` turns
//! the cache off. A missing, unreadable, foreign or corrupt entry is simply
//! computed again: the cache can make a launch faster, never wrong or
//! failed.

use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};

/// Changes whenever what an entry holds, or how it is computed, changes.
const FORMAT: &[u8; 8] = b"VKTC0001";

/// The cache directory, unless the cache is off or there is no home.
pub fn dir() -> Option<PathBuf> {
    if std::env::var("VKTERRAIN_CACHE").as_deref() == Ok("0") {
        return None;
    }
    let base = std::env::var_os("XDG_CACHE_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))?;
    Some(base.join("vkterrain"))
}

/// A hash of `parts`, for naming an entry by its inputs.
pub fn key(parts: impl Hash) -> u64 {
    let mut hasher = std::hash::DefaultHasher::new();
    FORMAT.hash(&mut hasher);
    parts.hash(&mut hasher);
    hasher.finish()
}

/// The `len` bytes stored as `kind` under `key` in `dir`, or, when there
/// are none (or `dir` is None), what `compute` returns, stored for next
/// time. Failing to store only costs the next launch the same work.
pub fn load_or_compute(
    dir: Option<&Path>,
    kind: &str,
    key: u64,
    len: usize,
    compute: impl FnOnce() -> Vec<u8>,
) -> Vec<u8> {
    let Some(dir) = dir else {
        return compute();
    };
    let path = dir.join(format!("{kind}-{key:016x}.bin"));
    if let Some(bytes) = read(&path, key, len) {
        return bytes;
    }
    let bytes = compute();
    if let Err(e) = write(dir, &path, key, &bytes) {
        log::warn!("cache: cannot store {}: {e}", path.display());
    }
    bytes
}

/// The entry's bytes when its header names this format, key and length.
fn read(path: &Path, key: u64, len: usize) -> Option<Vec<u8>> {
    let data = std::fs::read(path).ok()?;
    let (header, body) = data.split_at_checked(24)?;
    let ok = header[..8] == FORMAT[..]
        && header[8..16] == key.to_le_bytes()
        && header[16..24] == (len as u64).to_le_bytes()
        && body.len() == len;
    if !ok {
        log::warn!(
            "cache: {} is not a valid entry; computing again",
            path.display()
        );
        return None;
    }
    Some(body.to_vec())
}

/// Writes a temporary file beside the entry and renames it into place, so
/// a reader never sees half an entry.
fn write(dir: &Path, path: &Path, key: u64, bytes: &[u8]) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    // Unique per process and call: two writers never share a temporary.
    static WRITES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = WRITES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = path.with_extension(format!("tmp{}-{n}", std::process::id()));
    let mut data = Vec::with_capacity(24 + bytes.len());
    data.extend_from_slice(FORMAT);
    data.extend_from_slice(&key.to_le_bytes());
    data.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
    data.extend_from_slice(bytes);
    std::fs::write(&tmp, data)?;
    std::fs::rename(&tmp, path).inspect_err(|_| {
        let _ = std::fs::remove_file(&tmp);
    })
}
