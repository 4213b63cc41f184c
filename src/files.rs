//! The files a conf names (images, worlds, camera and kernel files, `.fzz` fuzzy
//! controllers...): one way to read them and one error type, so every such error
//! reads `file:line: what was wrong` the same way.
//!
//! [`open_checked`] is the one open of a file a conf names (models, materials,
//! worlds, images, calibrations, recordings): it looks at the path before opening
//! it and opens without blocking (a FIFO does not hang it), takes only regular
//! files (a device such as `/dev/zero` or `/dev/urandom`, a FIFO, a socket or a
//! directory is an error that says what the path is) and refuses a file larger
//! than a limit before reading it, every error naming the path.
//! [`read_limited`] (and [`FileError::read`] for text) reads a whole file
//! through it. [`check_regular`] says the same for a path a conf line names.
//! [`shorten`] cuts a word taken from outside (a conf token, a wire line) before
//! an error message echoes it.

use std::{
    borrow::Cow,
    fs::File,
    io::Read,
    os::unix::fs::{FileTypeExt, OpenOptionsExt},
    path::{Path, PathBuf},
};

/// The largest text file we read (worlds, camera, kernel and fuzzy files, confs).
pub const MAX_TEXT_BYTES: u64 = 16 << 20;

/// The largest image file we read (a 67 Mpx binary PPM is 201 MB).
pub const MAX_IMAGE_BYTES: u64 = 256 << 20;

/// The largest 3D model (OBJ) file we read: a robot's model is a few MB; a
/// 1 GB OBJ took minutes and GBs of memory to load (issue 38).
pub const MAX_MODEL_BYTES: u64 = 64 << 20;

/// The most characters of an outside word that an error message echoes.
pub const ECHO_CHARS: usize = 60;

/// A problem reading, parsing or writing a text file.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    #[error("{file}: cannot read: {source}")]
    Io {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Not a regular file: `what` says what it is ("a directory", "a FIFO"...).
    #[error("{file}: is {what}, not a regular file")]
    NotRegular { file: PathBuf, what: &'static str },
    #[error("{file}: is {size} bytes, more than the {max} bytes this reads")]
    TooBig { file: PathBuf, size: u64, max: u64 },
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
    /// Reads a whole text file (at most [`MAX_TEXT_BYTES`]; see [`read_limited`]),
    /// naming it in the error.
    pub fn read(path: &Path) -> Result<String, FileError> {
        let bytes = read_limited(path, MAX_TEXT_BYTES)?;
        String::from_utf8(bytes).map_err(|e| FileError::Io {
            file: path.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::InvalidData, e.utf8_error()),
        })
    }
}

impl FileError {
    /// The message without the file's name (for an error type that names the
    /// file its own way; after "cannot read FILE: ").
    pub fn reason(&self) -> String {
        match self {
            FileError::Io { source, .. } => source.to_string(),
            FileError::NotRegular { what, .. } => format!("is {what}, not a regular file"),
            FileError::TooBig { size, max, .. } => {
                format!("is {size} bytes, more than the {max} bytes this reads")
            }
            FileError::Syntax { line, message, .. } => format!("line {line}: {message}"),
            FileError::Invalid { message, .. } => message.clone(),
        }
    }
}

/// What a file type is, in words, for a path that is not a regular file.
fn kind_of(t: std::fs::FileType) -> &'static str {
    if t.is_dir() {
        "a directory"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_fifo() {
        "a FIFO (named pipe)"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a file"
    }
}

/// Opens the regular file `path` for reading, if it is at most `max` bytes:
/// the one checked open of every file a conf names. Refuses anything that is not
/// a regular file (saying what it is; a device is not even opened: the path is
/// looked at first) or is larger than `max`; opens with `O_NONBLOCK`, so a FIFO
/// put in the file's place between the look and the open cannot hang it (it is
/// then refused too). Returns the file and its size; read at most `max` bytes of
/// it (`take(max)`: a file may grow while read).
pub fn open_checked(path: &Path, max: u64) -> Result<(File, u64), FileError> {
    let io = |source| FileError::Io {
        file: path.to_path_buf(),
        source,
    };
    // Look before opening (opening a device can have effects: a serial port's
    // DTR line), then again at what was opened (the path may have changed).
    if let Ok(m) = std::fs::metadata(path)
        && !m.is_file()
    {
        return Err(FileError::NotRegular {
            file: path.to_path_buf(),
            what: kind_of(m.file_type()),
        });
    }
    let f = File::options()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(io)?;
    let meta = f.metadata().map_err(io)?;
    if !meta.is_file() {
        return Err(FileError::NotRegular {
            file: path.to_path_buf(),
            what: kind_of(meta.file_type()),
        });
    }
    if meta.len() > max {
        return Err(FileError::TooBig {
            file: path.to_path_buf(),
            size: meta.len(),
            max,
        });
    }
    Ok((f, meta.len()))
}

