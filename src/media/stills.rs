//! The worker that serves still images on image interfaces (imagefile, opencv's
//! `image` source).
//!
//! An image is published when someone starts using its interface (clock + 1),
//! read again from its file each time the interface is resumed after a suspend
//! (as 4.3 loaded it on each run), and while used whenever the file changes
//! (checked every 100 ms: edit the image, see it). A file that becomes unreadable
//! keeps the last image and marks the interface stale with the reason.

use std::{
    path::{Path, PathBuf},
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    time::{Duration, SystemTime},
};

use super::{MediaError, still};
use crate::{
    interfaces::{Image, Interface},
    supervisor::Worker,
};

/// How an image file's size maps onto the interface's size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fit {
    /// The file must be this size (colorA..D without `scale`).
    Exact(u32, u32),
    /// Scaled to this size.
    Scale(u32, u32),
    /// The file's own size (varcolor autosize).
    Auto,
}

/// Reads `path` and fits it; `iface` names the interface in errors.
pub fn load_fitted(path: &Path, fit: Fit, iface: &str) -> Result<Image, MediaError> {
    let img = still::load_image(path)?;
    match fit {
        Fit::Auto => Ok(img),
        Fit::Scale(w, h) => Ok(still::resize(&img, w, h)),
        Fit::Exact(w, h) if (img.width, img.height) == (w, h) => Ok(img),
        Fit::Exact(w, h) => Err(MediaError::format(
            path,
            format!(
                "image size mismatch: the file is {}x{}, but {iface} is {w}x{h}; \
                 add `scale` to the provides line, or use a varcolor interface",
                img.width, img.height
            ),
        )),
    }
}

/// One interface served from one file.
pub struct StillSpec {
    pub path: PathBuf,
    pub fit: Fit,
    pub iface: Arc<Interface<Image>>,
    /// The image already read (at load time, to report a bad file at once).
    pub first: Option<Image>,
}

/// A running still-image worker.
pub struct Stills(Worker);

const TICK: Duration = Duration::from_millis(100);

struct Entry {
    spec: StillSpec,
    used: bool,
    mtime: Option<SystemTime>,
    error: Option<String>,
}

fn mtime(p: &Path) -> Option<SystemTime> {
    std::fs::metadata(p).and_then(|m| m.modified()).ok()
}

impl Entry {
    fn publish(&mut self, reload: bool) {
        self.mtime = mtime(&self.spec.path);
        let img = match self.spec.first.take() {
            Some(img) if !reload => Ok(img),
            _ => load_fitted(&self.spec.path, self.spec.fit, self.spec.iface.name()),
        };
        let result = img.and_then(|img| {
            self.spec
                .iface
                .publish(img)
                .map_err(|e| MediaError::Child(e.to_string()))
        });
        match result {
            Ok(_) => self.error = None,
            Err(e) => {
                let why = e.to_string();
                if self.error.as_ref() != Some(&why) {
                    tracing::error!("{}: {why}", self.spec.iface.name());
                }
                self.spec.iface.set_stale(why.clone());
                self.error = Some(why);
            }
        }
    }
}

impl Stills {
    /// Starts the worker for `specs`; `name` names its thread.
    pub fn start(name: &str, specs: Vec<StillSpec>) -> anyhow::Result<Stills> {
        let stop = Arc::new(AtomicBool::new(false));
        let s = stop.clone();
        let mut entries: Vec<Entry> = specs
            .into_iter()
            .map(|spec| Entry {
                spec,
                used: false,
                mtime: None,
                error: None,
            })
            .collect();
        let worker = Worker::start(name, stop, move || {
            while !s.load(Ordering::Acquire) {
                for e in &mut entries {
                    let used = e.spec.iface.users() > 0;
                    if used && !e.used {
                        let reload = e.spec.first.is_none();
                        e.publish(reload);
                    } else if used && mtime(&e.spec.path) != e.mtime {
                        e.publish(true);
                    }
                    e.used = used;
                }
                // Sleep on the first interface, so a resume of it is served at once.
                match entries.first() {
                    Some(e) if !e.used => {
                        e.spec.iface.wait_used(TICK);
                    }
                    _ => std::thread::sleep(TICK),
                }
            }
        })?;
        Ok(Stills(worker))
    }

    pub fn stop(&mut self) {
        self.0.stop();
    }
}
