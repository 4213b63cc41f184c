//! imagefile: images from files, as JDE 4.3's imagefile driver.
//!
//! Reads PNM as 4.3 did (binary `P6`; also `P5`, `P3`, `P2`, comments anywhere in
//! the header, 16-bit samples) and, beyond it, PNG, JPEG and BMP (the `image`
//! crate). No system package needed.
//!
//! # Conf
//! ```text
//! driver imagefile
//! provides colorA casaleft.pnm          # 320x240 BGR; another size is an error...
//! provides colorB photo.jpg scale       # ...unless `scale`: resized to 320x240
//! provides varcolorA casaleft.pnm 500 400   # any size: the file scaled to W x H
//! provides varcolorB atardecer.ppm      # no size: the file's own size (autosize)
//! end_driver
//! load_driver imagefile
//! ```
//! Relative paths are relative to the conf file the lines are in.
//!
//! # Interfaces
//! `colorA..D` (320x240) and `varcolorA..D` (any size): BGR bytes, rows top to
//! bottom. An image is published (clock + 1) when someone starts using the
//! interface, read again each time it is resumed, and while it is used whenever
//! the file changes; otherwise the driver does nothing.
//!
//! # Errors
//! Each file is read when the driver loads: a missing, truncated or non-image
//! file, or a colorX file that is not 320x240 (4.3 shut down with "image size
//! mismatch"), stops the load with an error naming the conf line and the file.
//! If a file goes bad later, the interface keeps its last image and is marked
//! stale with the reason (`ps`, `echo`, mastergui show it).

use std::sync::Arc;

use anyhow::Context as _;

use crate::{
    conf::{
        ComponentConf, ConfLine,
        settings::{self, Setting},
    },
    interfaces::{COLOR_HEIGHT, COLOR_WIDTH, Image, Interface},
    media::{
        still::MAX_PIXELS,
        stills::{Fit, StillSpec, Stills, load_fitted},
    },
    runtime::{Driver, Runtime},
};

const USAGE: &str = "provides colorA..D FILE [scale], provides varcolorA..D FILE [W H]";

/// One `provides` line, parsed.
#[derive(Clone, Debug, PartialEq)]
pub struct Source {
    pub interface: String,
    pub path: std::path::PathBuf,
    pub fit: Fit,
}

/// Parses a `W H` pair of image dimensions (1..=16384 each).
pub fn size(l: &ConfLine, i: usize) -> Result<(u32, u32), crate::conf::ConfError> {
    let w: u32 = l.arg(i, "a width W in pixels")?;
    let h: u32 = l.arg(i + 1, "a height H in pixels")?;
    if !(1..=16384).contains(&w) || !(1..=16384).contains(&h) || (w as u64 * h as u64) > MAX_PIXELS
    {
        return Err(l.error(format!(
            "`{}`: {w}x{h} is not an image size (1..16384 pixels each)",
            l.keyword()
        )));
    }
    Ok((w, h))
}

/// The driver's lines, declared once (`jderobot help imagefile`).
const LINES: &[Setting] = &[settings::provides(USAGE).required()];

/// Parses the driver's lines.
pub fn parse(conf: &ComponentConf) -> anyhow::Result<Vec<(Source, ConfLine)>> {
    conf.check(LINES)?;
    let mut out: Vec<(Source, ConfLine)> = Vec::new();
    for l in &conf.lines {
        let image = l.image_interface(0, "imagefile", USAGE)?;
        let (iface, color) = (image.name.as_str(), image.fixed_size);
        let fit = if color {
            l.expect_args(2, 3, &format!("provides {iface} FILE [scale]"))?;
            match l.args().get(2).map(String::as_str) {
                None => Fit::Exact(COLOR_WIDTH, COLOR_HEIGHT),
                Some("scale") => Fit::Scale(COLOR_WIDTH, COLOR_HEIGHT),
                Some(w) => {
                    return Err(l
                        .error(format!("`provides {iface}`: `{w}` is not `scale`; colorA..D are 320x240 (use varcolor for other sizes)"))
                        .into());
                }
            }
        } else {
            if l.args().len() != 2 && l.args().len() != 4 {
                l.expect_args(2, 4, &format!("provides {iface} FILE [W H]"))?;
                return Err(l
                    .error(format!("`provides {iface}` takes FILE and an optional size W H; usage: provides {iface} FILE [W H]"))
                    .into());
            }
            if l.args().len() == 4 {
                let (w, h) = size(l, 2)?;
                Fit::Scale(w, h)
            } else {
                Fit::Auto
            }
        };
        if out.iter().any(|(s, _)| s.interface == iface) {
            return Err(l.error(format!("`{iface}` is provided twice")).into());
        }
        out.push((
            Source {
                interface: iface.to_string(),
                path: conf.resolve(&l.args()[1]),
                fit,
            },
            l.clone(),
        ));
    }
    Ok(out)
}

struct ImageFile {
    stills: Stills,
}

impl Driver for ImageFile {
    fn terminate(&mut self) {
        self.stills.stop();
    }
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let sources = parse(conf)?;
    let mut specs = Vec::new();
    for (s, line) in sources {
        let img =
            load_fitted(&s.path, s.fit, &s.interface).map_err(|e| line.error(e.to_string()))?;
        let iface: Arc<Interface<Image>> = rt.interfaces.provide_value(
            &s.interface,
            &conf.name,
            Image::new(img.width, img.height),
        )?;
        specs.push(StillSpec {
            path: s.path,
            fit: s.fit,
            iface,
            first: Some(img),
        });
    }
    let stills = Stills::start("imagefile", specs).context("cannot start the imagefile thread")?;
    Ok(Box::new(ImageFile { stills }))
}

crate::register_driver!(
    Driver,
    "imagefile",
    "images from PNM (4.3), PNG, JPEG and BMP files on colorA..D / varcolorA..D",
    create,
    lines = LINES
);
