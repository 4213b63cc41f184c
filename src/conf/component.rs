//! The lines one component gets (its section or its own file), with lookups by
//! keyword and typed single-value reads.

use std::{
    path::{Path, PathBuf},
    sync::Arc,
};

use super::{ConfError, ConfErrors, ConfLine, Kind, split_lines};

/// The lines a component gets: its section or its own file.
#[derive(Clone, Debug)]
pub struct ComponentConf {
    pub kind: Kind,
    pub name: String,
    /// The file these lines came from (main conf or the component's own file).
    pub file: PathBuf,
    pub lines: Vec<ConfLine>,
}

impl ComponentConf {
    /// A conf with no lines (a component loaded with no section).
    pub fn empty(kind: Kind, name: &str, file: &Path) -> Self {
        ComponentConf {
            kind,
            name: name.to_string(),
            file: file.to_path_buf(),
            lines: Vec::new(),
        }
    }

    /// Builds a conf from text, as if it were the body of the component's section.
    /// Handy for tests and for components created from code.
    pub fn from_text(kind: Kind, name: &str, text: &str) -> Result<Self, ConfErrors> {
        let file: Arc<Path> = Arc::from(Path::new("<inline>"));
        let lines = split_lines(&file, text)
            .into_iter()
            .map(|(at, words)| ConfLine { at, words })
            .collect();
        Ok(ComponentConf {
            kind,
            name: name.to_string(),
            file: file.to_path_buf(),
            lines,
        })
    }

    /// Lines whose keyword is `key`.
    pub fn lines_with<'a>(&'a self, key: &'a str) -> impl Iterator<Item = &'a ConfLine> + 'a {
        self.lines.iter().filter(move |l| l.keyword() == key)
    }

    /// The last line with keyword `key`, if any (later lines override earlier ones).
    pub fn line<'a>(&'a self, key: &'a str) -> Option<&'a ConfLine> {
        self.lines_with(key).last()
    }

    /// `provides NAME ...` lines.
    pub fn provides(&self) -> impl Iterator<Item = &ConfLine> {
        self.lines_with("provides")
    }

    /// A single-valued `key VALUE` line parsed as `T`, or `default` when absent.
    pub fn value_or<T: std::str::FromStr>(
        &self,
        key: &str,
        what: &str,
        default: T,
    ) -> Result<T, ConfError> {
        match self.line(key) {
            Some(l) => {
                l.expect_args(1, 1, &format!("{key} <{what}>"))?;
                l.arg(0, what)
            }
            None => Ok(default),
        }
    }

    /// A path value resolved relative to the directory of the file it came from.
    pub fn resolve(&self, path: &str) -> PathBuf {
        let p = Path::new(path);
        if p.is_absolute() {
            return p.to_path_buf();
        }
        self.file
            .parent()
            .map(|d| d.join(p))
            .unwrap_or_else(|| p.to_path_buf())
    }

    /// An error for a line the component does not understand.
    pub fn unknown(&self, line: &ConfLine, expected: &str) -> ConfError {
        line.error(format!(
            "{} {}: I don't know what to do with `{}`; expected {expected}",
            self.kind,
            self.name,
            line.words
                .iter()
                .map(|w| crate::files::shorten(w))
                .collect::<Vec<_>>()
                .join(" ")
        ))
    }
}
