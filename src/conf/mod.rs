//! The `jde.conf` loader: the grammar of the JDE 4.3 manual.
//!
//! ```text
//! # a comment (indented comments too)
//! path /usr/local/lib/jderobot        # accepted for compatibility; components are linked in
//! driver simulator                     # a component's own lines, read only by it
//! world assets/worlds/simple.world
//! provides laser
//! end_driver
//! load_driver simulator [own.conf]     # load_service / load_schema / load (any kind)
//! load_schema introrob
//! run introrob                         # synonyms: resume, on
//! show introrob                        # synonyms: guiresume, guion
//! ```
//!
//! A component reads its lines from its section in the main file or, when its load
//! line names a file, from that file (from the file's own section for it if it has
//! one, else every line of the file). Sections may come anywhere in the file, before
//! or after their load line, as in 4.3. Every error carries `file:line` and says what
//! was expected; [`Conf::parse`] reports all problems it finds, not just the first.

use std::{
    fmt,
    path::{Path, PathBuf},
    sync::Arc,
};

mod component;
mod line;
pub mod settings;

pub use component::ComponentConf;
pub use line::{ConfLine, ImageInterface};

/// What a component is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kind {
    Driver,
    Service,
    Schema,
}

impl Kind {
    /// Drivers and services are the same kind of object (as in 4.3): a service may
    /// read a `driver NAME` section and the reverse.
    pub fn same_family(self, other: Kind) -> bool {
        self == other || (self != Kind::Schema && other != Kind::Schema)
    }
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Kind::Driver => "driver",
            Kind::Service => "service",
            Kind::Schema => "schema",
        })
    }
}

/// Where a line came from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Location {
    pub file: Arc<Path>,
    pub line: usize,
}

/// `file:line`, or the file alone for what is about no line of it (a line that
/// is absent, line 0).
impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line == 0 {
            write!(f, "{}", self.file.display())
        } else {
            write!(f, "{}:{}", self.file.display(), self.line)
        }
    }
}

/// One problem in a conf file.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{at}: {}", crate::files::shorten_long_words(.message))]
pub struct ConfError {
    pub at: Location,
    pub message: String,
}

/// Every problem found in a conf file, in file order.
#[derive(Debug, thiserror::Error)]
pub struct ConfErrors(pub Vec<ConfError>);

impl fmt::Display for ConfErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, e) in self.0.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{e}")?;
        }
        Ok(())
    }
}

/// What a directive line asks for.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Action {
    /// `load_driver|load_service|load_schema NAME [file]`; `kind` is `None` for `load`.
    Load {
        kind: Option<Kind>,
        name: String,
        file: Option<PathBuf>,
    },
    /// `run NAME` (and synonyms `resume`, `on`).
    Run(String),
    /// `show NAME` (and synonyms `guiresume`, `guion`).
    Show(String),
}

/// A directive and where it was.
#[derive(Clone, Debug)]
pub struct Directive {
    pub action: Action,
    pub at: Location,
}

/// A `driver|service|schema NAME ... end_*` section.
#[derive(Clone, Debug)]
pub struct Section {
    pub kind: Kind,
    pub name: String,
    pub at: Location,
    pub lines: Vec<ConfLine>,
}

/// A parsed conf file.
#[derive(Clone, Debug)]
pub struct Conf {
    pub file: PathBuf,
    /// The `path` line's directories (kept for compatibility; unused by a static build).
    pub path: Vec<PathBuf>,
    pub sections: Vec<Section>,
    pub directives: Vec<Directive>,
}

/// Splits text into (location, words), dropping blank lines and `#` comments
/// (a `#` starts a comment at the start of a line or after a word).
pub(crate) fn split_lines(file: &Arc<Path>, text: &str) -> Vec<(Location, Vec<String>)> {
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let content = match raw.find('#') {
            Some(pos) => &raw[..pos],
            None => raw,
        };
        let words: Vec<String> = content.split_whitespace().map(str::to_string).collect();
        if !words.is_empty() {
            out.push((
                Location {
                    file: file.clone(),
                    line: i + 1,
                },
                words,
            ));
        }
    }
    out
}

fn section_kind(word: &str) -> Option<(Kind, bool)> {
    Some(match word {
        "driver" => (Kind::Driver, true),
        "service" => (Kind::Service, true),
        "schema" => (Kind::Schema, true),
        "end_driver" => (Kind::Driver, false),
        "end_service" => (Kind::Service, false),
        "end_schema" => (Kind::Schema, false),
        _ => return None,
    })
}

