//! What the vision schemas share: the image they work on (the `image` line; the
//! tuners' panels may switch it among the run's image interfaces), the image they
//! publish (the `output` line), the lines that declare them and the HSV ranges
//! (`hmin` .. `vmax`, `toblack`), and the frame loop: work on a frame when it is new
//! or when the parameters changed, and publish the result.
//!
//! hsvtuner, colortuner, opencvdemo, imagerectifier and extrinsics are each a
//! [`FrameSchema`] over their own [`Work`] (what they do with a frame), on a
//! [`Source`] that the tuners' panels switch (the others' is fixed). hsvtuner and
//! colortuner share more: their state is a [`ColourTuner`] over their ranges
//! ([`RangeFilter`]), made with [`ColourTuner::schema`] and edited by their panels
//! through `ColourTuner::edit`. calibrador and image_viewer take a fixed [`image`].

use std::{
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    time::Duration,
};

use parking_lot::Mutex;

use crate::{
    colorspaces::HsvRange,
    conf::{
        ComponentConf,
        settings::{self, Arg, Setting, float, interface, on_off},
    },
    interfaces::{Image, InUse, Interface, InterfaceError, Interfaces, Sample},
    runtime::{Context, Schema},
};

/// `image INTERFACE`: the image a schema works on.
pub const IMAGE: Setting =
    settings::uses("image", "the image it works on: colorA..D or varcolorA..D").default("colorA");
/// `output INTERFACE`: a new image interface the result is published on.
pub const OUTPUT: Setting = Setting::new(
    "output",
    "publish the result on this new image interface (so `echo NAME` shows it headless)",
    &[interface("INTERFACE")],
);
/// `toblack on|off`: rejected pixels black, or grey.
pub const TOBLACK: Setting = Setting::new(
    "toblack",
    "rejected pixels black (on) or grey (off)",
    &[on_off("SWITCH")],
)
.default("off");

const TAU: f64 = std::f64::consts::TAU;
const HUE: &[Arg] = &[float("H", "radians", 0.0, TAU)];
const SAT: &[Arg] = &[float("S", "", 0.0, 1.0)];
const VAL: &[Arg] = &[float("V", "", 0.0, 255.0)];
/// The group of the HSV range lines, read into a [`HsvRange`] field with
/// [`hsv_lines`].
pub const HSV: &str = "hsv";
/// The HSV range lines as 4.3 wrote them (each schema gives its defaults):
/// hue in radians 0..2π (wrapping through 0 when `hmin > hmax`), saturation
/// 0..1, value 0..255 (V = max(R, G, B)); the group [`HSV`].
pub const HMIN: Setting = Setting::new(
    "hmin",
    "the hue range's start (wraps when hmin > hmax)",
    HUE,
)
.group(HSV);
pub const HMAX: Setting = Setting::new("hmax", "the hue range's end", HUE).group(HSV);
pub const SMIN: Setting = Setting::new("smin", "the saturation range's start", SAT).group(HSV);
pub const SMAX: Setting = Setting::new("smax", "the saturation range's end", SAT).group(HSV);
pub const VMIN: Setting = Setting::new("vmin", "the value range's start", VAL).group(HSV);
pub const VMAX: Setting = Setting::new("vmax", "the value range's end", VAL).group(HSV);

