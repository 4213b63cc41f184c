//! The operator core that teleoperator and naooperator share: a base command
//! (v mm/s, w deg/s, limited to the joystick's maxima) and a head command (pan-tilt
//! longitude and latitude, deg), the name-space cells through which their panels and
//! scripts set them, the lines that declare them, and the iteration that writes
//! them: the base to `motors` every cycle (so it never goes stale), the head to
//! `pantiltmotors` when it changes, and zero to `motors` on stop.
//!
//! Building one: [`interface_names`] resolves the interfaces its lines name (motors
//! required), [`Operator::from_lines`] makes the shared commands and the schema;
//! with the GUI, [`controls`] draws what both panels show (the joystick and its
//! STOP, the head positioner, the camera image).

use std::{sync::Arc, time::Duration};

use parking_lot::Mutex;

use crate::{
    conf::{
        ComponentConf,
        settings::{Setting, float},
    },
    interfaces::{Interface, Motors, PtMotors},
    namespace::Namespace,
    runtime::{Context, Runtime, Schema},
};

/// The joystick's maximum speed, `max_v V`.
pub const MAX_V: Setting = Setting::new(
    "max_v",
    "the joystick's maximum speed",
    &[float("V", "mm/s", 1.0, 1000.0)],
)
.default("500");
/// The joystick's maximum turn rate, `max_w W`.
pub const MAX_W: Setting = Setting::new(
    "max_w",
    "the joystick's maximum turn rate",
    &[float("W", "deg/s", 1.0, 180.0)],
)
.default("30");
/// An initial base command, `KEY V W` (teleoperator's `base`, naooperator's `walk`).
pub const BASE: Setting = Setting::new(
    "base",
    "the initial base command (limited to max_v and max_w)",
    &[
        float("V", "mm/s", -1000.0, 1000.0),
        float("W", "deg/s", -180.0, 180.0),
    ],
)
.default("0 0");
/// An initial head command, `KEY LONGITUDE LATITUDE` (teleoperator's `pantilt`,
/// naooperator's `head`); the unit clamps it to its own limits.
pub const HEAD: Setting = Setting::new(
    "pantilt",
    "the initial pan-tilt command (the unit clamps it to its limits)",
    &[
        float("LONGITUDE", "deg", -180.0, 180.0),
        float("LATITUDE", "deg", -90.0, 90.0),
    ],
)
.default("0 0");

/// The commands a schema, its panel and the name space share.
pub struct Commands {
    pub base: Arc<Mutex<Motors>>,
    pub head: Arc<Mutex<[f32; 2]>>,
    pub max_v: f32,
    pub max_w: f32,
}

impl Commands {
    /// The commands of `component`, shared through the name space under
    /// `base_key` (`Mutex<Motors>`) and `head_key` (`Mutex<[f32; 2]>`): imported
    /// when somebody exported them first, exported otherwise. Starts at `base` and
    /// `head`.
    pub fn shared(
        names: &Namespace,
        component: &str,
        (base_key, head_key): (&str, &str),
        (max_v, max_w): (f32, f32),
        base: (f32, f32),
        head: (f32, f32),
    ) -> Commands {
        fn cell<T: Send + Sync + Default + 'static>(
            names: &Namespace,
            c: &str,
            key: &str,
        ) -> Arc<Mutex<T>> {
            names.import::<Mutex<T>>(c, key).unwrap_or_else(|_| {
                let a = Arc::new(Mutex::new(T::default()));
                let _ = names.export_arc(c, key, a.clone());
                a
            })
        }
        let c = Commands {
            base: cell(names, component, base_key),
            head: cell(names, component, head_key),
            max_v,
            max_w,
        };
        c.set_base(base.0, base.1);
        c.set_head(head.0, head.1);
        c
    }
    /// Sets the base command, limited to the maxima.
    pub fn set_base(&self, v: f32, w: f32) {
        *self.base.lock() = Motors::limited(v, w, self.max_v, self.max_w);
    }
    /// Sets the head command (a non-finite angle counts as 0; the unit clamps the
    /// rest to its limits).
    pub fn set_head(&self, longitude: f32, latitude: f32) {
        let fin = |x: f32| if x.is_finite() { x } else { 0.0 };
        *self.head.lock() = [fin(longitude), fin(latitude)];
    }
}

/// An operator schema: it writes the commands to the robot (the base every
/// iteration, the head when it changed, zero on stop), runs the interfaces it
/// uses as its children, and hands out its panel.
pub struct Operator {
    pub commands: Arc<Commands>,
    pub motors: Arc<Interface<Motors>>,
    pub head: Option<Arc<Interface<PtMotors>>>,
    /// The interfaces it uses, run as its children.
    pub children: Vec<String>,
    pub cycle: Duration,
    #[cfg(feature = "gui")]
    pub panel: Option<Box<dyn crate::runtime::Panel>>,
    last_head: Option<[f32; 2]>,
}

/// The interfaces an operator uses, by the names its lines give (in `lines`
/// order, `motors` first). Motors is required: `none` or a name nothing provides
/// is an error at its line, `hint` saying what to load. The others are `None` when
/// `none` or not provided.
pub fn interface_names(
    conf: &ComponentConf,
    rt: &Runtime,
    motors: &str,
    others: &[&str],
    hint: &str,
) -> anyhow::Result<Vec<Option<String>>> {
    let name = |n: &str| (n != "none" && rt.interfaces.contains(n)).then(|| n.to_string());
    if name(motors).is_none() {
        anyhow::bail!(
            "{}: {} needs a motors interface (`{motors}` is not provided); load a driver \
             that provides it ({hint}) before {}",
            conf.line("motors")
                .map(|l| l.at.to_string())
                .unwrap_or_else(|| conf.file.display().to_string()),
            conf.name,
            conf.name,
        );
    }
    Ok(std::iter::once(motors)
        .chain(others.iter().copied())
        .map(name)
        .collect())
}

