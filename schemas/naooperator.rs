//! naooperator: teleoperation of a walking robot, as JDE 4.3.1's `naooperator`
//! did for the Nao: the walk (`motors`: v forward, w turning), the head
//! (`pantiltmotors`, watched through `pantiltencoders`) and the camera image, in one
//! panel (a joystick, a head positioner, the image).
//!
//! 4.3.1 drove the Nao through NAOqi (its `naobody` driver). NAOqi is Aldebaran's
//! proprietary middleware and is out of reach here, so there is no Nao driver:
//! naooperator works against any driver that provides these interfaces (the
//! simulator, player, networkclient ...), and a Nao bridge would only need to
//! provide them.
//!
//! Headless it holds the commanded values (from the conf or the name space) and
//! writes them every iteration: the walk to `motors` (so it never goes stale) and
//! the head to `pantiltmotors` when it changes. Stopping the schema stops the walk.
//!
//! Conf (every line optional; defaults shown):
//! ```text
//! schema naooperator
//! walk 0 0                 # V W: initial walk command, mm/s and deg/s
//! head 0 0                 # LONGITUDE LATITUDE: initial head command, deg
//! max_v 500                # joystick maxima, mm/s and deg/s
//! max_w 30
//! cycle 100                # ms
//! motors motors            # interface names; all but motors may be `none`
//! pantiltmotors pantiltmotors
//! pantiltencoders pantiltencoders
//! camera varcolorA         # 4.3.1 used varcolorX; any image interface
//! end_schema
//! ```
//! Name space, component `naooperator`: `walk` (`Mutex<Motors>`) and `head`
//! (`Mutex<[f32; 2]>`, longitude and latitude in degrees).

use std::{sync::Arc, time::Duration};

use parking_lot::Mutex;

use crate::{
    conf::{ComponentConf, ConfLine},
    interfaces::{Image, Interface, Motors, PtEncoders, PtMotors},
    runtime::{Context, Runtime, Schema},
};

/// The commands the schema, its panel and the name space share.
pub struct Commands {
    pub walk: Arc<Mutex<Motors>>,
    pub head: Arc<Mutex<[f32; 2]>>,
    pub max_v: f32,
    pub max_w: f32,
}

impl Commands {
    pub fn set_walk(&self, v: f32, w: f32) {
        *self.walk.lock() = Motors::limited(v, w, self.max_v, self.max_w);
    }
    pub fn set_head(&self, longitude: f32, latitude: f32) {
        let fin = |x: f32| if x.is_finite() { x } else { 0.0 };
        *self.head.lock() = [fin(longitude), fin(latitude)];
    }
}

/// The interfaces it drives and watches.
#[derive(Clone)]
pub struct Devices {
    pub motors: Arc<Interface<Motors>>,
    pub ptmotors: Option<Arc<Interface<PtMotors>>>,
    pub ptencoders: Option<Arc<Interface<PtEncoders>>>,
    pub camera: Option<Arc<Interface<Image>>>,
}

pub struct NaoOperator {
    pub commands: Arc<Commands>,
    dev: Devices,
    children: Vec<String>,
    cycle: Duration,
    last_head: Option<[f32; 2]>,
    #[cfg(feature = "gui")]
    panel: Option<Box<dyn crate::runtime::Panel>>,
}

impl Schema for NaoOperator {
    fn cycle(&self) -> Duration {
        self.cycle
    }
    fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
        ctx.run_children(&self.children, None)?;
        self.last_head = None;
        Ok(())
    }
    fn iteration(&mut self, _ctx: &Context) -> anyhow::Result<()> {
        let walk = *self.commands.walk.lock();
        self.dev.motors.publish(walk).map_err(anyhow::Error::msg)?;
        let head = *self.commands.head.lock();
        if let Some(ptm) = &self.dev.ptmotors
            && self.last_head != Some(head)
        {
            ptm.point(head[0], head[1])?;
            self.last_head = Some(head);
        }
        Ok(())
    }
    fn on_stop(&mut self, _ctx: &Context) {
        let _ = self.dev.motors.publish(Motors::default());
    }
    #[cfg(feature = "gui")]
    fn panel(&mut self) -> Option<Box<dyn crate::runtime::Panel>> {
        self.panel.take()
    }
}

