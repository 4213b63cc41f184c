//! media: what the image-source drivers share (`imagefile`, `opencv`, `mplayer`).
//!
//! - [`still`]: reads PNM (P6/P5/P3, as JDE 4.3's imagefile, plus P2 and 16-bit
//!   maxval) with our own parser, and PNG, JPEG and BMP with the `image` crate, into
//!   a BGR [`Image`](crate::interfaces::Image); bilinear [`still::resize`].
//! - [`child`]: a child process (mplayer, ffmpeg) that writes raw frames to a pipe.
//!   The child gets no terminal (stdin is /dev/null, its own process group so the
//!   shell's Ctrl+C does not reach it), is killed when its handle drops, and is
//!   killed by the kernel if jderobot dies (`PR_SET_PDEATHSIG`), so it never
//!   outlives jderobot. A [`child::Killer`] lets another thread (a driver's
//!   `terminate`) end a child that a reader thread is blocked on.
//! - [`y4m`]: the YUV4MPEG2 stream mplayer's `-vo yuv4mpeg` writes, and 4:2:0 →
//!   BGR conversion (BT.601, limited range, as mplayer and FFmpeg decode).
//! - [`pace`]: frame pacing against absolute deadlines (no drift).
//! - [`stream`]: the worker thread that feeds one image interface from a stream of
//!   frames: works only while the interface is used, paces, repeats, marks the
//!   interface stale with the reason when the source fails, retries.
//! - [`stills`]: the worker that serves still images (loaded on first use,
//!   reloaded on each new use and when the file changes).
//!
//! Compiled only with the internal feature `_media`, which the drivers that use
//! it turn on.

pub mod child;
pub mod pace;
pub mod still;
pub mod stills;
pub mod stream;
pub mod y4m;

use std::path::{Path, PathBuf};

/// What can go wrong reading an image source.
#[derive(Debug, thiserror::Error)]
pub enum MediaError {
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file is not an image, is truncated, or is an image we cannot use.
    #[error("{}: {message}", path.display())]
    Format { path: PathBuf, message: String },
    /// A helper program is not installed.
    #[error(
        "the `{program}` program is not installed (not found on PATH); install the Debian package `{package}`"
    )]
    Missing {
        program: String,
        package: &'static str,
    },
    /// A child process could not start, died, or wrote something unusable.
    #[error("{0}")]
    Child(String),
}

impl MediaError {
    pub(crate) fn format(path: &Path, message: impl Into<String>) -> Self {
        MediaError::Format {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }
}

/// The full path of `program` if it is on `PATH`.
pub fn find_program(program: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|d| d.join(program))
        .find(|p| is_executable(p))
}

fn is_executable(p: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    std::fs::metadata(p).is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
}

/// `program`'s full path, or [`MediaError::Missing`] naming the Debian `package`.
pub fn require_program(program: &str, package: &'static str) -> Result<PathBuf, MediaError> {
    find_program(program).ok_or_else(|| MediaError::Missing {
        program: program.to_string(),
        package,
    })
}

/// Whether a source names a URL (`scheme://...`) rather than a local file.
pub fn is_url(source: &str) -> bool {
    source.split_once("://").is_some_and(|(scheme, _)| {
        !scheme.is_empty()
            && scheme
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '+')
    })
}
