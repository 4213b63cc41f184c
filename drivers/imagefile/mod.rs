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
        settings::{self, Form, choice, path, pixels},
    },
    interfaces::{COLOR_HEIGHT, COLOR_WIDTH, Image, Interface},
    media::{
        still::MAX_PIXELS,
        stills::{Fit, StillSpec, Stills, load_fitted},
    },
    runtime::{Driver, Runtime},
};

/// One `provides` line, parsed.
#[derive(Clone, Debug, PartialEq)]
pub struct Source {
    pub interface: String,
    pub path: std::path::PathBuf,
    pub fit: Fit,
}

crate::declare_lines! {
    /// The driver's lines, declared once (`jderobot help imagefile`).
    struct Lines {
        provides: Vec<Provides> = settings::provides_forms(
            "an image interface and its file",
            &[
                Form::new(
                    "color",
                    "320x240 from FILE (another size is an error unless `scale`: resized to 320x240)",
                    &[
                        settings::COLOR,
                        path("FILE"),
                        choice("scale", &["scale"]).optional(),
                    ],
                ),
                Form::new(
                    "varcolor",
                    "FILE at its own size, or scaled to W x H",
                    &[
                        settings::VARCOLOR,
                        path("FILE"),
                        pixels("W", 16384).optional(),
                        pixels("H", 16384),
                    ],
                ),
            ],
        )
        .required(),
    }
}

#[derive(serde::Deserialize)]
enum Provides {
    #[serde(rename = "color")]
    Color(String, std::path::PathBuf, Option<String>),
    #[serde(rename = "varcolor")]
    Varcolor(String, std::path::PathBuf, Option<u32>, Option<u32>),
}

/// Parses the driver's lines.
pub fn parse(conf: &ComponentConf) -> anyhow::Result<Vec<(Source, ConfLine)>> {
    let lines: Lines = conf.read()?;
    let mut out: Vec<(Source, ConfLine)> = Vec::new();
    for (p, l) in lines.provides.into_iter().zip(conf.provides()) {
        let (interface, path, fit) = match p {
            Provides::Color(i, path, None) => (i, path, Fit::Exact(COLOR_WIDTH, COLOR_HEIGHT)),
            Provides::Color(i, path, Some(_)) => (i, path, Fit::Scale(COLOR_WIDTH, COLOR_HEIGHT)),
            Provides::Varcolor(i, path, Some(w), Some(h)) => {
                if w as u64 * h as u64 > MAX_PIXELS {
                    return Err(l
                        .error(format!(
                            "`provides {i}`: {w}x{h} is too large (at most {MAX_PIXELS} pixels)"
                        ))
                        .into());
                }
                (i, path, Fit::Scale(w, h))
            }
            Provides::Varcolor(i, path, ..) => (i, path, Fit::Auto),
        };
        if out.iter().any(|(s, _)| s.interface == interface) {
            return Err(l.error(format!("`{interface}` is provided twice")).into());
        }
        out.push((
            Source {
                interface,
                path,
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
    lines = Lines
);