fn pair(l: &ConfLine, a: &str, b: &str) -> anyhow::Result<[f32; 2]> {
    l.expect_args(2, 2, &format!("{} {a} {b}", l.keyword()))?;
    Ok([l.number(0, a, ..)?, l.number(1, b, ..)?])
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let (mut walk, mut head) = ([0.0f32; 2], [0.0f32; 2]);
    let (mut max_v, mut max_w) = (500.0f32, 30.0f32);
    let mut cycle = Duration::from_millis(100);
    let mut names: Vec<(&str, Option<String>)> = [
        ("motors", "motors"),
        ("pantiltmotors", "pantiltmotors"),
        ("pantiltencoders", "pantiltencoders"),
        ("camera", "varcolorA"),
    ]
    .into_iter()
    .map(|(k, v)| (k, Some(v.to_string())))
    .collect();
    for l in &conf.lines {
        match l.keyword() {
            "walk" => walk = pair(l, "V(mm/s)", "W(deg/s)")?,
            "head" => head = pair(l, "LONGITUDE(deg)", "LATITUDE(deg)")?,
            "max_v" => {
                l.expect_args(1, 1, "max_v MM_S")?;
                max_v = l.number(0, "a speed in mm/s", 1.0..=1000.0)?;
            }
            "max_w" => {
                l.expect_args(1, 1, "max_w DEG_S")?;
                max_w = l.number(0, "a turn rate in deg/s", 1.0..=180.0)?;
            }
            "cycle" => {
                l.expect_args(1, 1, "cycle MS")?;
                cycle = l.millis(0, "a period in ms", 1..=10_000)?;
            }
            k if names.iter().any(|(n, _)| *n == k) => {
                l.expect_args(1, 1, &format!("{k} INTERFACE|none"))?;
                let v = &l.args()[0];
                if k == "motors" && v == "none" {
                    return Err(l.error("naooperator needs a motors interface").into());
                }
                if let Some(e) = names.iter_mut().find(|(n, _)| *n == k) {
                    e.1 = (v != "none").then(|| v.clone());
                }
            }
            _ => {
                return Err(conf
                    .unknown(
                        l,
                        "walk, head, max_v, max_w, cycle, motors, pantiltmotors, pantiltencoders or camera",
                    )
                    .into());
            }
        }
    }
    let name = |k: &str| {
        names
            .iter()
            .find(|(n, _)| *n == k)
            .and_then(|(_, v)| v.clone())
            .filter(|n| rt.interfaces.contains(n))
    };
    let Some(motors) = name("motors") else {
        anyhow::bail!(
            "{}: naooperator needs a motors interface; load a driver that provides it (the \
             simulator, player, networkclient ...) before naooperator",
            conf.file.display()
        );
    };
    let ifs = &rt.interfaces;
    let dev = Devices {
        motors: ifs.get(&motors)?,
        ptmotors: name("pantiltmotors").map(|n| ifs.get(&n)).transpose()?,
        ptencoders: name("pantiltencoders").map(|n| ifs.get(&n)).transpose()?,
        camera: name("camera").map(|n| ifs.get(&n)).transpose()?,
    };
    let children: Vec<String> = ["motors", "pantiltmotors", "pantiltencoders", "camera"]
        .iter()
        .filter_map(|k| name(k))
        .collect();
    let c = conf.name.as_str();
    let walk_cmd = match rt.names.import::<Mutex<Motors>>(c, "walk") {
        Ok(a) => a,
        Err(_) => {
            let a = Arc::new(Mutex::new(Motors::default()));
            let _ = rt.names.export_arc(c, "walk", a.clone());
            a
        }
    };
    let head_cmd = match rt.names.import::<Mutex<[f32; 2]>>(c, "head") {
        Ok(a) => a,
        Err(_) => {
            let a = Arc::new(Mutex::new([0.0f32; 2]));
            let _ = rt.names.export_arc(c, "head", a.clone());
            a
        }
    };
    let commands = Arc::new(Commands {
        walk: walk_cmd,
        head: head_cmd,
        max_v,
        max_w,
    });
    commands.set_walk(walk[0], walk[1]);
    commands.set_head(head[0], head[1]);
    Ok(Box::new(NaoOperator {
        #[cfg(feature = "gui")]
        panel: Some(Box::new(panel::NaoPanel::new(
            commands.clone(),
            dev.clone(),
        ))),
        commands,
        dev,
        children,
        cycle,
        last_head: None,
    }))
}

