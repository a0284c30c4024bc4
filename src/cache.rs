//! An on-disk cache for what every launch would otherwise recompute from
//! unchanged inputs: the lightmap bake (about 0.9 s of the default scene's
//! 1.8 s to its first picture on a 2-core machine) and the error LOD's view
//! model (`terrain::sight`, 2 s for the default scene). Entries live in the
//! user's cache directory (`$XDG_CACHE_HOME/vkterrain`, else
//! `~/.cache/vkterrain`), never in the repository, each named and checked
//! by a hash of everything its bytes depend on. `VKTERRAIN_CACHE=0` turns
//! the cache off. A missing, unreadable, foreign or corrupt entry is simply
//! computed again: the cache can make a launch faster, never wrong or
//! failed.
//!
//! Entries of other inputs or older formats are never read again, so the
//! directory is kept within `MAX_BYTES`: after each store, the entries used
//! longest ago (by modification time, which a read renews) are removed
//! until the rest fit.

use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};

/// Changes whenever what an entry holds, or how it is computed, changes.
const FORMAT: &[u8; 8] = b"VKTC0001";

/// The most the cache directory's entries may hold together: the view
/// models of a 4097^2 terrain (111 MB) and of a dozen smaller ones, with
/// room to spare.
pub const MAX_BYTES: u64 = 2 << 30;

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
    let path = entry_path(dir, kind, key);
    if let Some(bytes) = read(&path, key, len) {
        // Used now: the last to be removed.
        let renewed = std::fs::File::options()
            .write(true)
            .open(&path)
            .and_then(|f| f.set_modified(std::time::SystemTime::now()));
        if let Err(e) = renewed {
            log::debug!("cache: cannot renew {}: {e}", path.display());
        }
        return bytes;
    }
    let bytes = compute();
    match write(dir, &path, key, &bytes) {
        Ok(()) => prune(dir, MAX_BYTES, &path),
        Err(e) => log::warn!("cache: cannot store {}: {e}", path.display()),
    }
    bytes
}

/// Where `kind`'s entry for `key` lives in `dir`.
fn entry_path(dir: &Path, kind: &str, key: u64) -> PathBuf {
    dir.join(format!("{kind}-{key:016x}.bin"))
}

/// Whether `name` is an entry's file name (`entry_path`):
/// `{kind}-{16 hex digits}.bin`.
fn is_entry(name: &str) -> bool {
    let Some(stem) = name.strip_suffix(".bin") else {
        return false;
    };
    stem.rsplit_once('-').is_some_and(|(kind, hash)| {
        !kind.is_empty() && hash.len() == 16 && hash.bytes().all(|b| b.is_ascii_hexdigit())
    })
}

/// Removes the entries of `dir` used longest ago until the rest hold at
/// most `max_bytes`, never `keep` (the entry just stored). Files that are
/// not entries are left alone; what cannot be read or removed is skipped.
fn prune(dir: &Path, max_bytes: u64, keep: &Path) {
    let Ok(listing) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<(std::time::SystemTime, u64, PathBuf)> = listing
        .flatten()
        .filter(|e| e.file_name().to_str().is_some_and(is_entry))
        .filter_map(|e| {
            let meta = e.metadata().ok().filter(std::fs::Metadata::is_file)?;
            Some((meta.modified().ok()?, meta.len(), e.path()))
        })
        .collect();
    let mut total: u64 = entries.iter().map(|(_, len, _)| len).sum();
    entries.sort();
    for (_, len, path) in entries {
        if total <= max_bytes {
            break;
        }
        if path == keep {
            continue;
        }
        match std::fs::remove_file(&path) {
            Ok(()) => total -= len,
            Err(e) => log::debug!("cache: cannot remove {}: {e}", path.display()),
        }
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Stores `n` bytes as `kind` under `key` in `dir`, its modification
    /// time `age` seconds ago.
    fn entry(dir: &Path, kind: &str, key: u64, n: usize, age: u64) -> PathBuf {
        let path = entry_path(dir, kind, key);
        write(dir, &path, key, &vec![7u8; n]).unwrap();
        let when = std::time::SystemTime::now() - std::time::Duration::from_secs(age);
        std::fs::File::options()
            .write(true)
            .open(&path)
            .unwrap()
            .set_modified(when)
            .unwrap();
        path
    }

    #[test]
    fn entry_names_are_kind_dash_sixteen_hex_digits() {
        assert!(is_entry("sight-0123456789abcdef.bin"));
        assert!(is_entry("light-map-0123456789ABCDEF.bin"));
        for name in [
            "sight-0123456789abcde.bin",
            "-0123456789abcdef.bin",
            "sight-0123456789abcdeg.bin",
            "sight-0123456789abcdef.tmp12-0",
            "notes.txt",
        ] {
            assert!(!is_entry(name), "{name}");
        }
    }

    #[test]
    fn pruning_removes_the_entries_used_longest_ago_until_the_rest_fit() {
        let dir = tempfile::tempdir().unwrap();
        let dir = dir.path();
        // Four entries of 1,024 bytes (1,048 with their headers), the
        // oldest first, and a file that is not an entry.
        let paths: Vec<PathBuf> = (0..4)
            .map(|i| entry(dir, "sight", i, 1024, 400 - 100 * i))
            .collect();
        std::fs::write(dir.join("notes.txt"), vec![1u8; 5000]).unwrap();
        // Room for two: the two oldest go.
        prune(dir, 2 * 1048, &paths[3]);
        let left: Vec<bool> = paths.iter().map(|p| p.exists()).collect();
        assert_eq!(left, [false, false, true, true]);
        assert!(dir.join("notes.txt").exists(), "not an entry: left alone");
        // The entry just stored stays even when it alone is too large.
        prune(dir, 10, &paths[2]);
        let left: Vec<bool> = paths.iter().map(|p| p.exists()).collect();
        assert_eq!(left, [false, false, true, false]);
    }

    #[test]
    fn a_read_renews_an_entry_so_it_outlives_older_ones() {
        let dir = tempfile::tempdir().unwrap();
        let dir = dir.path();
        let old = entry(dir, "sight", 1, 100, 1000);
        let newer = entry(dir, "sight", 2, 100, 10);
        let got = load_or_compute(Some(dir), "sight", 1, 100, || unreachable!("cached"));
        assert_eq!(got, vec![7u8; 100]);
        // Stored now, with room for two of the three: the one read is kept.
        let stored = entry_path(dir, "lightmap", 3);
        write(dir, &stored, 3, &[1u8; 100]).unwrap();
        prune(dir, 2 * 124, &stored);
        assert!(old.exists() && stored.exists() && !newer.exists());
    }
}
