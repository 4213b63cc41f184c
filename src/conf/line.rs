//! One conf line and the vocabulary every component reads its lines with: numbers
//! with ranges, points, on/off switches, interface names with a robot suffix, files
//! relative to their conf. Every error names `file:line`, the argument and what
//! would be right, so no component writes its own argument checks.

use std::{ops::RangeBounds, path::PathBuf};

use super::{ConfError, Location};
use crate::interfaces;

/// One non-blank, non-comment line, split into words.
#[derive(Clone, Debug)]
pub struct ConfLine {
    pub at: Location,
    pub words: Vec<String>,
}

impl ConfLine {
    /// The first word.
    pub fn keyword(&self) -> &str {
        &self.words[0]
    }
    /// Words after the keyword.
    pub fn args(&self) -> &[String] {
        &self.words[1..]
    }
    /// An error located at this line.
    pub fn error(&self, message: impl Into<String>) -> ConfError {
        ConfError {
            at: self.at.clone(),
            message: message.into(),
        }
    }
    /// Argument `i` (0 = first word after the keyword) parsed as `T`, with an error
    /// that names the line, the argument and what was expected.
    pub fn arg<T: std::str::FromStr>(&self, i: usize, what: &str) -> Result<T, ConfError> {
        let word = self.words.get(i + 1).ok_or_else(|| {
            self.error(format!(
                "`{}` needs {what} as argument {}",
                self.keyword(),
                i + 1
            ))
        })?;
        word.parse().map_err(|_| {
            self.error(format!(
                "`{}`: argument {} is `{}`, expected {what}",
                crate::files::shorten(self.keyword()),
                i + 1,
                crate::files::shorten(word)
            ))
        })
    }
    /// Fails unless the line has between `min` and `max` arguments.
    pub fn expect_args(&self, min: usize, max: usize, usage: &str) -> Result<(), ConfError> {
        let n = self.args().len();
        if n < min || n > max {
            return Err(self.error(format!(
                "`{}` takes {}; usage: {usage}",
                self.keyword(),
                if min == max {
                    format!("{min} argument(s), got {n}")
                } else {
                    format!("{min} to {max} arguments, got {n}")
                }
            )));
        }
        Ok(())
    }
}

/// An image interface named on a line: `colorA..D` (320x240) or `varcolorA..D`
/// (any size).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ImageInterface {
    pub name: String,
    /// `colorA..D`: the size is fixed at 320x240.
    pub fixed_size: bool,
}

/// A number type the vocabulary reads ([`ConfLine::number`]).
pub trait ConfNumber: std::str::FromStr + PartialOrd + Copy + std::fmt::Display {
    /// Whether the value is a usable number (finite for floats).
    fn usable(self) -> bool {
        true
    }
}

macro_rules! conf_number {
    ($($t:ty),*; float $($f:ty),*) => {
        $(impl ConfNumber for $t {})*
        $(impl ConfNumber for $f {
            fn usable(self) -> bool {
                self.is_finite()
            }
        })*
    };
}
conf_number!(u8, u16, u32, u64, usize, i32, i64; float f32, f64);

/// Says a range in words: `between 1 and 100`, `at least 0`, `at most 5`.
fn range_words<T: ConfNumber>(range: &impl RangeBounds<T>) -> String {
    use std::ops::Bound::*;
    match (range.start_bound(), range.end_bound()) {
        (Included(a), Included(b)) => format!("between {a} and {b}"),
        (Included(a), Excluded(b)) => format!("at least {a} and below {b}"),
        (Excluded(a), Included(b)) => format!("above {a} and at most {b}"),
        (Excluded(a), Excluded(b)) => format!("above {a} and below {b}"),
        (Included(a), Unbounded) => format!("at least {a}"),
        (Excluded(a), Unbounded) => format!("above {a}"),
        (Unbounded, Included(b)) => format!("at most {b}"),
        (Unbounded, Excluded(b)) => format!("below {b}"),
        (Unbounded, Unbounded) => "a number".into(),
    }
}

/// The words that switch something on or off (`on`/`off` and 4.3's synonyms).
const ON: [&str; 4] = ["on", "yes", "true", "1"];
const OFF: [&str; 4] = ["off", "no", "false", "0"];