/// Reads the group [`HSV`] (H in radians, as written) into a [`HsvRange`] (H in
/// degrees): `#[serde(deserialize_with = "imagesource::hsv_lines")] hsv: HsvRange`.
pub fn hsv_lines<'de, D: serde::Deserializer<'de>>(d: D) -> Result<HsvRange, D::Error> {
    const KEYS: &[&str] = &["hmin", "hmax", "smin", "smax", "vmin", "vmax"];
    struct Six;
    impl<'de> serde::de::Visitor<'de> for Six {
        type Value = [f32; 6];
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("the lines hmin .. vmax")
        }
        fn visit_map<M: serde::de::MapAccess<'de>>(self, mut m: M) -> Result<[f32; 6], M::Error> {
            let mut v = [f32::NAN; 6];
            while let Some(k) = m.next_key::<String>()? {
                let i = KEYS.iter().position(|x| *x == k);
                let i = i.ok_or_else(|| serde::de::Error::unknown_field(&k, KEYS))?;
                v[i] = m.next_value()?;
            }
            // Every line of the group has a default where it is declared; one left
            // out of a declaration is an error here, not a NaN in the filter.
            match v.iter().position(|x| x.is_nan()) {
                Some(i) => Err(serde::de::Error::missing_field(KEYS[i])),
                None => Ok(v),
            }
        }
    }
    let [hmin, hmax, smin, smax, vmin, vmax] = d.deserialize_struct("HsvRange", KEYS, Six)?;
    Ok(HsvRange::from_radians(hmin, hmax, smin, smax, vmin, vmax))
}

/// An error at the line `key` of `conf`, or (a default value) at its file.
pub fn error_at(conf: &ComponentConf, key: &str, message: impl std::fmt::Display) -> anyhow::Error {
    match conf.line(key) {
        Some(l) => l.error(format!("{key}: {message}")).into(),
        None => anyhow::anyhow!(
            "{}: {} {}: {key} (by default): {message}",
            conf.file.display(),
            conf.kind,
            conf.name
        ),
    }
}

/// The image interface `name` of the line `key` (an error at that line when it is
/// `none`, not provided, or not an image).
pub fn image(
    conf: &ComponentConf,
    ifs: &Interfaces,
    key: &str,
    name: &str,
) -> anyhow::Result<Arc<Interface<Image>>> {
    if name == "none" {
        return Err(error_at(
            conf,
            key,
            "needs an image interface (colorA..D or varcolorA..D), not none",
        ));
    }
    ifs.get::<Image>(name).map_err(|e| match e {
        InterfaceError::WrongType { found, .. } => error_at(
            conf,
            key,
            format!("{name} is a {found} interface, not an image"),
        ),
        e => error_at(conf, key, e),
    })
}

/// The `output` interface, provided by `conf`'s component (`None` or `none`: none).
pub fn output(
    conf: &ComponentConf,
    ifs: &Interfaces,
    name: Option<&str>,
) -> anyhow::Result<Option<Arc<Interface<Image>>>> {
    match name {
        None | Some("none") => Ok(None),
        Some(n) => Ok(Some(
            ifs.provide::<Image>(n, &conf.name)
                .map_err(|e| error_at(conf, "output", e))?,
        )),
    }
}

/// The image a tuner works on; its panel may switch it.
pub struct Source {
    /// The interface in use.
    pub name: Mutex<String>,
    /// Every image interface of the run but the output (the panel's choice).
    pub choices: Vec<String>,
}

impl Source {
    /// The `image` and `output` lines made real: the source (an image interface
    /// that the run provides) and the output, provided.
    pub fn open(
        conf: &ComponentConf,
        ifs: &Interfaces,
        image_name: &str,
        output_name: Option<&str>,
    ) -> anyhow::Result<(Source, Option<Arc<Interface<Image>>>)> {
        let name = image(conf, ifs, "image", image_name)?.name().to_string();
        let output = output(conf, ifs, output_name)?;
        let choices = ifs
            .names_of::<Image>()
            .into_iter()
            .filter(|n| output.as_ref().is_none_or(|o| o.name() != n))
            .collect();
        let source = Source {
            name: Mutex::new(name),
            choices,
        };
        Ok((source, output))
    }

    /// A fixed image (no choice): `name`, already checked.
    pub fn fixed(name: &str) -> Source {
        Source {
            name: Mutex::new(name.to_string()),
            choices: Vec::new(),
        }
    }

    /// A fixed source has no choices (the schema runs it as its child).
    pub fn is_fixed(&self) -> bool {
        self.choices.is_empty()
    }

