//! followball: keeps a coloured ball in the middle of a pan-tilt camera's image,
//! as JDE 4.3's `followball` did: an HSV filter finds the ball, and the head is
//! driven by speed (not by position) toward it, with 4.3's dead band and speed ramps.
//!
//! Each cycle (30 ms, as 4.3) it filters the image in HSV (the seed's units: H in
//! radians, wrapping through 0 when `hmin > hmax`; S 0..1; V 0..255), takes the
//! centroid of the passing pixels and its offset (x right, y down) from the image
//! centre. With more than `min_pixels` pixels and the centroid farther than the dead
//! band (40 px at 320x240) from the centre, each axis is sent toward its limit on the
//! ball's side at a speed that ramps linearly with the offset, as 4.3: pan from
//! 350·ENC (18.0 deg/s) at 40 px to 2500·ENC (128.6 deg/s) at 160 px, tilt from
//! 300·ENC (15.4) at 40 px to 1000·ENC (51.4) at 120 px (ENC = 3.086/60 deg per step).
//! Below 40 px the speed falls in proportion to the offset, and the head stops
//! (commanded to where it is) once the centroid is within a quarter of the dead band,
//! so a rolling ball is followed smoothly, not in 40-pixel jerks; and a ball that
//! moves away from the centre two frames in a row is followed before it reaches the
//! dead band (a ball at rest inside the band leaves the head still). Without a ball the
//! head stops. Pixel figures scale with the image's width (and height).
//!
//! Stopping is "go where you are" rather than speed 0, because drivers differ on
//! speed 0 (the PTU stops, the simulator and the EVI use their maximum speed);
//! `stop speed0` sends speed 0 instead, as 4.3 did with the PTU, whose encoders are
//! polled only every 300 ms (going back to a position 300 ms old would jerk).
//! The pan direction follows the interfaces' convention (pan counter-clockwise, tilt
//! up, as the simulator); `invert pan` suits a head whose positive pan turns right
//! (the EVI, as 4.3 used it).
//!
//! Conf (every line optional; defaults shown):
//! ```text
//! schema followball
//! image colorA                 # any image interface (colorA..D, varcolorA..D)
//! pantiltencoders pantiltencoders
//! pantiltmotors pantiltmotors
//! hmin 6.0                     # HSV pass ranges, hsvtuner's units: H rad, S 0..1, V 0..255
//! hmax 0.35                    #   (red: H wraps through 0)
//! smin 0.5
//! smax 1
//! vmin 60
//! vmax 255
//! deadband 40                  # px at 320 columns
//! min_pixels 400               # px at 320x240
//! cycle 30                     # ms
//! stop position                # or speed0 (the PTU, as 4.3)
//! invert pan                   # and/or `invert tilt`
//! end_schema
//! ```
//! Interfaces: reads an image (BGR), `pantiltencoders` (deg); writes
//! `pantiltmotors` (longitude/latitude deg toward a limit or the current position,
//! speeds deg/s). Its panel shows the filtered image with the centroid, the offset
//! and the commands.

use std::{sync::Arc, time::Duration};

use parking_lot::Mutex;

use crate::{
    colorspaces::{HsvRange, Lookup, hsv_mask},
    conf::{
        ComponentConf,
        settings::{self, CYCLE, Setting, choice, float, int},
    },
    imagesource,
    interfaces::{Image, Interface, InterfaceValue, PtEncoders, PtMotors},
    runtime::{Context, Runtime, Schema},
};

/// Degrees per PTU encoder step (4.3's ENCOD_TO_DEG), the unit of 4.3's speed ramps.
pub const ENC: f32 = 3.086 / 60.0;

/// What the tracker does with one image.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Decision {
    /// Passing pixels.
    pub pixels: usize,
    /// Centroid (column, row), if there are pixels.
    pub centroid: Option<(f32, f32)>,
    /// Offset of the centroid from the centre, x right, y down (px).
    pub offset: (f32, f32),
    /// Pan and tilt speeds, deg/s, signed in the interface's direction (0 = hold).
    pub speed: (f32, f32),
    /// Whether the head is being driven (outside the dead band, or catching up).
    pub moving: bool,
}