impl ConfLine {
    /// Argument `i` as a word, or an error saying `what` was expected there.
    pub fn word(&self, i: usize, what: &str) -> Result<&str, ConfError> {
        self.words.get(i + 1).map(String::as_str).ok_or_else(|| {
            self.error(format!(
                "`{}` needs {what} as argument {}",
                self.keyword(),
                i + 1
            ))
        })
    }

    /// Argument `i` as a number within `range` (floats must be finite).
    pub fn number<T: ConfNumber>(
        &self,
        i: usize,
        what: &str,
        range: impl RangeBounds<T>,
    ) -> Result<T, ConfError> {
        let v: T = self.arg(i, what)?;
        if !v.usable() || !range.contains(&v) {
            return Err(self.error(format!(
                "`{}`: {what} (argument {}) must be {}, got {v}",
                self.keyword(),
                i + 1,
                range_words(&range)
            )));
        }
        Ok(v)
    }

    /// Argument `i` as a duration in milliseconds within `range` (a `cycle`, `poll`,
    /// or timeout line).
    pub fn millis(
        &self,
        i: usize,
        what: &str,
        range: impl RangeBounds<u64>,
    ) -> Result<std::time::Duration, ConfError> {
        Ok(std::time::Duration::from_millis(
            self.number(i, what, range)?,
        ))
    }

    /// Arguments `i` and `i+1` as an (x, y) point of finite numbers.
    pub fn point(&self, i: usize, what: &str) -> Result<(f64, f64), ConfError> {
        Ok((
            self.number(i, &format!("{what} x"), ..)?,
            self.number(i + 1, &format!("{what} y"), ..)?,
        ))
    }

    /// Argument `i` as a switch: `on`/`off` (also yes/no, true/false, 1/0, and 4.3's
    /// `NAME_on`/`NAME_off` forms such as `repeat_on`).
    pub fn on_off(&self, i: usize, what: &str) -> Result<bool, ConfError> {
        let w = self.word(i, &format!("{what} (on or off)"))?;
        let tail = w.rsplit('_').next().unwrap_or(w);
        if ON.contains(&w) || (w.contains('_') && tail == "on") {
            Ok(true)
        } else if OFF.contains(&w) || (w.contains('_') && tail == "off") {
            Ok(false)
        } else {
            Err(self.error(format!(
                "`{}`: {what} is `{}`, expected on or off",
                self.keyword(),
                crate::files::shorten(w)
            )))
        }
    }

