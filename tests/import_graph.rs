//! The import graph between the crate's files has no cycle inside any
//! folder: within a folder, files form layers.
//!
//! A file imports another when it names a path into it (`crate::a::b::X`,
//! `super::b::{X, Y}`, or a child module it declares, `b::X`). A folder's
//! `mod.rs` (or the `x.rs` beside folder `x/`) is the folder's face: a
//! file inside the folder that names it only for what it re-exports from
//! a sibling imports that sibling, not the face; naming something the
//! face itself defines imports the face.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use regex::Regex;

/// One source file: its module path (`terrain::tiled::reader`), its
/// folder, and its text before the tests.
struct SourceFile {
    folder: PathBuf,
    path: PathBuf,
    text: String,
}

fn module_name(src: &Path, file: &Path) -> String {
    let rel = file.strip_prefix(src).unwrap().with_extension("");
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if parts.last().is_some_and(|p| p == "mod") {
        parts.pop();
    }
    parts.join("::")
}

fn collect(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            collect(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The files of the crate rooted at `src`, by module name.
fn source_files(src: &Path) -> BTreeMap<String, SourceFile> {
    let mut paths = Vec::new();
    collect(src, &mut paths);
    paths
        .into_iter()
        .map(|path| {
            let text = std::fs::read_to_string(&path).unwrap();
            let text = text.split("#[cfg(test)]").next().unwrap().to_string();
            let file = SourceFile {
                folder: path.parent().unwrap().to_path_buf(),
                path: path.clone(),
                text,
            };
            (module_name(src, &path), file)
        })
        .collect()
}

/// The folder a face module (`mod.rs`, or `x.rs` beside `x/`) fronts.
fn fronted_folder(file: &SourceFile) -> Option<PathBuf> {
    if file.path.file_name().is_some_and(|n| n == "mod.rs") {
        return Some(file.folder.clone());
    }
    let beside = file.path.with_extension("");
    beside.is_dir().then_some(beside)
}

/// Which modules each module imports.
fn import_edges(files: &BTreeMap<String, SourceFile>) -> BTreeMap<String, BTreeSet<String>> {
    let defines = Regex::new(
        r"(?m)^\s*(?:pub(?:\([a-z]+\))?\s+)?(?:fn|struct|enum|const|static|type|trait|union)\s+(\w+)",
    )
    .unwrap();
    let path_re =
        Regex::new(r"\b((?:crate|super)(?:::(?:super|[a-z_0-9]+))*)::(\{[^}]*\}|\w+)").unwrap();
    let child_re = Regex::new(r"(?m)^\s*(?:pub(?:\([a-z]+\))?\s+)?mod\s+(\w+)\s*;").unwrap();
    let word = Regex::new(r"\w+").unwrap();
    let defined: BTreeMap<&str, BTreeSet<String>> = files
        .iter()
        .map(|(m, f)| {
            let names = defines
                .captures_iter(&f.text)
                .map(|c| c[1].to_string())
                .collect();
            (m.as_str(), names)
        })
        .collect();
    let mut edges = BTreeMap::new();
    for (m, file) in files {
        let mut deps = BTreeSet::new();
        for c in path_re.captures_iter(&file.text) {
            let segments: Vec<&str> = c[1].split("::").collect();
            let mut base: Vec<&str> = if segments[0] == "crate" {
                Vec::new()
            } else {
                let mut b: Vec<&str> = m.split("::").collect();
                b.pop();
                b
            };
            for s in &segments[1..] {
                if *s == "super" {
                    base.pop();
                } else {
                    base.push(s);
                }
            }
            let names: Vec<&str> = word.find_iter(&c[2]).map(|w| w.as_str()).collect();
            let mut full = base;
            if names.len() == 1 {
                full.push(names[0]);
            }
            let Some(k) = (1..=full.len())
                .rev()
                .find(|&k| files.contains_key(&full[..k].join("::")))
            else {
                continue;
            };
            let target = full[..k].join("::");
            if &target == m {
                continue;
            }
            let used: Vec<&str> = if k < full.len() { vec![full[k]] } else { names };
            let face = &files[&target];
            if let Some(fronted) = fronted_folder(face) {
                if file.folder.starts_with(&fronted)
                    && !used.iter().any(|n| defined[target.as_str()].contains(*n))
                {
                    continue;
                }
            }
            deps.insert(target);
        }
        for c in child_re.captures_iter(&file.text) {
            let child = if m.is_empty() {
                c[1].to_string()
            } else {
                format!("{m}::{}", &c[1])
            };
            let uses = Regex::new(&format!(r"(?:^|[^:\w]){}::", &c[1])).unwrap();
            if files.contains_key(&child) && uses.is_match(&file.text) {
                deps.insert(child);
            }
        }
        edges.insert(m.clone(), deps);
    }
    edges
}

/// Pairs of files in one folder that import each other, directly or
/// through other files of that folder.
fn cycles_within_folders(files: &BTreeMap<String, SourceFile>) -> Vec<(String, String)> {
    let edges = import_edges(files);
    let mut found = BTreeSet::new();
    for (a, deps) in &edges {
        for b in deps {
            if files[a].folder != files[b].folder {
                continue;
            }
            let mut stack = vec![b.clone()];
            let mut seen = BTreeSet::from([b.clone()]);
            while let Some(x) = stack.pop() {
                if &x == a {
                    let pair = if a < b { (a, b) } else { (b, a) };
                    found.insert((pair.0.clone(), pair.1.clone()));
                    break;
                }
                for y in &edges[&x] {
                    if files[y].folder == files[a].folder && seen.insert(y.clone()) {
                        stack.push(y.clone());
                    }
                }
            }
        }
    }
    found.into_iter().collect()
}

#[test]
fn no_file_imports_itself_through_its_own_folder() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let files = source_files(&src);
    assert!(files.len() > 80, "{} files", files.len());
    let cycles = cycles_within_folders(&files);
    assert!(
        cycles.is_empty(),
        "files of one folder that import each other: {cycles:?}"
    );
}

/// The check finds what it is for: a face that defines something a child
/// uses while using the child, and two siblings that import each other
/// through a third; a child naming only what the face re-exports is fine.
#[test]
fn the_check_finds_cycles_in_a_made_up_crate() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("src");
    let write = |rel: &str, text: &str| {
        let path = src.join(rel);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    };
    write("lib.rs", "pub mod a;\npub mod b;\n");
    // a/: the face defines HELPER, which child x uses, and uses x.
    write(
        "a/mod.rs",
        "mod x;\npub use x::X;\npub const HELPER: u32 = 1;\nfn f() { x::go(); }\n",
    );
    write(
        "a/x.rs",
        "pub struct X;\npub fn go() { let _ = super::HELPER; }\n",
    );
    // b/: p -> q -> r -> p, and s names only the face's re-export of p.
    write(
        "b/mod.rs",
        "mod p;\nmod q;\nmod r;\nmod s;\npub use p::P;\n",
    );
    write("b/p.rs", "pub struct P;\nfn f() { super::q::go(); }\n");
    write("b/q.rs", "pub fn go() { crate::b::r::go(); }\n");
    write("b/r.rs", "pub fn go() { let _ = super::p::P; }\n");
    write("b/s.rs", "use super::P;\n");
    let cycles = cycles_within_folders(&source_files(&src));
    let pairs: Vec<(&str, &str)> = cycles
        .iter()
        .map(|(a, b)| (a.as_str(), b.as_str()))
        .collect();
    assert_eq!(
        pairs,
        [
            ("a", "a::x"),
            ("b::p", "b::q"),
            ("b::p", "b::r"),
            ("b::q", "b::r"),
        ]
    );
}
