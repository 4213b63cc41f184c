//! introrob's controller, free of interfaces and threads: the [`Behaviour`]s,
//! the [`Dashboard`] the operator and the brain share, and the [`Brain`] that turns
//! one iteration's [`Inputs`] into a motors command (VFF, GPP, teleoperation or
//! your code). Tests drive it against a stepped simulation, the schema
//! ([`super::Introrob`]) against the live interfaces.

use std::{fmt, str::FromStr, sync::Arc};

use parking_lot::Mutex;

use crate::{
    interfaces::{Bumpers, Encoders, Image, Laser, Motors, Sonars},
    world::World,
};

use super::{
    gpp::{self, Follower, GridMap, PlanParams},
    navigation::{self, Drawing, Robot, YourState},
    vff::{self, Forces, VffParams},
};

/// What introrob does each iteration.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Behaviour {
    #[default]
    Teleop,
    Stop,
    Vff,
    Gpp,
    YourCode,
}

impl Behaviour {
    pub const ALL: [Behaviour; 5] = [
        Behaviour::Teleop,
        Behaviour::Stop,
        Behaviour::Vff,
        Behaviour::Gpp,
        Behaviour::YourCode,
    ];
    pub fn as_str(self) -> &'static str {
        match self {
            Behaviour::Teleop => "teleop",
            Behaviour::Stop => "stop",
            Behaviour::Vff => "vff",
            Behaviour::Gpp => "gpp",
            Behaviour::YourCode => "yourcode",
        }
    }
}

impl fmt::Display for Behaviour {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Behaviour {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Ok(match s.to_ascii_lowercase().as_str() {
            "teleop" | "teleoperated" | "teleoperation" => Behaviour::Teleop,
            "stop" => Behaviour::Stop,
            "vff" => Behaviour::Vff,
            "gpp" => Behaviour::Gpp,
            "yourcode" | "your_code" => Behaviour::YourCode,
            _ => {
                return Err(format!(
                    "unknown behaviour `{s}`; expected teleop, stop, vff, gpp or yourcode"
                ));
            }
        })
    }
}

/// What the panel shows of the last iteration.
#[derive(Clone, Debug, Default)]
pub struct View {
    /// The planned path (gpp), world mm.
    pub path: Vec<[f32; 2]>,
    /// The point the follower steers to (gpp).
    pub carrot: Option<[f32; 2]>,
    /// The VFF forces (vff, gpp), robot frame.
    pub forces: Option<Forces>,
    /// What your code drew.
    pub drawings: Vec<Drawing>,
    /// One line: what the behaviour is doing.
    pub status: String,
    /// The last command written.
    pub command: Motors,
    /// The pose of the last iteration.
    pub pose: Encoders,
}

/// introrob's dashboard, shared by the brain, the panel, the shell and the name
/// space (exported as `introrob.state`): what the operator sets (the behaviour,
/// the target, the teleoperation command within the maxima), the map, and what
/// the brain reports of its last iteration ([`View`]).
pub struct Dashboard {
    pub behaviour: Arc<Mutex<Behaviour>>,
    pub target: Arc<Mutex<Option<[f32; 2]>>>,
    pub teleop: Arc<Mutex<Motors>>,
    pub view: Mutex<View>,
    /// The world (walls for the world view, the map for gpp), if known: from
    /// introrob's `world FILE` line or the exported `world.map`.
    pub world: Option<Arc<World>>,
    pub max_v: f32,
    pub max_w: f32,
}

impl Dashboard {
    /// A fresh state (not exported).
    pub fn new(world: Option<Arc<World>>, max_v: f32, max_w: f32) -> Arc<Dashboard> {
        Arc::new(Dashboard {
            behaviour: Arc::new(Mutex::new(Behaviour::default())),
            target: Arc::new(Mutex::new(None)),
            teleop: Arc::new(Mutex::new(Motors::default())),
            view: Mutex::new(View::default()),
            world,
            max_v,
            max_w,
        })
    }
    pub fn set_behaviour(&self, b: Behaviour) {
        *self.behaviour.lock() = b;
    }
    pub fn set_target(&self, t: Option<[f32; 2]>) {
        *self.target.lock() = t;
    }
    /// Sets the teleoperation command (clamped to the maxima).
    pub fn set_teleop(&self, v: f32, w: f32) {
        *self.teleop.lock() = Motors::limited(v, w, self.max_v, self.max_w);
    }
}

/// What the brain gets each iteration.
pub struct Inputs<'a> {
    pub pose: Encoders,
    pub laser: &'a Laser,
    pub sonars: Option<&'a Sonars>,
    pub bumpers: Option<&'a Bumpers>,
    pub image: Option<&'a Image>,
    /// Seconds since introrob started.
    pub time: f64,
}

/// introrob's controller, free of interfaces and threads: tests drive it against
/// a stepped simulation, the schema against the live interfaces.
pub struct Brain {
    pub dashboard: Arc<Dashboard>,
    pub vff: VffParams,
    pub plan: PlanParams,
    /// gpp grid cell, mm.
    pub cell: f32,
    map: Option<Arc<GridMap>>,
    follower: Option<(Option<[f32; 2]>, Follower)>,
    your: YourState,
    robot: Robot,
    last: Behaviour,
}

