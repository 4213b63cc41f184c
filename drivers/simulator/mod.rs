//! simulator: Pioneer-like robots in a 2D world (2.5D for the camera), so every
//! robot and vision schema runs with no hardware.
//!
//! The core is a plain struct, [`Sim`] (a [`World`](crate::world::World) plus
//! robots and balls), that [`Sim::step`] advances deterministically; the driver runs it on a thread in real
//! time (or `speed N` times faster, or lock-stepped with the controller) and
//! publishes the interfaces below. See `docs/simulator.md` and
//! `examples/simulator.conf`.
//!
//! # Interfaces (the seed's names, layouts and units)
//! | interface | what |
//! |---|---|
//! | `encoders` | odometry: x, y mm, θ rad in (0, 2π], cos θ, sin θ; starts at the robot's pose |
//! | `motors` | v mm/s (\|v\| ≤ 1000), w deg/s counter-clockwise (\|w\| ≤ 180); a command older than `motors_timeout` counts as zero |
//! | `laser` | N readings (180 by default) at R per degree (1), mm, max 8000; reading i at −90 + i/R deg; the laser is at (19, 0) mm on the robot |
//! | `sonars` | the 16-sonar Pioneer ring (positions of R430 libs/pioneer), mm, max 5000 |
//! | `bumpers` | 10 bytes: 5 front (left to right), 5 rear (right to left); 1 = touching |
//! | `colorA..D` | 320x240 BGR image from the camera on the pan-tilt unit |
//! | `varcolorA..D` | the same camera at any size (`provides varcolorA W H`) |
//! | `pantiltencoders` | pan_angle, tilt_angle deg (pan counter-clockwise, tilt up) |
//! | `pantiltmotors` | longitude, latitude deg; longitude_speed, latitude_speed deg/s (0 = the unit's maximum); limits of the Directed Perception PTU: pan ±159.13, tilt −46..+30, 205.89 deg/s |
//! | `imu` | the true heading as a quaternion about z (no odometry drift), turn rate rad/s, and an accelerometer's reading m/s²: forward dv/dt, centripetal v·ω to the left, gravity 9.81 up; 50 Hz |
//!
//! The camera sits on the pan-tilt unit at the Pioneer camera position (190, 0) mm,
//! 500 mm above the floor, 65° horizontal field of view; it uses progeo's pinhole
//! model (`position`, `foa`, `fx = fy`, `u0 = rows/2`, `v0 = columns/2`).
//!
//! # Conf
//! ```text
//! driver simulator
//! world assets/worlds/simple.world   # world file (relative to this conf file); none = an empty plane
//! robot robot1 1000 1000 90          # NAME X_MM Y_MM THETA_DEG, repeatable; the first robot's
//!                                    # interfaces have plain names, the others' get a .NAME suffix
//! initial_position 1000 1000 90      # the seed's player line: the first robot's pose
//! provides encoders                  # encoders, motors, sonars, bumpers, pantiltencoders,
//! provides motors                    #   pantiltmotors, imu, colorA..D [ROBOT]
//! provides laser 180 1               # laser [N RESOLUTION] [ROBOT]
//! provides varcolorA 640 480         # varcolorA..D [W H] [ROBOT]
//! provides laser robot2              # robot2's laser: interface laser.robot2
//! motors_timeout 500                 # ms; a stale motors command counts as zero
//! speed 1                            # real time (default); N = N times faster; max = as fast as possible
//! stepped 100                        # instead of speed: advance 100 ms per new motors command
//! seed 1                             # noise seed
//! step 10                            # physics step, ms
//! period laser 100                   # publishing period (ms) of encoders, laser, sonars,
//!                                    #   bumpers, camera, pantiltencoders, imu
//! noise odometry 0.02 0.01           # odometry: σ of distance and turn, as fractions
//! noise laser 10                     # σ, mm (also: noise sonars MM); no noise by default
//! accel 300 100                      # mm/s², deg/s² (a Pioneer's defaults)
//! radius 250                         # robot radius, mm
//! laser_range 8000                   # mm
//! camera_height 500                  # mm; camera_fov 65 (deg)
//! camera_tilt -20                    # deg: the pan-tilt unit's tilt at the start (-46..30; 0)
//! score lap                          # the exercise's score: swept, targets, lap or none (default)
//! publish_always off                 # on: compute laser, sonars and camera even when unused
//! end_driver
//! ```
//! The laser, sonars and cameras are computed only while someone uses them
//! (resume/suspend), unless `publish_always on`.
//!
//! # Name space
//! The driver exports its world under the documented keys of [`crate::world`]:
//! `world.map`, the static [`World`](crate::world::World) (walls, boxes, where
//! balls start), and `world.balls`, the balls as they roll
//! ([`LiveBalls`], refreshed at the encoders' period). Schemas read them with
//! [`crate::world::map`] and [`crate::world::balls`], whichever driver exported
//! them. With a `score` line it keeps that score (the rules of
//! [`crate::world::scoring`]) from the first robot's true pose after each step and
//! exports it as `world.score` ([`LiveScore`](crate::world::LiveScore), refreshed at the
//! encoders' period; [`crate::world::score`] reads it); a world that lacks what the
//! score needs (targets, a closed painted line, walls) is an error at the `score`
//! line. When it does not run in real time (`speed` other than 1, `max`,
//! `stepped`), it also exports its simulated time as the run's clock, `run.clock`
//! ([`RunClock`]): the simulator's start time plus the simulated seconds (the
//! `ros2` service publishes it on `/clock`).
//!
//! # Files
//! - [`conf`]: the conf lines above → a [`Simulation`] ready to run.
//! - [`driver`]: the thread that runs it and publishes the interfaces.
//! - [`physics`]: [`Sim`], robots, balls and collisions, stepped deterministically.
//! - [`sensors`]: laser, sonars and bumpers; [`camera`]: the camera and its renderer.
//! - The world file format, geometry and grid are [`crate::world`]'s.

