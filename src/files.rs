//! Errors of the line-based text files the libraries read and write (camera and world
//! files, kernel files, `.fzz` fuzzy controllers): one type, so every such error reads
//! `file:line: what was wrong` the same way.

use std::path::{Path, PathBuf};

/// A problem reading, parsing or writing a text file.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    #[error("{file}: cannot read: {source}")]
    Io {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}:{line}: {message}")]
    Syntax {
        file: PathBuf,
        line: usize,
        message: String,
    },
    /// The file parsed but does not describe something usable (no rules, no kernel...).
    #[error("{file}: {message}")]
    Invalid { file: PathBuf, message: String },
}

impl FileError {
    /// Reads a whole file, naming it in the error.
    pub fn read(path: &Path) -> Result<String, FileError> {
        std::fs::read_to_string(path).map_err(|source| FileError::Io {
            file: path.to_path_buf(),
            source,
        })
    }
}