impl Brain {
    pub fn new(dashboard: Arc<Dashboard>) -> Brain {
        let vff = VffParams {
            max_v: dashboard.max_v,
            max_w: dashboard.max_w,
            ..VffParams::default()
        };
        Brain {
            dashboard,
            vff,
            plan: PlanParams::default(),
            cell: 50.0,
            map: None,
            follower: None,
            your: YourState::default(),
            robot: Robot::default(),
            last: Behaviour::Teleop,
        }
    }

    /// The gpp map (built from the world on first use).
    pub fn map(&mut self) -> Option<Arc<GridMap>> {
        if self.map.is_none()
            && let Some(w) = &self.dashboard.world
        {
            self.map = Some(Arc::new(GridMap::from_world(w, self.cell)));
        }
        self.map.clone()
    }

    /// One iteration: the command to write to the motors.
    pub fn step(&mut self, input: &Inputs) -> Motors {
        let behaviour = *self.dashboard.behaviour.lock();
        let target = *self.dashboard.target.lock();
        if behaviour != self.last {
            self.follower = None;
            self.last = behaviour;
        }
        let mut view = View {
            pose: input.pose,
            ..View::default()
        };
        let m = match behaviour {
            Behaviour::Teleop => {
                view.status = "teleoperated".into();
                *self.dashboard.teleop.lock()
            }
            Behaviour::Stop => {
                view.status = "stopped".into();
                Motors::default()
            }
            Behaviour::Vff => match target {
                None => {
                    view.status = "vff: no target (click in the world view)".into();
                    Motors::default()
                }
                Some(t) => {
                    let out = vff::command(&input.pose, input.laser, t, &self.vff);
                    view.forces = Some(out.forces);
                    view.status = if out.arrived {
                        "vff: target reached".into()
                    } else {
                        format!("vff: going to ({:.0}, {:.0})", t[0], t[1])
                    };
                    out.motors
                }
            },
            Behaviour::Gpp => self.gpp(input, target, &mut view),
            Behaviour::YourCode => {
                let r = &mut self.robot;
                r.robot = input.pose.robot();
                r.laser.clone_from(input.laser);
                r.sonars.clear();
                if let Some(s) = input.sonars {
                    r.sonars.extend_from_slice(&s.us);
                }
                r.bumpers.clear();
                if let Some(b) = input.bumpers {
                    r.bumpers.extend_from_slice(&b.bumpers);
                }
                r.image = input.image.cloned();
                r.target = target.unwrap_or([r.robot[0], r.robot[1]]);
                r.time = input.time;
                r.drawings.clear();
                navigation::your_code(r, &mut self.your);
                view.drawings = r.drawings.clone();
                view.status = "your code".into();
                let m = Motors { v: r.v, w: r.w };
                r.image = None;
                m
            }
        };
        let m = Motors::limited(m.v, m.w, self.dashboard.max_v, self.dashboard.max_w);
        self.robot.v = m.v;
        self.robot.w = m.w;
        view.command = m;
        *self.dashboard.view.lock() = view;
        m
    }

    fn gpp(&mut self, input: &Inputs, target: Option<[f32; 2]>, view: &mut View) -> Motors {
        let Some(goal) = target else {
            view.status = "gpp: no goal (click in the world view)".into();
            return Motors::default();
        };
        let here = [input.pose.x, input.pose.y];
        let replan = match &self.follower {
            Some((g, _)) => *g != Some(goal),
            None => true,
        };
        if replan {
            let Some(map) = self.map() else {
                view.status =
                    "gpp needs a map: give introrob a `world FILE` line, or load a driver that \
                               exports one as world.map (the simulator does)"
                        .into();
                return Motors::default();
            };
            match gpp::plan(&map, here, goal, &self.plan) {
                Ok(path) => self.follower = Some((Some(goal), Follower::new(path, 500.0))),
                Err(e) => {
                    // Remember the failure for this goal so we do not plan every cycle.
                    self.follower = Some((Some(goal), Follower::new(Vec::new(), 500.0)));
                    view.status = format!("gpp: {e}");
                    return Motors::default();
                }
            }
        }
        let Some((_, f)) = &mut self.follower else {
            return Motors::default();
        };
        if f.path.is_empty() {
            view.status = "gpp: no path to the goal".into();
            return Motors::default();
        }
        let out = f.step(&input.pose, input.laser, &self.vff);
        view.path = f.path.clone();
        view.carrot = Some(out.carrot);
        view.forces = Some(out.forces);
        if out.lost {
            // Off the path (pushed away): plan again next iteration.
            self.follower = None;
        }
        view.status = if out.done {
            "gpp: goal reached".into()
        } else {
            format!(
                "gpp: following a {}-point path to ({:.0}, {:.0})",
                view.path.len(),
                goal[0],
                goal[1]
            )
        };
        out.motors
    }
}