pub mod camera;
pub mod conf;
pub mod driver;
pub mod physics;
pub mod sensors;

use crate::{
    conf::ComponentConf,
    runtime::{Driver, RunClock, Runtime},
    world::{self, LiveBalls},
};

pub use camera::Renderer;
pub use conf::{Clock, Periods, Provides, Simulation};
pub use driver::SimDriver;
pub use physics::{Noise, Pose, Rng, Robot, RobotModel, Sim};

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let mut simulation = Simulation::parse(conf)?;
    if !matches!(simulation.clock, Clock::Speed(s) if s == 1.0) {
        match RunClock::export(&rt.names, matches!(simulation.clock, Clock::Stepped(_))) {
            Ok(c) => simulation.run_clock = Some(c),
            Err(e) => tracing::warn!("simulator: its time is not the run's clock: {e}"),
        }
    }
    if let Some(score) = simulation.sim.score() {
        match world::export_score(&rt.names, score.clone()) {
            Ok(live) => simulation.live_score = Some(live),
            Err(e) => tracing::warn!("simulator: the score is not exported: {e}"),
        }
    }
    let balls = simulation.sim.balls.clone();
    // The first exporter of the world keeps the keys; a second one warns and runs
    // with balls nobody else sees.
    if let Err(e) = world::export_map(&rt.names, simulation.sim.world.clone()) {
        tracing::warn!("simulator: the world map is not exported: {e}");
    }
    let balls = world::export_balls(&rt.names, balls.clone()).unwrap_or_else(|e| {
        tracing::warn!("simulator: the balls are not exported: {e}");
        std::sync::Arc::new(LiveBalls::from_pointee(balls))
    });
    Ok(Box::new(SimDriver::start(
        simulation,
        &rt.interfaces,
        &conf.name,
        balls,
    )?))
}

crate::register_driver!(
    Driver,
    "simulator",
    "simulated Pioneer robots in a 2D world: encoders, motors, laser, sonars, bumpers, camera, pan-tilt",
    create,
    lines = conf::Lines
);
