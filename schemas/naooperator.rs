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

use std::sync::Arc;

use crate::{
    conf::{
        ComponentConf,
        settings::{self, CYCLE},
    },
    interfaces::{Image, Interface, PtEncoders, PtMotors},
    operator::{self, CommandLines, Operator},
    runtime::{Runtime, Schema},
};

crate::declare_lines! {
    /// naooperator's lines, declared once (`jderobot help naooperator`).
    struct Lines {
        walk: (f32, f32) = operator::BASE
            .key("walk")
            .help("the initial walk command (limited to max_v and max_w)"),
        head: (f32, f32) = operator::HEAD
            .key("head")
            .help("the initial head command (the robot clamps it to its limits)"),
        max_v: f32 = operator::MAX_V,
        max_w: f32 = operator::MAX_W,
        cycle: u64 = CYCLE.default("100"),
        motors: String = settings::uses("motors", "the interface it walks the robot with"),
        pantiltmotors: String = settings::uses("pantiltmotors", "the head it points (none: no head)"),
        pantiltencoders: String = settings::uses("pantiltencoders", "the head angles it shows (none: none)"),
        camera: String = settings::uses(
            "camera",
            "the image it shows (4.3.1 used varcolorX; none: none)",
        )
        .default("varcolorA"),
    }
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
    let l: Lines = conf.read()?;
    let names = operator::interface_names(
        conf,
        rt,
        &l.motors,
        &[&l.pantiltmotors, &l.pantiltencoders, &l.camera],
        "the simulator, player, networkclient ...",
    )?;
    let ifs = &rt.interfaces;
    let get = |i: usize| names[i].as_deref();
    let dev = Devices {
        motors: ifs.get(get(0).unwrap_or_default())?,
        ptmotors: get(1).map(|n| ifs.get(n)).transpose()?,
        ptencoders: get(2).map(|n| ifs.get(n)).transpose()?,
        camera: get(3).map(|n| ifs.get(n)).transpose()?,
    };
    let lines = CommandLines {
        keys: ("walk", "head"),
        max: (l.max_v, l.max_w),
        base: l.walk,
        head: l.head,
        cycle: l.cycle,
    };
    let children = names.into_iter().flatten().collect();
    #[cfg_attr(not(feature = "gui"), allow(unused_mut))]
    let mut schema = Operator::from_lines(
        rt,
        conf,
        lines,
        dev.motors.clone(),
        dev.ptmotors.clone(),
        children,
    );
    #[cfg(feature = "gui")]
    {
        let commands = schema.commands.clone();
        schema.panel = Some(Box::new(panel::NaoPanel::new(commands, dev)));
    }
    Ok(Box::new(schema))
}

crate::register_schema!(
    "naooperator",
    "teleoperates a walking robot: walk (v, w), head (pan-tilt) and camera in one panel",
    create,
    lines = Lines
);

#[cfg(feature = "gui")]
mod panel {
    //! The joystick (walk), the head positioner and the camera image.

    use std::sync::Arc;

    use egui::vec2;

    use crate::{
        operator::controls::{self, Controls},
        runtime::{Panel, Runtime},
        widgets::ImageView,
    };

    use super::Devices;
    use crate::operator::Commands;

    pub struct NaoPanel {
        dev: Devices,
        controls: Controls,
        image: ImageView,
    }

    impl NaoPanel {
        pub fn new(commands: Arc<Commands>, dev: Devices) -> Self {
            let labels = ("naooperator walk", "naooperator head");
            NaoPanel {
                controls: Controls::new(commands, labels, dev.ptmotors.as_deref()),
                dev,
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
                self.controls.speeds_and_stop(ui, "walk ", &self.dev.motors);
            });
            ui.horizontal_top(|ui| {
                ui.vertical(|ui| self.controls.show(ui, ("walk", "head"), head));
                ui.vertical(|ui| {
                    ui.label("camera");
                    match &self.dev.camera {
                        Some(c) => controls::camera(ui, &mut self.image, c, vec2(320.0, 240.0)),
                        None => {
                            ui.small("(no camera interface)");
                        }
                    }
                });
            });
        }
    }
}