    /// The panel's source picker (a combo box labelled `image`).
    #[cfg(feature = "gui")]
    pub fn picker(&self, ui: &mut egui::Ui, id: &str) {
        let mut src = self.name.lock().clone();
        egui::ComboBox::new(id, "image")
            .selected_text(&src)
            .show_ui(ui, |ui| {
                for c in &self.choices {
                    ui.selectable_value(&mut src, c.clone(), c);
                }
            });
        *self.name.lock() = src;
    }
}

/// The frame loop: which frame to work on, and where the result goes. `K` is what
/// the result depends on besides the frame (the ranges, the filter ...).
pub struct Frames<K> {
    used: InUse<Image>,
    output: Option<Arc<Interface<Image>>>,
    last: Option<(String, u64, K)>,
}

/// A frame to work on.
pub struct Frame {
    pub sample: Arc<Sample<Image>>,
    /// Frames of the same source published since the last one worked on and never
    /// seen (the schema was slower than the source).
    pub skipped: u64,
}

impl<K: PartialEq> Frames<K> {
    pub fn new(output: Option<Arc<Interface<Image>>>) -> Self {
        Frames {
            used: InUse::default(),
            output,
            last: None,
        }
    }
    /// On run: uses the source (resumes it; a fixed one is the schema's child, the
    /// runtime resumes it) and works on the next frame whatever it is.
    pub fn on_run(&mut self, ifs: &Interfaces, source: &Source) -> Result<(), InterfaceError> {
        if !source.is_fixed() {
            self.used.follow(ifs, &source.name.lock().clone())?;
        }
        self.restart();
        Ok(())
    }
    /// Works on the next frame whatever it is.
    fn restart(&mut self) {
        self.last = None;
    }
    /// Follows the source (the panel may have switched it) and gives its frame if
    /// there is one and it, or `key`, changed since the last.
    pub fn next(
        &mut self,
        ifs: &Interfaces,
        source: &Source,
        key: K,
    ) -> Result<Option<Frame>, InterfaceError> {
        let name = source.name.lock().clone();
        let iface = if source.is_fixed() {
            ifs.get::<Image>(&name)?
        } else {
            self.used.follow(ifs, &name)?
        };
        Ok(self.fresh(&iface, key))
    }
    /// The frame of `iface` if there is one and it, or `key`, changed since the
    /// last.
    fn fresh(&mut self, iface: &Interface<Image>, key: K) -> Option<Frame> {
        let sample = iface.snapshot();
        let key = (iface.name().to_string(), sample.clock, key);
        if sample.clock == 0 || self.last.as_ref() == Some(&key) {
            return None;
        }
        let skipped = match &self.last {
            Some((name, clock, _)) if *name == key.0 => sample.clock.saturating_sub(clock + 1),
            _ => 0,
        };
        self.last = Some(key);
        Some(Frame { sample, skipped })
    }
    /// The key of the last frame worked on.
    pub fn key(&self) -> Option<&K> {
        self.last.as_ref().map(|(_, _, k)| k)
    }
    /// Publishes `image` on the output, if there is one.
    pub fn publish(&self, image: &Image) -> anyhow::Result<()> {
        if let Some(o) = &self.output {
            o.publish(image.clone()).map_err(anyhow::Error::msg)?;
        }
        Ok(())
    }
    /// On stop: stops using the source.
    pub fn release(&mut self) {
        self.used.release();
    }
}

/// What a tuner does with a frame.
pub trait Work: Send + 'static {
    /// What the result depends on besides the frame (the ranges, the filter ...).
    type Key: PartialEq + Send + 'static;
    /// The image worked on (shared with the panel).
    fn source(&self) -> &Source;
    /// The key as it is now.
    fn key(&self) -> Self::Key;
    /// Works on `frame`: keeps the result for the panel and the name space, and
    /// publishes the image through `frames`.
    fn work(
        &mut self,
        frame: &Frame,
        key: &Self::Key,
        frames: &Frames<Self::Key>,
    ) -> anyhow::Result<()>;
}

