//! The operator core that teleoperator and naooperator share: a base command
//! (v mm/s, w deg/s, limited to the joystick's maxima) and a head command (pan-tilt
//! longitude and latitude, deg), the name-space cells through which their panels and
//! scripts set them, the lines that declare them, and the iteration that writes
//! them: the base to `motors` every cycle (so it never goes stale), the head to
//! `pantiltmotors` when it changes, and zero to `motors` on stop.

use std::{sync::Arc, time::Duration};

use parking_lot::Mutex;

use crate::{
    conf::settings::{Setting, float},
    interfaces::{Interface, Motors, PtMotors},
    namespace::Namespace,
    runtime::{Context, Schema},
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

impl Operator {
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