    /// Argument `i` as one of `choices` (returned as written in `choices`).
    pub fn choice<'a>(
        &self,
        i: usize,
        what: &str,
        choices: &[&'a str],
    ) -> Result<&'a str, ConfError> {
        let w = self.word(i, &format!("{what} ({})", choices.join("|")))?;
        choices.iter().find(|c| **c == w).copied().ok_or_else(|| {
            self.error(format!(
                "`{}`: {what} is `{}`, expected one of {}",
                self.keyword(),
                crate::files::shorten(w),
                choices.join(", ")
            ))
        })
    }

    /// Argument `i` as a standard interface name (4.3's aliases accepted, returned
    /// canonical): `laser`, `colorA`, `ptencoders` → `pantiltencoders`.
    pub fn interface(&self, i: usize) -> Result<String, ConfError> {
        let w = self.word(i, "an interface name")?;
        if w.contains('.') || interfaces::family(w).is_none() {
            return Err(self.error(format!(
                "`{}`: `{}` is not an interface; interfaces: {}",
                self.keyword(),
                crate::files::shorten(w),
                interfaces::STANDARD_NAMES.join(", ")
            )));
        }
        Ok(interfaces::canonical(w))
    }

    /// The interface named by argument `i`, for the robot or device named by the
    /// line's last argument when `suffix_at` holds one: `provides laser robot2` →
    /// `laser.robot2` (see [`interfaces::interface_name`]).
    pub fn interface_for(&self, i: usize, suffix_at: Option<usize>) -> Result<String, ConfError> {
        let base = self.interface(i)?;
        let suffix = match suffix_at {
            Some(j) => Some(self.word(j, "a robot name")?),
            None => None,
        };
        Ok(interfaces::interface_name(&base, suffix))
    }

    /// Argument `i` as an image interface (`colorA..D` or `varcolorA..D`), for
    /// `component` whose line reads `usage`.
    pub fn image_interface(
        &self,
        i: usize,
        component: &str,
        usage: &str,
    ) -> Result<ImageInterface, ConfError> {
        let w = self.word(i, "an image interface (colorA..D or varcolorA..D)")?;
        let fixed_size = matches!(w, "colorA" | "colorB" | "colorC" | "colorD");
        let var = matches!(w, "varcolorA" | "varcolorB" | "varcolorC" | "varcolorD");
        if !fixed_size && !var {
            return Err(self.error(format!(
                "{component} provides colorA..D or varcolorA..D, not `{}`; usage: {usage}",
                crate::files::shorten(w)
            )));
        }
        Ok(ImageInterface {
            name: w.to_string(),
            fixed_size,
        })
    }

    /// Argument `i` as a file path, relative to the directory of the conf file this
    /// line is in (absolute paths as they are).
    pub fn path(&self, i: usize, what: &str) -> Result<PathBuf, ConfError> {
        let w = self.word(i, what)?;
        let p = std::path::Path::new(w);
        Ok(if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.at
                .file
                .parent()
                .map(|d| d.join(p))
                .unwrap_or_else(|| p.to_path_buf())
        })
    }

    /// Argument `i` as an existing regular file (see [`path`](Self::path)); a
    /// directory, a device or a FIFO is an error that says what the path is.
    pub fn existing_file(&self, i: usize, what: &str) -> Result<PathBuf, ConfError> {
        let p = self.path(i, what)?;
        if let Err(problem) = crate::files::check_regular(&p) {
            return Err(self.error(format!(
                "`{}`: {what} `{}` {problem} (relative paths are relative to {})",
                self.keyword(),
                crate::files::shorten_long_words(&p.display().to_string()),
                self.at
                    .file
                    .parent()
                    .map(|d| d.display().to_string())
                    .filter(|d| !d.is_empty())
                    .unwrap_or_else(|| ".".into())
            )));
        }
        Ok(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::{path::Path, sync::Arc};

    fn line(text: &str) -> ConfLine {
        ConfLine {
            at: Location {
                file: Arc::from(Path::new("dir/t.conf")),
                line: 7,
            },
            words: text.split_whitespace().map(String::from).collect(),
        }
    }

    #[test]
    fn numbers_with_ranges() {
        let l = line("radius 250 -3 nan x");
        assert_eq!(l.number::<f64>(0, "radius", 0.0..).unwrap(), 250.0);
        let e = l.number::<f64>(1, "radius", 0.0..).unwrap_err().to_string();
        assert_eq!(
            e,
            "dir/t.conf:7: `radius`: radius (argument 2) must be at least 0, got -3"
        );
        assert!(l.number::<f64>(2, "r", ..).is_err());
        let e = l.number::<u32>(3, "count", 1..=10).unwrap_err().to_string();
        assert!(e.contains("argument 4 is `x`, expected count"), "{e}");
        assert!(
            l.number::<u32>(4, "count", 1..=10)
                .unwrap_err()
                .to_string()
                .contains("needs count")
        );
    }

    #[test]
    fn switches_choices_interfaces_paths() {
        let l = line("provides laser robot2 repeat_on off maybe ptmotors file.ppm");
        assert_eq!(l.interface_for(0, Some(1)).unwrap(), "laser.robot2");
        assert!(l.on_off(2, "repeat").unwrap());
        assert!(!l.on_off(3, "x").unwrap());
        assert!(
            l.on_off(4, "x")
                .unwrap_err()
                .to_string()
                .contains("expected on or off")
        );
        assert_eq!(l.interface(5).unwrap(), "pantiltmotors");
        assert!(
            l.interface(1)
                .unwrap_err()
                .to_string()
                .contains("not an interface")
        );
        assert_eq!(l.path(6, "image").unwrap(), Path::new("dir/file.ppm"));
        assert!(
            l.existing_file(6, "image")
                .unwrap_err()
                .to_string()
                .contains("does not exist")
        );
        assert_eq!(l.choice(3, "mode", &["on", "off"]).unwrap(), "off");
    }
}