/// A schema that works on each new frame of its source (and again on the same
/// frame when the parameters change): hsvtuner, colortuner and opencvdemo (the
/// panel switches the source), imagerectifier and extrinsics (a fixed source, run
/// as the schema's child as 4.3 did).
pub struct FrameSchema<W: Work> {
    pub work: W,
    frames: Frames<W::Key>,
    cycle: Duration,
    #[cfg(feature = "gui")]
    panel: Option<Box<dyn crate::runtime::Panel>>,
}

impl<W: Work> FrameSchema<W> {
    pub fn new(work: W, output: Option<Arc<Interface<Image>>>, cycle_ms: u64) -> Self {
        FrameSchema {
            work,
            frames: Frames::new(output),
            cycle: Duration::from_millis(cycle_ms),
            #[cfg(feature = "gui")]
            panel: None,
        }
    }
    /// With its panel.
    #[cfg(feature = "gui")]
    pub fn with_panel(mut self, panel: impl crate::runtime::Panel + 'static) -> Self {
        self.panel = Some(Box::new(panel));
        self
    }
}

impl<W: Work> Schema for FrameSchema<W> {
    fn cycle(&self) -> Duration {
        self.cycle
    }
    fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
        let source = self.work.source();
        if source.is_fixed() {
            ctx.run_children(&[source.name.lock().as_str()], None)?;
        }
        Ok(self.frames.on_run(&ctx.runtime().interfaces, source)?)
    }
    fn iteration(&mut self, ctx: &Context) -> anyhow::Result<()> {
        let key = self.work.key();
        let ifs = &ctx.runtime().interfaces;
        let Some(frame) = self.frames.next(ifs, self.work.source(), key)? else {
            return Ok(());
        };
        let Some(key) = self.frames.key() else {
            return Ok(());
        };
        self.work.work(&frame, key, &self.frames)
    }
    fn on_stop(&mut self, _ctx: &Context) {
        self.frames.release();
    }
    #[cfg(feature = "gui")]
    fn panel(&mut self) -> Option<Box<dyn crate::runtime::Panel>> {
        self.panel.take()
    }
}

/// What a colour tuner computed from a frame.
#[derive(Clone, Debug, Default)]
pub struct Filtered {
    /// The filtered image.
    pub image: Image,
    /// The source image's clock.
    pub clock: u64,
    /// How many pixels passed.
    pub passed: usize,
    /// The image's colours: pixel counts per bin of the tuner's colour plane.
    pub hist: Vec<u32>,
}

/// A colour tuner's ranges.
pub trait RangeFilter: Copy + PartialEq + Send + 'static {
    /// Filters `img`: the image with rejected pixels black (`toblack`) or grey, the
    /// count that passed, and the histogram.
    fn filter(&self, img: &Image, toblack: bool) -> (Image, usize, Vec<u32>);
}

/// The state of a colour tuner (hsvtuner, colortuner), shared by the schema, its
/// panel and the name space.
pub struct ColourTuner<R> {
    pub ranges: Mutex<R>,
    pub toblack: AtomicBool,
    /// The image interface tuned on (the panel may switch it).
    pub source: Source,
    pub result: Mutex<Filtered>,
}

impl<R: RangeFilter> ColourTuner<R> {
    pub fn new(ranges: R, toblack: bool, source: Source) -> Self {
        ColourTuner {
            ranges: Mutex::new(ranges),
            toblack: AtomicBool::new(toblack),
            source,
            result: Mutex::new(Filtered::default()),
        }
    }

