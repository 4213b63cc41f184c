//! simulated3D: synthetic camera images of a 3D wireframe world, as JDE 4.3.1's
//! `simulated3D` driver.
//!
//! The world is a set of 3D segments (4.3's world file, the one extrinsics reads);
//! each camera is a progeo pinhole camera (4.3's camera file). Every 33 ms the
//! driver renders each camera someone uses: white background, the world's lines
//! in black, projected with [`crate::progeo`] (`project`, `displayline`, optical
//! to graphic coordinates). No system package needed.
//!
//! # Conf (the seed's lines)
//! ```text
//! driver simulated3D
//! worldfile ../assets/simulated3D/robotics-lab.world
//! provides colorA ../assets/simulated3D/cameraA     # the camera file must say 320x240
//! provides varcolorB ../assets/simulated3D/cameraB  # any size: the file's columns x rows
//! end_driver
//! load_driver simulated3D
//! ```
//! Relative paths are relative to the conf file. The world file holds
//! `worldline X1 Y1 Z1 H1 X2 Y2 Z2 H2` lines (mm; the other keys of extrinsics'
//! world files are read and ignored); the camera file holds `positionX..H`,
//! `FOApositionX..H`, `roll` (radians), `fx`, `fy`, `skew`, `u0`, `v0`, `columns`,
//! `rows` (see [`crate::progeo`]). Errors in either name `file:line`.
//!
//! # Interfaces
//! `colorA..D` (320x240) and `varcolorA..D` (the camera file's size), BGR. A
//! camera is rendered only while its interface is used; each render is one new
//! frame (clock + 1), every 33 ms as in 4.3. Segments that cross a camera's
//! plane are drawn clipped (4.3.0 left them out; 4.3.1 drew them).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use std::{path::PathBuf, sync::Arc};

use crate::{
    conf::{
        ComponentConf,
        settings::{self, Form, Setting},
    },
    interfaces::{COLOR_HEIGHT, COLOR_WIDTH, Image, Interface},
    progeo::{PinholeCamera, World},
    runtime::{Driver, Runtime, Worker},
    vision::draw_line,
};

/// The render period, as 4.3 (33 ms).
pub const PERIOD: Duration = Duration::from_millis(33);

/// Draws `world`'s lines in black on white through `cam` into `img` (resized to
/// the camera's columns x rows).
pub fn render(world: &World, cam: &PinholeCamera, img: &mut Image) {
    let (w, h) = (cam.columns, cam.rows);
    img.width = w;
    img.height = h;
    img.data.clear();
    img.data.resize(w as usize * h as usize * 3, 255);
    for (a, b) in &world.lines {
        let (pa, pb) = (cam.project(*a), cam.project(*b));
        if let Some((ga, gb)) = cam.displayline(pa, pb) {
            let (c0, r0) = cam.optical_to_graphic(ga);
            let (c1, r1) = cam.optical_to_graphic(gb);
            draw_line(img, (c0, r0), (c1, r1), [0, 0, 0]);
        }
    }
}

/// The driver's settings.
pub struct Sim3dConf {
    pub world: World,
    /// (interface, camera).
    pub cameras: Vec<(String, PinholeCamera)>,
}

crate::declare_lines! {
    /// The driver's lines, declared once (`jderobot help simulated3D`).
    struct Lines {
        worldfile: PathBuf = Setting::new(
            "worldfile",
            "the world it renders (a world file)",
            &[settings::path("FILE")],
        )
        .required(),
        provides: Vec<(String, PathBuf)> = settings::provides_forms(
            "a camera: an image interface and its camera file (progeo's format)",
            &[
                Form::new(
                    "color",
                    "a 320x240 camera (its file must say so)",
                    &[settings::COLOR, settings::path("CAMERA_FILE")],
                ),
                Form::new(
                    "varcolor",
                    "a camera of the file's columns x rows",
                    &[settings::VARCOLOR, settings::path("CAMERA_FILE")],
                ),
            ],
        )
        .required(),
    }
}
/// Parses the driver's lines and reads the world and camera files.
pub fn parse(conf: &ComponentConf) -> anyhow::Result<Sim3dConf> {
    let lines: Lines = conf.read()?;
    let world = World::load(&lines.worldfile).map_err(|e| {
        let at = conf
            .line("worldfile")
            .map(|l| l.at.to_string())
            .unwrap_or_default();
        anyhow::anyhow!("{at}: world file: {e}")
    })?;
    let mut cameras: Vec<(String, PinholeCamera)> = Vec::new();
    for ((iface, path), l) in lines.provides.into_iter().zip(conf.provides()) {
        let color = settings::COLOR.accepts(&iface);
        let cam = PinholeCamera::load(&path).map_err(|e| l.error(format!("camera file: {e}")))?;
        let (c, r) = (cam.columns, cam.rows);
        if !(1..=8192).contains(&c) || !(1..=8192).contains(&r) {
            return Err(l
                .error(format!(
                    "{}: columns {c} rows {r} is not an image size (1..8192)",
                    path.display()
                ))
                .into());
        }
        if color && (c, r) != (COLOR_WIDTH, COLOR_HEIGHT) {
            return Err(l
                .error(format!(
                    "{}: the camera is {c}x{r}, but {iface} is {COLOR_WIDTH}x{COLOR_HEIGHT}; use a varcolor interface",
                    path.display()
                ))
                .into());
        }
        if cameras.iter().any(|(n, _)| *n == iface) {
            return Err(l.error(format!("`{iface}` is provided twice")).into());
        }
        cameras.push((iface, cam));
    }
    Ok(Sim3dConf { world, cameras })
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let sc = parse(conf)?;
    let mut cams: Vec<(Arc<Interface<Image>>, PinholeCamera)> = Vec::new();
    for (name, cam) in sc.cameras {
        let iface =
            rt.interfaces
                .provide_value(&name, &conf.name, Image::new(cam.columns, cam.rows))?;
        cams.push((iface, cam));
    }
    let world = sc.world;
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    let worker = Worker::start("simulated3D", stop, move || {
        let mut next = Instant::now();
        while !s.load(Ordering::Acquire) {
            let mut any = false;
            for (iface, cam) in &cams {
                if iface.users() > 0 {
                    any = true;
                    if let Err(e) = iface.write(|img| render(&world, cam, img)) {
                        iface.set_stale(e.to_string());
                    }
                }
            }
            if !any {
                // Nobody looks: sleep until the first camera is used (or a tick).
                cams[0].0.wait_used(PERIOD);
                next = Instant::now();
                continue;
            }
            next += PERIOD;
            let now = Instant::now();
            if next > now {
                std::thread::sleep(next - now);
            } else {
                next = now;
            }
        }
    })?;
    Ok(Box::new(worker))
}

crate::register_driver!(
    Driver,
    "simulated3D",
    "synthetic camera images of a 3D wireframe world (progeo cameras, black lines on white)",
    create,
    lines = Lines
);
