//! What a scene file's parts report when they are refused: the error,
//! and the checker that names the file, line and key. Below the file's
//! parser and the look's, which both use it.

use std::path::{Path, PathBuf};

use toml::Spanned;

/// Why a scene file was refused.
#[derive(Debug, thiserror::Error)]
pub enum SceneFileError {
    #[error("{path}: cannot read the scene: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Syntax errors, unknown keys and wrong types; toml's message carries
    /// the line, column and key.
    #[error("{path}: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("{path}:{line}: {key}: {message}")]
    Invalid {
        path: PathBuf,
        line: usize,
        key: String,
        message: String,
    },
}

/// 1-based line of a byte offset.
pub(super) fn line_of(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

pub(super) struct Checker<'a> {
    pub(super) path: &'a Path,
    pub(super) text: &'a str,
}

impl Checker<'_> {
    pub(super) fn invalid<T>(
        &self,
        key: &str,
        span: std::ops::Range<usize>,
        message: String,
    ) -> Result<T, SceneFileError> {
        Err(SceneFileError::Invalid {
            path: self.path.to_path_buf(),
            line: line_of(self.text, span.start),
            key: key.to_string(),
            message,
        })
    }

    pub(super) fn finite<const N: usize>(
        &self,
        key: &'static str,
        v: &Spanned<[f64; N]>,
    ) -> Result<[f64; N], SceneFileError> {
        let value = *v.get_ref();
        if value.iter().all(|x| x.is_finite()) {
            Ok(value)
        } else {
            self.invalid(key, v.span(), format!("{value:?} must be finite"))
        }
    }
}