    /// A tuner's schema from its lines: the `image` and `output` made real, the
    /// state exported as `state` of `conf`'s component (the panel, if any, takes
    /// the schema's `work`).
    pub fn schema(
        conf: &ComponentConf,
        rt: &crate::runtime::Runtime,
        lines: TunerLines<'_>,
        ranges: R,
    ) -> anyhow::Result<FrameSchema<Arc<Self>>> {
        let (source, output) = Source::open(conf, &rt.interfaces, lines.image, lines.output)?;
        let state = Arc::new(Self::new(ranges, lines.toblack, source));
        rt.names
            .export_arc(&conf.name, "state", state.clone())
            .map_err(anyhow::Error::msg)?;
        Ok(FrameSchema::new(state, output, lines.cycle))
    }
}

/// The lines every colour tuner has: `image`, `output`, `toblack`, `cycle`.
pub struct TunerLines<'a> {
    pub image: &'a str,
    pub output: Option<&'a str>,
    pub toblack: bool,
    pub cycle: u64,
}

#[cfg(feature = "gui")]
impl<R> ColourTuner<R> {
    /// The panel's `toblack` checkbox.
    pub fn toblack_checkbox(&self, ui: &mut egui::Ui) {
        let mut black = self.toblack.load(Ordering::Relaxed);
        if ui.checkbox(&mut black, "toblack").changed() {
            self.toblack.store(black, Ordering::Relaxed);
        }
    }

    /// A panel frame: `ui` edits a copy of the ranges beside the last result, and
    /// the ranges are stored back when it changed them.
    pub fn edit(&self, ui: impl FnOnce(&mut R, &Filtered))
    where
        R: Copy + PartialEq,
    {
        let mut r = *self.ranges.lock();
        let before = r;
        let res = self.result.lock().clone();
        ui(&mut r, &res);
        if r != before {
            *self.ranges.lock() = r;
        }
    }
}

/// A colour tuner filters each frame with its ranges.
impl<R: RangeFilter> Work for Arc<ColourTuner<R>> {
    type Key = (R, bool);
    fn source(&self) -> &Source {
        &self.source
    }
    fn key(&self) -> Self::Key {
        (*self.ranges.lock(), self.toblack.load(Ordering::Relaxed))
    }
    fn work(
        &mut self,
        f: &Frame,
        &(ranges, toblack): &Self::Key,
        out: &Frames<Self::Key>,
    ) -> anyhow::Result<()> {
        let (image, passed, hist) = ranges.filter(&f.sample.value, toblack);
        out.publish(&image)?;
        *self.result.lock() = Filtered {
            image,
            clock: f.sample.clock,
            passed,
            hist,
        };
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_give_each_new_frame_once_and_again_when_the_key_changes() {
        let ifs = Interfaces::default();
        let cam = ifs.provide::<Image>("colorA", "test").unwrap();
        let out = ifs.provide::<Image>("varcolorD", "test").unwrap();
        let source = Source::fixed("colorA");
        let mut frames = Frames::new(Some(out.clone()));
        assert!(
            frames.next(&ifs, &source, 1).unwrap().is_none(),
            "no frame yet"
        );
        cam.publish(Image::new(320, 240)).unwrap();
        let f = frames
            .next(&ifs, &source, 1)
            .unwrap()
            .expect("the first frame");
        assert_eq!((f.sample.clock, f.skipped), (1, 0));
        assert!(frames.next(&ifs, &source, 1).unwrap().is_none(), "seen");
        assert!(frames.next(&ifs, &source, 2).unwrap().is_some(), "new key");
        for _ in 0..3 {
            cam.publish(Image::new(320, 240)).unwrap();
        }
        let f = frames.next(&ifs, &source, 2).unwrap().unwrap();
        assert_eq!((f.sample.clock, f.skipped), (4, 2));
        assert_eq!(frames.key(), Some(&2));
        frames.publish(&f.sample.value).unwrap();
        assert_eq!(out.clock(), 1);
        // A missing source is an error, not a panic.
        let gone = Source::fixed("colorB");
        assert!(frames.next(&ifs, &gone, 2).is_err());
    }
}