/// Reads the whole of the regular file `path`, at most `max` bytes, through
/// [`open_checked`].
pub fn read_limited(path: &Path, max: u64) -> Result<Vec<u8>, FileError> {
    let (f, len) = open_checked(path, max)?;
    let mut bytes = Vec::with_capacity(len as usize);
    // The file may grow while we read it: never more than `max`.
    f.take(max + 1)
        .read_to_end(&mut bytes)
        .map_err(|source| FileError::Io {
            file: path.to_path_buf(),
            source,
        })?;
    if bytes.len() as u64 > max {
        return Err(FileError::TooBig {
            file: path.to_path_buf(),
            size: bytes.len() as u64,
            max,
        });
    }
    Ok(bytes)
}

/// Ok if `path` is a regular file; otherwise what it is, in words ("does not
/// exist", "is a directory, not a regular file", "is a character device, not a
/// regular file"...), for a message that names the path before it.
pub fn check_regular(path: &Path) -> Result<(), String> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => Ok(()),
        Ok(m) => Err(format!("is {}, not a regular file", kind_of(m.file_type()))),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err("does not exist".into()),
        Err(e) => Err(format!("cannot be read ({e})")),
    }
}

/// `word` as an error message may echo it: at most [`ECHO_CHARS`] characters
/// (cut with `…` and its full length), control characters shown as `?`.
pub fn shorten(word: &str) -> Cow<'_, str> {
    let clean = |c: char| if c.is_control() { '?' } else { c };
    let n = word.chars().count();
    if n <= ECHO_CHARS {
        if word.chars().any(char::is_control) {
            return Cow::Owned(word.chars().map(clean).collect());
        }
        return Cow::Borrowed(word);
    }
    let head: String = word.chars().take(ECHO_CHARS).map(clean).collect();
    Cow::Owned(format!("{head}… ({n} characters)"))
}

/// Words (runs without a space) longer than this in an error message are cut
/// by [`shorten_long_words`]; shorter ones (paths, lists) are kept whole.
pub const LONG_WORD: usize = 256;

/// `text` with each word longer than [`LONG_WORD`] characters cut by
/// [`shorten`]: the last guard before a message that may hold outside input
/// (a conf error) is shown.
pub fn shorten_long_words(text: &str) -> Cow<'_, str> {
    if !text.split(' ').any(|w| w.len() > LONG_WORD) {
        return Cow::Borrowed(text);
    }
    let words: Vec<Cow<'_, str>> = text
        .split(' ')
        .map(|w| {
            if w.chars().count() > LONG_WORD {
                shorten(w)
            } else {
                Cow::Borrowed(w)
            }
        })
        .collect();
    Cow::Owned(words.join(" "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_regular_files_are_read() {
        let e = read_limited(Path::new("/dev/zero"), 10).unwrap_err();
        assert_eq!(
            e.to_string(),
            "/dev/zero: is a character device, not a regular file"
        );
        let e = read_limited(Path::new("/"), 10).unwrap_err();
        assert_eq!(e.to_string(), "/: is a directory, not a regular file");
        assert!(check_regular(Path::new("/nonexistent-x")).unwrap_err() == "does not exist");
        assert!(
            check_regular(Path::new("/dev/urandom"))
                .unwrap_err()
                .contains("device")
        );
    }

    #[test]
    fn size_limit() {
        let d = std::env::temp_dir().join(format!("jde-files-{}", std::process::id()));
        std::fs::write(&d, b"0123456789").unwrap();
        assert_eq!(read_limited(&d, 10).unwrap().len(), 10);
        let e = read_limited(&d, 9).unwrap_err().to_string();
        assert!(
            e.ends_with("is 10 bytes, more than the 9 bytes this reads"),
            "{e}"
        );
        let _ = std::fs::remove_file(&d);
    }

    #[test]
    fn shorten_cuts_long_words() {
        assert_eq!(shorten("abc"), "abc");
        let long = "x".repeat(1 << 20);
        let s = shorten(&long);
        assert!(s.starts_with(&"x".repeat(60)), "{s}");
        assert!(s.ends_with("… (1048576 characters)"), "{s}");
        assert_eq!(shorten("a\nb"), "a?b");
        let msg = format!("bad `{long}`, and /a/path/{}", "p".repeat(200));
        let cut = shorten_long_words(&msg);
        assert!(cut.len() < 400, "{cut}");
        assert!(cut.ends_with(&"p".repeat(200)), "{cut}");
    }
}