/// The tracker's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    pub range: HsvRange,
    pub deadband: f32,
    pub min_pixels: usize,
    pub invert_pan: bool,
    pub invert_tilt: bool,
    /// How an axis is stopped.
    pub stop: Stop,
}

/// How followball stops an axis.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Stop {
    /// Command the axis to where the encoders say it is (works with every driver).
    #[default]
    Position,
    /// Speed 0 (4.3 with the PTU, whose `PS0` stops where the axis is; better than
    /// `position` when the encoders are polled slowly).
    Speed0,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            range: HsvRange::from_radians(6.0, 0.35, 0.5, 1.0, 60.0, 255.0),
            deadband: 40.0,
            min_pixels: 400,
            invert_pan: false,
            invert_tilt: false,
            stop: Stop::Position,
        }
    }
}

/// A linear ramp from `lo` at `from` to `hi` at `to` (clamped), proportional below `from`.
fn ramp(off: f32, from: f32, to: f32, lo: f32, hi: f32) -> f32 {
    let a = off.abs();
    if a < from {
        lo * a / from
    } else {
        lo + (hi - lo) * ((a - from) / (to - from)).min(1.0)
    }
}

/// The image-to-speed part of followball (no interfaces), for tests and benchmarks.
#[derive(Clone, Debug, Default)]
pub struct Tracker {
    pub settings: Settings,
    moving: bool,
    last_dist: Option<f32>,
    growing: u8,
}

impl Tracker {
    pub fn new(settings: Settings) -> Self {
        Tracker {
            settings,
            ..Tracker::default()
        }
    }

    /// Filters `img`, finds the ball and decides the speeds. Also returns the mask.
    pub fn decide(&mut self, img: &Image) -> (Decision, Vec<u8>) {
        let mask = hsv_mask(img, &self.settings.range, Lookup::Exact);
        let (w, h) = (img.width.max(1) as usize, img.height.max(1) as usize);
        let (mut n, mut sx, mut sy) = (0usize, 0u64, 0u64);
        for (row, line) in mask.data.chunks_exact(w).enumerate().take(h) {
            let mut rn = 0u64;
            for (col, &m) in line.iter().enumerate() {
                if m != 0 {
                    rn += 1;
                    sx += col as u64;
                }
            }
            n += rn as usize;
            sy += rn * row as u64;
        }
        let sxs = w as f32 / 320.0;
        let sys = h as f32 / 240.0;
        let scale_px = sxs * sys;
        let s = &self.settings;
        let mut d = Decision {
            pixels: n,
            ..Decision::default()
        };
        if n == 0 || (n as f32) <= s.min_pixels as f32 * scale_px {
            self.moving = false;
            self.last_dist = None;
            return (d, mask.data);
        }
        let c = (sx as f32 / n as f32, sy as f32 / n as f32);
        d.centroid = Some(c);
        let off = (c.0 - w as f32 / 2.0, c.1 - h as f32 / 2.0);
        d.offset = off;
        let (ox, oy) = (off.0 / sxs, off.1 / sys);
        let dist = ox.hypot(oy);
        // A ball moving away from the centre for two frames in a row is followed
        // before it leaves the dead band (a ball at rest inside it is not).
        let away = self.last_dist.is_some_and(|p| dist > p + 0.5);
        self.growing = if away {
            self.growing.saturating_add(1)
        } else {
            0
        };
        self.last_dist = Some(dist);
        if dist > s.deadband || (dist > s.deadband / 4.0 && self.growing >= 2) {
            self.moving = true;
        } else if dist < s.deadband / 4.0 {
            self.moving = false;
        }
        d.moving = self.moving;
        if self.moving {
            let db = s.deadband;
            let pan = ramp(ox, db, 4.0 * db, 350.0 * ENC, 2500.0 * ENC);
            let tilt = ramp(oy, db, 3.0 * db, 300.0 * ENC, 1000.0 * ENC);
            // Ball to the right → pan clockwise (negative); below → tilt down.
            let sp = if s.invert_pan { 1.0 } else { -1.0 };
            let st = if s.invert_tilt { 1.0 } else { -1.0 };
            d.speed = (sp * ox.signum() * pan, st * oy.signum() * tilt);
        }
        (d, mask.data)
    }
}