/// The lines that make an operator's commands: the name-space keys of the base and
/// the head, the maxima, the initial base and head commands, the cycle (ms).
pub struct CommandLines {
    pub keys: (&'static str, &'static str),
    pub max: (f32, f32),
    pub base: (f32, f32),
    pub head: (f32, f32),
    pub cycle: u64,
}

impl Operator {
    /// An operator of `conf`'s component with its commands shared through the name
    /// space, writing to `motors` and `head`, running `children`.
    pub fn from_lines(
        rt: &Runtime,
        conf: &ComponentConf,
        lines: CommandLines,
        motors: Arc<Interface<Motors>>,
        head: Option<Arc<Interface<PtMotors>>>,
        children: Vec<String>,
    ) -> Operator {
        let commands = Arc::new(Commands::shared(
            &rt.names, &conf.name, lines.keys, lines.max, lines.base, lines.head,
        ));
        Operator::new(
            commands,
            motors,
            head,
            children,
            Duration::from_millis(lines.cycle),
        )
    }

    pub fn new(
        commands: Arc<Commands>,
        motors: Arc<Interface<Motors>>,
        head: Option<Arc<Interface<PtMotors>>>,
        children: Vec<String>,
        cycle: Duration,
    ) -> Operator {
        Operator {
            commands,
            motors,
            head,
            children,
            cycle,
            #[cfg(feature = "gui")]
            panel: None,
            last_head: None,
        }
    }
}

impl Schema for Operator {
    fn cycle(&self) -> Duration {
        self.cycle
    }
    fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
        ctx.run_children(&self.children, None)?;
        // The head is written again at the next iteration.
        self.last_head = None;
        Ok(())
    }
    fn iteration(&mut self, _ctx: &Context) -> anyhow::Result<()> {
        let base = *self.commands.base.lock();
        self.motors.publish(base).map_err(anyhow::Error::msg)?;
        let head = *self.commands.head.lock();
        if let Some(ptm) = &self.head
            && self.last_head != Some(head)
        {
            ptm.point(head[0], head[1])?;
            self.last_head = Some(head);
        }
        Ok(())
    }
    fn on_stop(&mut self, _ctx: &Context) {
        let _ = self.motors.publish(Motors::default());
    }
    #[cfg(feature = "gui")]
    fn panel(&mut self) -> Option<Box<dyn crate::runtime::Panel>> {
        self.panel.take()
    }
}

/// What both operators' panels show: the base joystick with its STOP, the head
/// positioner, the camera image.
#[cfg(feature = "gui")]
pub mod controls {
    use std::sync::Arc;

    use egui::vec2;

    use crate::{
        interfaces::{Image, Interface, Motors, PtMotors},
        widgets::{ImageView, Joystick, PanTiltLimits, PanTiltPad},
    };

    use super::Commands;

    /// The joystick (the base) and, with a head, its positioner.
    pub struct Controls {
        pub commands: Arc<Commands>,
        pub joystick: Joystick,
        pub pad: Option<PanTiltPad>,
    }

    impl Controls {
        /// `labels`: the joystick's and the positioner's; the positioner starts at
        /// the head command, within the limits `head` publishes.
        pub fn new(
            commands: Arc<Commands>,
            (joystick, pad): (&str, &str),
            head: Option<&Interface<PtMotors>>,
        ) -> Controls {
            let pad = head.map(|m| {
                let mut p = PanTiltPad::new(pad, PanTiltLimits::from(&m.read().value));
                let h = *commands.head.lock();
                (p.longitude, p.latitude) = (h[0], h[1]);
                p
            });
            Controls {
                joystick: Joystick::new(joystick, commands.max_v, commands.max_w),
                commands,
                pad,
            }
        }

        /// The base's speeds (`what` names it) and the STOP button, which zeroes
        /// the base command and the joystick.
        pub fn speeds_and_stop(
            &mut self,
            ui: &mut egui::Ui,
            what: &str,
            motors: &Interface<Motors>,
        ) {
            let m = motors.read().value;
            ui.label(format!("{what}v {:.0} mm/s  w {:.1} deg/s", m.v, m.w));
            if ui.button("STOP").clicked() {
                self.commands.set_base(0.0, 0.0);
                self.joystick.v = 0.0;
                self.joystick.w = 0.0;
            }
        }

        /// The joystick under `base` and the positioner under `head` (showing the
        /// head's angles `actual`), each setting its command when moved.
        pub fn show(
            &mut self,
            ui: &mut egui::Ui,
            (base, head): (&str, &str),
            actual: Option<(f32, f32)>,
        ) {
            ui.label(base);
            if self.joystick.show(ui, 140.0).changed() {
                self.commands.set_base(self.joystick.v, self.joystick.w);
            }
            if let Some(pad) = &mut self.pad {
                ui.label(head);
                if pad.show(ui, vec2(140.0, 90.0), actual).changed() {
                    self.commands.set_head(pad.longitude, pad.latitude);
                }
            }
        }
    }

    /// The latest image of `camera` in `view`, `size` points ("(no image yet)"
    /// before the first).
    pub fn camera(
        ui: &mut egui::Ui,
        view: &mut ImageView,
        camera: &Interface<Image>,
        size: egui::Vec2,
    ) {
        let s = camera.snapshot();
        ui.allocate_ui(size, |ui| {
            if s.clock > 0 {
                view.show_sample(ui, &s);
            } else {
                ui.small("(no image yet)");
            }
        });
    }
}