/// Every keyword allowed outside a section, for error messages.
pub const KEYWORDS: &str = "path, driver, service, schema, load_driver, load_service, \
load_schema, load, run (resume, on), show (guiresume, guion)";

impl Conf {
    /// Reads and parses a conf file.
    pub fn load(file: &Path) -> Result<Conf, ConfErrors> {
        let text = crate::files::FileError::read(file).map_err(|e| {
            ConfErrors(vec![ConfError {
                at: Location {
                    file: Arc::from(file),
                    line: 0,
                },
                message: format!("cannot read conf file: {}", e.reason()),
            }])
        })?;
        Conf::parse(&text, file)
    }

    /// Parses conf text; `file` names it in errors and anchors relative paths.
    pub fn parse(text: &str, file: &Path) -> Result<Conf, ConfErrors> {
        let fname: Arc<Path> = Arc::from(file);
        let mut conf = Conf {
            file: file.to_path_buf(),
            path: Vec::new(),
            sections: Vec::new(),
            directives: Vec::new(),
        };
        let mut errors = Vec::new();
        let mut open: Option<Section> = None;
        for (at, words) in split_lines(&fname, text) {
            let line = ConfLine { at, words };
            let kw = line.keyword().to_string();
            if let Some((kind, opening)) = section_kind(&kw) {
                match (&mut open, opening) {
                    (Some(s), true) => errors.push(line.error(format!(
                        "`{kw}` section inside the `{} {}` section opened at line {}; \
                         expected `end_{}` first",
                        s.kind, s.name, s.at.line, s.kind
                    ))),
                    (None, true) => {
                        if line.args().len() != 1 {
                            errors.push(line.error(format!(
                                "`{kw}` must be followed by exactly one name: `{kw} NAME`"
                            )));
                        }
                        open = Some(Section {
                            kind,
                            name: line.args().first().cloned().unwrap_or_default(),
                            at: line.at.clone(),
                            lines: Vec::new(),
                        });
                    }
                    (Some(s), false) if s.kind == kind => {
                        if !line.args().is_empty() {
                            errors.push(line.error(format!(
                                "`{kw}` takes no words after it, got `{}`; put them on a line of their own",
                                settings::echo(&line.args().join(" "))
                            )));
                        }
                        conf.sections.push(open.take().expect("open section"));
                    }
                    (Some(s), false) => errors.push(line.error(format!(
                        "`{kw}` closes a {kind} section, but the open section is `{} {}` \
                         (line {}); expected `end_{}`",
                        s.kind, s.name, s.at.line, s.kind
                    ))),
                    (None, false) => errors
                        .push(line.error(format!("`{kw}` without an open `{kind} NAME` section"))),
                }
                continue;
            }
            if let Some(s) = &mut open {
                s.lines.push(line);
                continue;
            }
            match Conf::directive(file, &line) {
                Ok(Some(d)) => conf.directives.push(d),
                Ok(None) => {
                    conf.path = line
                        .args()
                        .iter()
                        .flat_map(|a| a.split(':'))
                        .map(PathBuf::from)
                        .collect();
                }
                Err(e) => errors.push(e),
            }
        }
        if let Some(s) = open {
            errors.push(ConfError {
                at: s.at.clone(),
                message: format!(
                    "`{} {}` section is never closed; expected `end_{}`",
                    s.kind, s.name, s.kind
                ),
            });
        }
        if errors.is_empty() {
            Ok(conf)
        } else {
            Err(ConfErrors(errors))
        }
    }