/// The pan-tilt command for signed speeds: toward the limit on that side at |speed|;
/// a zero speed stops the axis as `stop` says (where the head is, at the minimum
/// speed; or speed 0).
pub fn command(d: &Decision, here: &PtEncoders, m: &PtMotors, stop: Stop) -> PtMotors {
    let axis = |speed: f32, cur: f32, lo: f32, hi: f32, hold: f32| -> (f32, f32) {
        if speed > 0.0 {
            (hi, speed)
        } else if speed < 0.0 {
            (lo, -speed)
        } else if stop == Stop::Speed0 {
            (cur, 0.0)
        } else {
            (cur, hold)
        }
    };
    let (longitude, longitude_speed) = axis(
        d.speed.0,
        here.pan_angle,
        m.min_longitude,
        m.max_longitude,
        350.0 * ENC,
    );
    let (latitude, latitude_speed) = axis(
        d.speed.1,
        here.tilt_angle,
        m.min_latitude,
        m.max_latitude,
        300.0 * ENC,
    );
    PtMotors {
        longitude,
        latitude,
        longitude_speed: longitude_speed.min(m.max_longitude_speed),
        latitude_speed: latitude_speed.min(m.max_latitude_speed),
        ..*m
    }
}

/// What the panel shows: the last image, its mask, the decision and the command.
/// The image and mask are kept only while the panel is drawn (so the image
/// driver's buffers are recycled when nobody looks).
#[derive(Clone, Default)]
pub struct Status {
    pub image: Option<Arc<crate::interfaces::Sample<Image>>>,
    pub mask: Vec<u8>,
    pub decision: Decision,
    pub command: Option<PtMotors>,
    /// When the panel last drew.
    pub drawn: Option<std::time::Instant>,
}

pub struct FollowBall {
    tracker: Tracker,
    image: Arc<Interface<Image>>,
    pte: Arc<Interface<PtEncoders>>,
    ptm: Arc<Interface<PtMotors>>,
    children: Vec<String>,
    cycle: Duration,
    last_clock: u64,
    last_cmd: Option<PtMotors>,
    status: Arc<Mutex<Status>>,
    #[cfg(feature = "gui")]
    panel: Option<Box<dyn crate::runtime::Panel>>,
}

impl Schema for FollowBall {
    fn cycle(&self) -> Duration {
        self.cycle
    }
    fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
        ctx.run_children(&self.children, None)?;
        self.last_clock = 0;
        self.last_cmd = None;
        Ok(())
    }
    fn iteration(&mut self, _ctx: &Context) -> anyhow::Result<()> {
        let img = self.image.snapshot();
        if img.clock == 0 || img.clock == self.last_clock {
            return Ok(());
        }
        self.last_clock = img.clock;
        let (d, mask) = self.tracker.decide(&img.value);
        let here = self.pte.read().value;
        let cmd = command(
            &d,
            &here,
            &self.ptm.read().value,
            self.tracker.settings.stop,
        );
        if self.last_cmd != Some(cmd) {
            self.ptm.publish(cmd).map_err(anyhow::Error::msg)?;
            self.last_cmd = Some(cmd);
        }
        let mut s = self.status.lock();
        if s.drawn
            .is_some_and(|t| t.elapsed() < Duration::from_secs(1))
        {
            s.image = Some(img);
            s.mask = mask;
        } else {
            s.image = None;
        }
        s.decision = d;
        s.command = Some(cmd);
        Ok(())
    }
    fn on_stop(&mut self, _ctx: &Context) {
        // Hold the head where it is.
        let here = self.pte.read().value;
        let cmd = command(
            &Decision::default(),
            &here,
            &self.ptm.read().value,
            self.tracker.settings.stop,
        );
        let _ = self.ptm.publish(cmd);
    }
    #[cfg(feature = "gui")]
    fn panel(&mut self) -> Option<Box<dyn crate::runtime::Panel>> {
        self.panel.take()
    }
}

