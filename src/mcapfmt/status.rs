//! What the recorder exports in the name space (`recorder.status`), read by its
//! shell command and `ps` line and by mastergui's recorder row.

use std::{
    path::PathBuf,
    sync::atomic::{AtomicBool, AtomicU64, Ordering},
    time::Instant,
};

use parking_lot::Mutex;

/// The recorder's state, exported as `recorder.status` (shown by `ps` and
/// `record status`; `record start|stop` set `want`).
#[derive(Default)]
pub struct RecorderStatus {
    /// Whether the shell wants it recording (`record start|stop`).
    pub want: AtomicBool,
    /// Whether a file is open.
    pub recording: AtomicBool,
    /// Messages written to the current file.
    pub messages: AtomicU64,
    /// Samples dropped since the recorder started: the queue was full (the disk
    /// could not keep up) or a sample was replaced before it was polled.
    pub dropped: AtomicU64,
    /// Bytes of the current file so far (complete chunks).
    pub bytes: AtomicU64,
    /// The current (or last) file and when it was opened.
    pub file: Mutex<Option<(PathBuf, Instant)>>,
    /// The last write error, if any.
    pub error: Mutex<Option<String>>,
}

impl RecorderStatus {
    /// One line: `recording FILE: 12.3 s, 456 messages, 7.8 MB, 0 dropped`.
    pub fn line(&self) -> String {
        let file = self.file.lock().clone();
        let recording = self.recording.load(Ordering::Acquire);
        let mut s = match (&file, recording) {
            (Some((p, t)), true) => format!(
                "recording {}: {:.1} s, ",
                p.display(),
                t.elapsed().as_secs_f64()
            ),
            (Some((p, _)), false) => format!("stopped (last file {}): ", p.display()),
            (None, _) => "stopped: ".to_string(),
        };
        s.push_str(&format!(
            "{} messages, {:.1} MB, {} dropped",
            self.messages.load(Ordering::Relaxed),
            self.bytes.load(Ordering::Relaxed) as f64 / 1e6,
            self.dropped.load(Ordering::Relaxed)
        ));
        if let Some(e) = &*self.error.lock() {
            s.push_str(&format!(", ERROR: {e}"));
        }
        s
    }
}