    /// One line outside a section: a directive, or `None` for `path`.
    fn directive(file: &Path, line: &ConfLine) -> Result<Option<Directive>, ConfError> {
        let load = |kind: Option<Kind>, usage: &str| -> Result<Action, ConfError> {
            line.expect_args(1, 2, usage)?;
            let file = line.args().get(1).map(|f| {
                let p = Path::new(f);
                if p.is_absolute() {
                    p.to_path_buf()
                } else {
                    file.parent().unwrap_or(Path::new("")).join(p)
                }
            });
            Ok(Action::Load {
                kind,
                name: line.args()[0].clone(),
                file,
            })
        };
        let one = |usage: &str| -> Result<String, ConfError> {
            line.expect_args(1, 1, usage)?;
            Ok(line.args()[0].clone())
        };
        let action = match line.keyword() {
            "path" => {
                line.expect_args(1, 1, "path DIR1:DIR2:...")?;
                return Ok(None);
            }
            "load_driver" => load(Some(Kind::Driver), "load_driver NAME [conf-file]")?,
            "load_service" => load(Some(Kind::Service), "load_service NAME [conf-file]")?,
            "load_schema" => load(Some(Kind::Schema), "load_schema NAME [conf-file]")?,
            "load" => load(None, "load NAME [conf-file]")?,
            "run" | "resume" | "on" => Action::Run(one("run NAME")?),
            "show" | "guiresume" | "guion" => Action::Show(one("show NAME")?),
            other => {
                return Err(line.error(format!(
                    "unknown keyword `{}`; expected one of: {KEYWORDS}",
                    crate::files::shorten(other)
                )));
            }
        };
        Ok(Some(Directive {
            action,
            at: line.at.clone(),
        }))
    }

    /// The section for component `name` of `kind`, if the file has one. A later
    /// section with the same name replaces an earlier one.
    pub fn section(&self, kind: Kind, name: &str) -> Option<&Section> {
        self.sections
            .iter()
            .rev()
            .find(|s| s.name == name && s.kind.same_family(kind))
    }

    /// The lines component `name` gets: from `own_file` if given (its section for the
    /// component there, else the whole file), else from its section in this file.
    pub fn component_conf(
        &self,
        kind: Kind,
        name: &str,
        own_file: Option<&Path>,
    ) -> Result<ComponentConf, ConfErrors> {
        match own_file {
            Some(path) => {
                let text = crate::files::FileError::read(path).map_err(|e| {
                    ConfErrors(vec![ConfError {
                        at: Location {
                            file: Arc::from(path),
                            line: 0,
                        },
                        message: format!(
                            "cannot read the conf file of {kind} `{name}`: {}",
                            e.reason()
                        ),
                    }])
                })?;
                // The component's own file may hold its section, or be all its lines.
                let own = match Conf::parse(&text, path) {
                    Ok(c) => c,
                    Err(_) => Conf {
                        file: path.to_path_buf(),
                        path: Vec::new(),
                        sections: Vec::new(),
                        directives: Vec::new(),
                    },
                };
                if let Some(s) = own.section(kind, name) {
                    return Ok(ComponentConf {
                        kind,
                        name: name.to_string(),
                        file: path.to_path_buf(),
                        lines: s.lines.clone(),
                    });
                }
                let fname: Arc<Path> = Arc::from(path);
                Ok(ComponentConf {
                    kind,
                    name: name.to_string(),
                    file: path.to_path_buf(),
                    lines: split_lines(&fname, &text)
                        .into_iter()
                        .map(|(at, words)| ConfLine { at, words })
                        .filter(|l| section_kind(l.keyword()).is_none())
                        .collect(),
                })
            }
            None => Ok(match self.section(kind, name) {
                Some(s) => ComponentConf {
                    kind,
                    name: name.to_string(),
                    file: self.file.clone(),
                    lines: s.lines.clone(),
                },
                None => ComponentConf::empty(kind, name, &self.file),
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Conf, ConfErrors> {
        Conf::parse(text, Path::new("t.conf"))
    }

    #[test]
    fn sections_and_directives() {
        let c = parse(
            "path /a:/b\n# comment\n  # indented comment\ndriver player\n  provides laser 180 1 # trailing\nend_driver\nload_driver player\nload myschema\nrun myschema\nshow myschema\n",
        )
        .unwrap();
        assert_eq!(c.path, vec![PathBuf::from("/a"), PathBuf::from("/b")]);
        assert_eq!(c.sections.len(), 1);
        assert_eq!(
            c.sections[0].lines[0].words,
            ["provides", "laser", "180", "1"]
        );
        assert_eq!(c.directives.len(), 4);
        assert_eq!(c.directives[3].action, Action::Show("myschema".into()));
    }

    #[test]
    fn errors_name_file_and_line() {
        let e = parse("load_driver a\nfrobnicate x\ndriver b\n").unwrap_err();
        let text = e.to_string();
        assert!(
            text.contains("t.conf:2: unknown keyword `frobnicate`"),
            "{text}"
        );
        assert!(
            text.contains("t.conf:3: `driver b` section is never closed"),
            "{text}"
        );
    }
}