crate::declare_lines! {
    /// followball's lines, declared once (`jderobot help followball`).
    struct Lines {
        image: String = settings::uses(
            "image",
            "the camera image it filters (colorA..D, varcolorA..D)",
        )
        .default("colorA"),
        pantiltencoders: String = settings::uses("pantiltencoders", "the head's angles"),
        pantiltmotors: String = settings::uses("pantiltmotors", "the head it drives"),
        #[serde(deserialize_with = "imagesource::hsv_lines")]
        hsv: HsvRange = [
            // The ball's colour: the HSV range lines the tuners share.
        imagesource::HMIN.default("6.0"),
            imagesource::HMAX.default("0.35"),
            imagesource::SMIN.default("0.5"),
            imagesource::SMAX.default("1"),
            imagesource::VMIN.default("60"),
            imagesource::VMAX.default("255"),
        ],
        deadband: f32 = Setting::new(
            "deadband",
            "no motion while the ball is this close to the centre (at 320 columns)",
            &[float("PX", "px", 1.0, 160.0)],
        )
        .default("40"),
        min_pixels: u32 = Setting::new(
            "min_pixels",
            "fewer passing pixels than this is no ball (at 320x240)",
            &[int("N", "px", 0, 76_800)],
        )
        .default("400"),
        cycle: u64 = CYCLE.default("30"),
        stop: String = Setting::new(
            "stop",
            "how the head stops: go where it is, or speed 0 (the PTU, as 4.3)",
            &[choice("HOW", &["position", "speed0"])],
        )
        .default("position"),
        invert: Vec<String> = Setting::new(
            "invert",
            "an axis whose positive direction is the other way (the EVI's pan)",
            &[choice("AXIS", &["pan", "tilt"])],
        )
        .repeats(),
    }
}
/// Parses the conf: settings, interface names, cycle.
pub fn parse(conf: &ComponentConf) -> anyhow::Result<(Settings, [String; 3], Duration)> {
    let l: Lines = conf.read()?;
    if crate::interfaces::family(&l.image) != Some(Image::KIND) {
        let at = conf
            .line("image")
            .map(|l| l.at.to_string())
            .unwrap_or_default();
        anyhow::bail!(
            "{at}: `image`: `{}` is not an image interface (colorA..D, varcolorA..D)",
            l.image
        );
    }
    let s = Settings {
        deadband: l.deadband,
        min_pixels: l.min_pixels as _,
        stop: if l.stop == "speed0" {
            Stop::Speed0
        } else {
            Stop::Position
        },
        invert_pan: l.invert.iter().any(|a| a == "pan"),
        invert_tilt: l.invert.iter().any(|a| a == "tilt"),
        range: l.hsv,
    };
    let names = [
        crate::interfaces::canonical(&l.image),
        l.pantiltencoders,
        l.pantiltmotors,
    ];
    Ok((s, names, Duration::from_millis(l.cycle)))
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let (settings, names, cycle) = parse(conf)?;
    let get_hint = |n: &str| {
        format!(
            "{}: followball needs `{n}`; load a driver that provides it before followball \
             (e.g. the simulator with `provides {n}`)",
            conf.file.display()
        )
    };
    let image = rt
        .interfaces
        .get::<Image>(&names[0])
        .map_err(|e| anyhow::anyhow!("{} ({e})", get_hint(&names[0])))?;
    let pte = rt
        .interfaces
        .get::<PtEncoders>(&names[1])
        .map_err(|e| anyhow::anyhow!("{} ({e})", get_hint(&names[1])))?;
    let ptm = rt
        .interfaces
        .get::<PtMotors>(&names[2])
        .map_err(|e| anyhow::anyhow!("{} ({e})", get_hint(&names[2])))?;
    let status = Arc::new(Mutex::new(Status::default()));
    Ok(Box::new(FollowBall {
        tracker: Tracker::new(settings),
        image,
        pte,
        ptm,
        children: names.to_vec(),
        cycle,
        last_clock: 0,
        last_cmd: None,
        #[cfg(feature = "gui")]
        panel: Some(Box::new(panel::FollowBallPanel::new(status.clone()))),
        status,
    }))
}

