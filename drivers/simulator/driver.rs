//! The running driver: the thread that steps a [`Simulation`] in real time (or
//! faster, or lock-stepped with the controller), reads the motors and pan-tilt
//! commands and publishes each sensor at its period, computing the laser, sonars
//! and cameras only while someone uses them.

use std::{
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    time::{Duration, Instant},
};

use crate::{
    interfaces::{
        Bumpers, Encoders, Image, Imu, Interface, InterfaceValue, Interfaces, Laser, Motors,
        PtEncoders, PtMotors, Sonars,
    },
    runtime::{Driver, Worker},
    world::LiveBalls,
};

use super::{
    camera::Renderer,
    conf::{Clock, Simulation},
};

/// One robot's interfaces.
struct RobotInterfaces {
    encoders: Option<Arc<Interface<Encoders>>>,
    motors: Option<Arc<Interface<Motors>>>,
    laser: Option<Arc<Interface<Laser>>>,
    sonars: Option<Arc<Interface<Sonars>>>,
    bumpers: Option<Arc<Interface<Bumpers>>>,
    pantilt_encoders: Option<Arc<Interface<PtEncoders>>>,
    pantilt_motors: Option<Arc<Interface<PtMotors>>>,
    imu: Option<Arc<Interface<Imu>>>,
    cameras: Vec<(Arc<Interface<Image>>, u32, u32, Renderer)>,
}

/// What the simulator thread publishes to: each robot's interfaces and the balls.
struct Outputs {
    robots: Vec<RobotInterfaces>,
    balls: Arc<LiveBalls>,
}

/// The running driver: a thread that steps the simulation and publishes.
pub struct SimDriver {
    worker: Worker,
    motors: Vec<Arc<Interface<Motors>>>,
}

impl SimDriver {
    /// Provides the interfaces of `simulation` on `ifaces` and starts the thread, which also
    /// keeps `balls` up to date.
    pub fn start(
        simulation: Simulation,
        ifaces: &Interfaces,
        provider: &str,
        balls: Arc<LiveBalls>,
    ) -> anyhow::Result<SimDriver> {
        let mut robots = Vec::new();
        for (k, p) in simulation.provides.iter().enumerate() {
            let pt_limits = simulation.sim.robots[k].model.pantilt;
            let ri = RobotInterfaces {
                encoders: p
                    .encoders
                    .as_ref()
                    .map(|n| ifaces.provide_value(n, provider, simulation.sim.encoders(k)))
                    .transpose()?,
                motors: p
                    .motors
                    .as_ref()
                    .map(|n| ifaces.provide(n, provider))
                    .transpose()?,
                laser: p
                    .laser
                    .as_ref()
                    .map(|n| ifaces.provide(n, provider))
                    .transpose()?,
                sonars: p
                    .sonars
                    .as_ref()
                    .map(|n| ifaces.provide(n, provider))
                    .transpose()?,
                bumpers: p
                    .bumpers
                    .as_ref()
                    .map(|n| ifaces.provide(n, provider))
                    .transpose()?,
                pantilt_encoders: p
                    .pantiltencoders
                    .as_ref()
                    .map(|n| ifaces.provide(n, provider))
                    .transpose()?,
                pantilt_motors: p
                    .pantiltmotors
                    .as_ref()
                    .map(|n| ifaces.provide_value(n, provider, pt_limits))
                    .transpose()?,
                imu: p
                    .imu
                    .as_ref()
                    .map(|n| ifaces.provide(n, provider))
                    .transpose()?,
                cameras: p
                    .cameras
                    .iter()
                    .map(|(n, w, h)| {
                        ifaces
                            .provide_value(n, provider, Image::new(*w, *h))
                            .map(|i| (i, *w, *h, Renderer::new()))
                    })
                    .collect::<Result<_, _>>()?,
            };
            robots.push(ri);
        }
        let motors = robots.iter().filter_map(|r| r.motors.clone()).collect();
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = stop.clone();
        let worker = Worker::start("simulator", stop, move || {
            run(simulation, Outputs { robots, balls }, &stop2)
        })?;
        Ok(SimDriver { worker, motors })
    }
}

impl Driver for SimDriver {
    fn terminate(&mut self) {
        self.worker.stop();
        for m in &self.motors {
            let _ = m.publish(Motors::default());
        }
    }
}

impl Drop for SimDriver {
    fn drop(&mut self) {
        self.terminate();
    }
}

/// Next publishing times (simulated seconds).
#[derive(Default)]
struct NextPublish {
    encoders: f64,
    laser: f64,
    sonars: f64,
    bumpers: f64,
    camera: f64,
    pantilt_encoders: f64,
    imu: f64,
}

/// Whether a sensor is due at `now`; if so, moves its `next` time one `period` on
/// (skipping ahead after a stall).
fn is_due(next: &mut f64, now: f64, period: f64) -> bool {
    if now + 1e-9 >= *next {
        *next = (*next + period).max(now + period * 0.5);
        true
    } else {
        false
    }
}

/// Whether a sensor is worth computing: someone uses it, or `publish_always`.
fn used<T: InterfaceValue>(i: &Interface<T>, always: bool) -> bool {
    always || i.users() > 0
}