crate::register_schema!(
    "naooperator",
    "teleoperates a walking robot: walk (v, w), head (pan-tilt) and camera in one panel",
    create
);

#[cfg(feature = "gui")]
mod panel {
    //! The joystick (walk), the head positioner and the camera image.

    use std::sync::Arc;

    use egui::vec2;

    use crate::{
        runtime::{Panel, Runtime},
        widgets::{ImageView, Joystick, PanTiltLimits, PanTiltPad},
    };

    use super::{Commands, Devices};

    pub struct NaoPanel {
        commands: Arc<Commands>,
        dev: Devices,
        joystick: Joystick,
        pad: Option<PanTiltPad>,
        image: ImageView,
    }

    impl NaoPanel {
        pub fn new(commands: Arc<Commands>, dev: Devices) -> Self {
            let pad = dev.ptmotors.as_ref().map(|m| {
                let mut p =
                    PanTiltPad::new("naooperator head", PanTiltLimits::from(&m.read().value));
                let h = *commands.head.lock();
                (p.longitude, p.latitude) = (h[0], h[1]);
                p
            });
            NaoPanel {
                joystick: Joystick::new("naooperator walk", commands.max_v, commands.max_w),
                commands,
                dev,
                pad,
                image: ImageView::new("naooperator camera"),
            }
        }
    }

    impl Panel for NaoPanel {
        fn title(&self) -> Option<String> {
            Some("naooperator".into())
        }

        fn ui(&mut self, ui: &mut egui::Ui, _rt: &Runtime) {
            let head = self
                .dev
                .ptencoders
                .as_ref()
                .map(|p| p.read().value)
                .map(|p| (p.pan_angle, p.tilt_angle));
            ui.horizontal(|ui| {
                let m = self.dev.motors.read().value;
                ui.label(format!("walk v {:.0} mm/s  w {:.1} deg/s", m.v, m.w));
                if ui.button("STOP").clicked() {
                    self.commands.set_walk(0.0, 0.0);
                    self.joystick.v = 0.0;
                    self.joystick.w = 0.0;
                }
            });
            ui.horizontal_top(|ui| {
                ui.vertical(|ui| {
                    ui.label("walk");
                    if self.joystick.show(ui, 140.0).changed() {
                        self.commands.set_walk(self.joystick.v, self.joystick.w);
                    }
                    if let Some(pad) = &mut self.pad {
                        ui.label("head");
                        if pad.show(ui, vec2(140.0, 90.0), head).changed() {
                            self.commands.set_head(pad.longitude, pad.latitude);
                        }
                    }
                });
                ui.vertical(|ui| {
                    ui.label("camera");
                    match &self.dev.camera {
                        Some(c) => {
                            let s = c.snapshot();
                            ui.allocate_ui(vec2(320.0, 240.0), |ui| {
                                if s.clock > 0 {
                                    self.image.show_sample(ui, &s);
                                } else {
                                    ui.small("(no image yet)");
                                }
                            });
                        }
                        None => {
                            ui.small("(no camera interface)");
                        }
                    }
                });
            });
        }
    }
}