crate::register_schema!(
    "followball",
    "keeps a coloured ball centred with a pan-tilt camera (HSV filter, speed control)",
    create,
    lines = Lines
);

#[cfg(feature = "gui")]
mod panel {
    //! The filtered image with the centroid and the dead band, the offset and the
    //! pan-tilt commands.

    use std::sync::Arc;

    use egui::{Color32, Stroke, pos2, vec2};
    use parking_lot::Mutex;

    use crate::{
        interfaces::Image,
        runtime::{Panel, Runtime},
        widgets::ImageView,
    };

    use super::Status;

    pub struct FollowBallPanel {
        status: Arc<Mutex<Status>>,
        view: ImageView,
        filtered: Image,
        shown_clock: u64,
    }

    impl FollowBallPanel {
        pub fn new(status: Arc<Mutex<Status>>) -> Self {
            FollowBallPanel {
                status,
                view: ImageView::new("followball filtered"),
                filtered: Image::default(),
                shown_clock: 0,
            }
        }
    }

    impl Panel for FollowBallPanel {
        fn title(&self) -> Option<String> {
            Some("followball".into())
        }

        fn ui(&mut self, ui: &mut egui::Ui, _rt: &Runtime) {
            let (image, d, cmd) = {
                let mut s = self.status.lock();
                s.drawn = Some(std::time::Instant::now());
                if let Some(img) = &s.image
                    && img.clock != self.shown_clock
                    && s.mask.len() == img.width as usize * img.height as usize
                {
                    // Passing pixels in colour, the rest grey (hsvtuner's view).
                    self.filtered.clone_from(&img.value);
                    for (p, &m) in self.filtered.data.chunks_exact_mut(3).zip(&s.mask) {
                        if m == 0 {
                            let g = (p[0].max(p[1]).max(p[2]) as u32 * 180 / 255) as u8;
                            p.fill(g);
                        }
                    }
                    self.shown_clock = img.clock;
                }
                (s.image.clone(), s.decision, s.command)
            };
            let Some(img) = image else {
                ui.label("(no image yet: is the image interface running?)");
                ui.ctx()
                    .request_repaint_after(std::time::Duration::from_millis(100));
                return;
            };
            let r = ui
                .allocate_ui(vec2(320.0, 240.0), |ui| {
                    self.view.show(ui, &self.filtered, self.shown_clock)
                })
                .inner;
            let (w, h) = (img.width as f32, img.height as f32);
            let to_screen = |x: f32, y: f32| {
                pos2(
                    r.rect.left() + x / w * r.rect.width(),
                    r.rect.top() + y / h * r.rect.height(),
                )
            };
            let painter = ui.painter_at(r.rect);
            let centre = to_screen(w / 2.0, h / 2.0);
            let band = 40.0 * w / 320.0 / w * r.rect.width();
            painter.circle_stroke(centre, band, Stroke::new(1.0, Color32::LIGHT_BLUE));
            if let Some((x, y)) = d.centroid {
                let c = to_screen(x, y);
                let red = Stroke::new(2.0, Color32::RED);
                painter.line_segment([c - vec2(8.0, 0.0), c + vec2(8.0, 0.0)], red);
                painter.line_segment([c - vec2(0.0, 8.0), c + vec2(0.0, 8.0)], red);
                painter.line_segment([centre, c], Stroke::new(1.0, Color32::YELLOW));
            }
            ui.label(format!(
                "pixels {}  offset ({:+.0}, {:+.0}) px  {}",
                d.pixels,
                d.offset.0,
                d.offset.1,
                if d.centroid.is_none() {
                    "no ball"
                } else if d.moving {
                    "following"
                } else {
                    "centred"
                }
            ));
            if let Some(c) = cmd {
                ui.label(format!(
                    "pan to {:.1}° at {:.1}°/s   tilt to {:.1}° at {:.1}°/s",
                    c.longitude, c.longitude_speed, c.latitude, c.latitude_speed
                ));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grey image with a red disc of radius `r` at (cx, cy).
    fn disc(w: u32, h: u32, cx: f32, cy: f32, r: f32) -> Image {
        let mut img = Image::new(w, h);
        for (i, p) in img.data.chunks_exact_mut(3).enumerate() {
            let (x, y) = ((i as u32 % w) as f32, (i as u32 / w) as f32);
            let red = (x - cx).hypot(y - cy) < r;
            p.copy_from_slice(if red {
                &[20, 20, 200]
            } else {
                &[120, 120, 120]
            });
        }
        img
    }

    #[test]
    fn directions_dead_band_ramps_and_size() {
        let mut t = Tracker::new(Settings::default());
        // Right and below: pan clockwise (negative), tilt down (negative).
        let (d, _) = t.decide(&disc(320, 240, 260.0, 200.0, 15.0));
        assert!(d.moving && d.speed.0 < 0.0 && d.speed.1 < 0.0, "{d:?}");
        // Offsets of 100 and 80 px: on 4.3's ramps.
        let pan = 350.0 * ENC + (2150.0 * ENC) * (100.0 - 40.0) / 120.0;
        assert!((d.speed.0 + pan).abs() < 0.5, "{d:?}");
        // Left and above: the other way; `invert pan` flips pan only.
        let (d, _) = t.decide(&disc(320, 240, 60.0, 40.0, 15.0));
        assert!(d.speed.0 > 0.0 && d.speed.1 > 0.0, "{d:?}");
        // Centred: the head holds.
        let mut t = Tracker::new(Settings::default());
        let (d, _) = t.decide(&disc(320, 240, 165.0, 118.0, 15.0));
        assert!(!d.moving && d.speed == (0.0, 0.0), "{d:?}");
        // Too small (under 400 pixels): no ball.
        let (d, _) = t.decide(&disc(320, 240, 60.0, 40.0, 10.0));
        assert_eq!(d.centroid, None);
        // 640x480: the same ball (scaled) gives the same speeds.
        let mut a = Tracker::new(Settings::default());
        let mut b = Tracker::new(Settings::default());
        let (da, _) = a.decide(&disc(320, 240, 260.0, 200.0, 15.0));
        let (db, _) = b.decide(&disc(640, 480, 520.0, 400.0, 30.0));
        assert!((da.speed.0 - db.speed.0).abs() < 0.5 && (da.speed.1 - db.speed.1).abs() < 0.5);
    }

    #[test]
    fn commands_go_to_a_limit_or_stop() {
        let lim = PtMotors::default();
        let here = PtEncoders {
            pan_angle: 12.0,
            tilt_angle: -3.0,
        };
        let d = Decision {
            speed: (-20.0, 0.0),
            ..Decision::default()
        };
        let c = command(&d, &here, &lim, Stop::Position);
        assert_eq!((c.longitude, c.longitude_speed), (lim.min_longitude, 20.0));
        assert_eq!(c.latitude, -3.0);
        assert!(c.latitude_speed > 0.0);
        let c = command(&d, &here, &lim, Stop::Speed0);
        assert_eq!((c.latitude, c.latitude_speed), (-3.0, 0.0));
    }
}
