//! naooperator: teleoperation of a walking robot, as JDE 4.3.1's `naooperator`
//! did for the Nao: the walk (`motors`: v forward, w turning), the head
//! (`pantiltmotors`, watched through `pantiltencoders`) and the camera image, in one
//! panel (a joystick, a head positioner, the image).
//!
//! 4.3.1 drove the Nao through NAOqi with its `naobody` driver, and so does this
//! one (`drivers/naobody`, `examples/naobody.conf`, docs/nao.md); naooperator
//! works against any driver that provides these interfaces (naobody, the
//! simulator, player, networkclient ...).
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

use crate::{
    conf::{
        ComponentConf,
        settings::{self, CYCLE, Setting},
    },
    interfaces::{Image, Interface, PtEncoders, PtMotors},
    operator::{self, Commands, Operator},
    runtime::{Runtime, Schema},
};

/// naooperator's lines, declared once (`jderobot help naooperator`).
const LINES: &[Setting] = &[
    operator::BASE
        .key("walk")
        .help("the initial walk command (limited to max_v and max_w)"),
    operator::HEAD
        .key("head")
        .help("the initial head command (the robot clamps it to its limits)"),
    operator::MAX_V,
    operator::MAX_W,
    CYCLE.default("100"),
    settings::uses("motors", "motors", "the interface it walks the robot with"),
    settings::uses(
        "pantiltmotors",
        "pantiltmotors",
        "the head it points (none: no head)",
    ),
    settings::uses(
        "pantiltencoders",
        "pantiltencoders",
        "the head angles it shows (none: none)",
    ),
    settings::uses(
        "camera",
        "varcolorA",
        "the image it shows (4.3.1 used varcolorX; none: none)",
    ),
];

/// The values of [`LINES`].
#[derive(serde::Deserialize)]
struct Lines {
    walk: (f32, f32),
    head: (f32, f32),
    max_v: f32,
    max_w: f32,
    cycle: u64,
    motors: String,
    pantiltmotors: String,
    pantiltencoders: String,
    camera: String,
}

/// The interfaces it drives and watches.
#[derive(Clone)]
pub struct Devices {
    pub motors: Arc<Interface<crate::interfaces::Motors>>,
    pub ptmotors: Option<Arc<Interface<PtMotors>>>,
    pub ptencoders: Option<Arc<Interface<PtEncoders>>>,
    pub camera: Option<Arc<Interface<Image>>>,
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let lines: Lines = conf.settings(LINES)?;
    // An interface the conf names, if it is not `none` and something provides it.
    let name = |n: &str| (n != "none" && rt.interfaces.contains(n)).then(|| n.to_string());
    let Some(motors) = name(&lines.motors) else {
        anyhow::bail!(
            "{}: naooperator needs a motors interface (`{}` is not provided); load a driver \
             that provides it (the simulator, player, networkclient ...) before naooperator",
            conf.line("motors")
                .map(|l| l.at.to_string())
                .unwrap_or_else(|| conf.file.display().to_string()),
            lines.motors
        );
    };
    let ifs = &rt.interfaces;
    let names = [
        Some(motors),
        name(&lines.pantiltmotors),
        name(&lines.pantiltencoders),
        name(&lines.camera),
    ];
    let dev = Devices {
        motors: ifs.get(names[0].as_deref().unwrap_or_default())?,
        ptmotors: names[1].as_deref().map(|n| ifs.get(n)).transpose()?,
        ptencoders: names[2].as_deref().map(|n| ifs.get(n)).transpose()?,
        camera: names[3].as_deref().map(|n| ifs.get(n)).transpose()?,
    };
    let commands = Arc::new(Commands::shared(
        &rt.names,
        &conf.name,
        ("walk", "head"),
        (lines.max_v, lines.max_w),
        lines.walk,
        lines.head,
    ));
    #[cfg_attr(not(feature = "gui"), allow(unused_mut))]
    let mut schema = Operator::new(
        commands.clone(),
        dev.motors.clone(),
        dev.ptmotors.clone(),
        names.into_iter().flatten().collect(),
        Duration::from_millis(lines.cycle),
    );
    #[cfg(feature = "gui")]
    {
        schema.panel = Some(Box::new(panel::NaoPanel::new(commands, dev)));
    }
    Ok(Box::new(schema))
}

crate::register_schema!(
    "naooperator",
    "teleoperates a walking robot: walk (v, w), head (pan-tilt) and camera in one panel",
    create,
    lines = LINES
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
                    self.commands.set_base(0.0, 0.0);
                    self.joystick.v = 0.0;
                    self.joystick.w = 0.0;
                }
            });
            ui.horizontal_top(|ui| {
                ui.vertical(|ui| {
                    ui.label("walk");
                    if self.joystick.show(ui, 140.0).changed() {
                        self.commands.set_base(self.joystick.v, self.joystick.w);
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