/// Publishes what is due after a step.
fn publish(simulation: &mut Simulation, out: &mut Outputs, next: &mut NextPublish) {
    let t = simulation.sim.time;
    if let Some(c) = &simulation.run_clock {
        c.set_elapsed(t);
    }
    let p = simulation.periods;
    let always = simulation.publish_always;
    let imu = is_due(&mut next.imu, t, p.imu);
    let (enc, las, son, bum, cam, pt) = (
        is_due(&mut next.encoders, t, p.encoders),
        is_due(&mut next.laser, t, p.laser),
        is_due(&mut next.sonars, t, p.sonars),
        is_due(&mut next.bumpers, t, p.bumpers),
        is_due(&mut next.camera, t, p.camera),
        is_due(&mut next.pantilt_encoders, t, p.pantiltencoders),
    );
    if enc && let (Some(out), Some(score)) = (&simulation.live_score, simulation.sim.score()) {
        out.store(Arc::new(score.clone()));
    }
    let sim = &mut simulation.sim;
    if enc && !sim.balls.is_empty() {
        out.balls.store(Arc::new(sim.balls.clone()));
    }
    for (k, r) in out.robots.iter_mut().enumerate() {
        if enc && let Some(i) = &r.encoders {
            let _ = i.publish(sim.encoders(k));
        }
        if pt && let Some(i) = &r.pantilt_encoders {
            let _ = i.publish(sim.pantilt_encoders(k));
        }
        if imu && let Some(i) = &r.imu {
            let _ = i.publish(sim.imu(k));
        }
        if bum && let Some(i) = &r.bumpers {
            let _ = i.write(|b| sim.bumpers(k, b));
        }
        if las
            && let Some(i) = &r.laser
            && used(i, always)
        {
            let _ = i.write(|l| sim.laser(k, l));
        }
        if son
            && let Some(i) = &r.sonars
            && used(i, always)
        {
            let _ = i.write(|s| sim.sonars(k, s));
        }
        if cam {
            for (i, w, h, rend) in &mut r.cameras {
                if used(i, always) {
                    let c = sim.camera(k, *w, *h);
                    let _ = i.write(|img| rend.render(sim, k, &c, img));
                }
            }
        }
    }
}

/// Reads the commands into the simulation.
fn commands(simulation: &mut Simulation, robots: &[RobotInterfaces], stepped: bool) {
    for (k, r) in robots.iter().enumerate() {
        if let Some(m) = &r.motors {
            let cmd = if stepped {
                m.read().value
            } else {
                m.command(simulation.motors_timeout)
            };
            simulation.sim.set_motors(k, cmd);
        }
        if let Some(p) = &r.pantilt_motors {
            let lim = simulation.sim.robots[k].model.pantilt;
            let c = p.read().value;
            simulation.sim.set_pantilt(
                k,
                PtMotors {
                    longitude: c.longitude,
                    latitude: c.latitude,
                    longitude_speed: c.longitude_speed,
                    latitude_speed: c.latitude_speed,
                    ..lim
                },
            );
        }
    }
}

/// The driver thread; says the score, if one is kept, when it ends.
fn run(mut simulation: Simulation, out: Outputs, stop: &AtomicBool) {
    step_until_stopped(&mut simulation, out, stop);
    if let Some(score) = simulation.sim.score() {
        tracing::info!(
            "simulator: score after {:.1} s: {}",
            simulation.sim.time,
            score.summary()
        );
    }
}

/// Steps and publishes until `stop`, at the simulation's clock.
fn step_until_stopped(simulation: &mut Simulation, mut out: Outputs, stop: &AtomicBool) {
    let dt = simulation.step;
    let mut next = NextPublish::default();
    commands(simulation, &out.robots, false);
    publish(simulation, &mut out, &mut next);
    match simulation.clock {
        Clock::Stepped(per) => {
            let steps = ((per / dt).round() as u64).max(1);
            let trigger = out.robots.iter().find_map(|r| r.motors.clone());
            // The interface was created with clock 0: any later value is a command.
            let mut seen = 0;
            while !stop.load(Ordering::Acquire) {
                let Some(m) = &trigger else {
                    std::thread::sleep(Duration::from_millis(20));
                    continue;
                };
                let c = m.clock();
                if c == seen {
                    std::thread::sleep(Duration::from_micros(500));
                    continue;
                }
                seen = c;
                commands(simulation, &out.robots, true);
                for _ in 0..steps {
                    simulation.sim.step(dt);
                    publish(simulation, &mut out, &mut next);
                }
            }
        }
        Clock::Speed(_) | Clock::Max => {
            let speed = match simulation.clock {
                Clock::Speed(s) => Some(s),
                _ => None,
            };
            let t0 = Instant::now();
            let mut done: u64 = 0; // steps counted against the wall clock
            // At most half a simulated second of catching up after a stall.
            let cap = ((0.5 / dt) as u64).max(1);
            while !stop.load(Ordering::Acquire) {
                let target = match speed {
                    Some(s) => (t0.elapsed().as_secs_f64() * s / dt) as u64,
                    None => done + 64,
                };
                if target <= done {
                    let s = speed.unwrap_or(1.0);
                    let wait =
                        ((done + 1) as f64 * dt / s - t0.elapsed().as_secs_f64()).clamp(0.0, 0.005);
                    std::thread::sleep(Duration::from_secs_f64(wait));
                    continue;
                }
                if target - done > cap {
                    done = target - cap;
                }
                while done < target && !stop.load(Ordering::Acquire) {
                    commands(simulation, &out.robots, false);
                    simulation.sim.step(dt);
                    publish(simulation, &mut out, &mut next);
                    done += 1;
                }
            }
        }
    }
}
