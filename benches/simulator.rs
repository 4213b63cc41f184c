//! Simulator benchmark: simulated seconds per wall second and camera frames per
//! second, medians over repetitions. Run with
//! `cargo bench --features full --bench simulator`.
//!
//! Goals (issue 5): one robot ≥ 1000x real time without the camera; a 320x240
//! camera ≥ 1000 frames/s.

mod common;
use common::median;

use std::{
    hint::black_box,
    path::{Path, PathBuf},
    time::Instant,
};

use jderobot::{
    drivers::simulator::{Renderer, RobotModel, Sim},
    interfaces::{Image, Laser, Motors, Sonars},
    world::World,
};

const DT: f64 = 0.01;
const REPS: usize = 7;

fn world(name: &str) -> World {
    let p: PathBuf =
        Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("assets/worlds/{name}.world"));
    World::load(&p).unwrap_or_else(|e| panic!("{e}"))
}

/// `n` robots wandering in `world`; every 100 ms of simulated time each publishes a
/// 180-reading laser scan and 16 sonars, and (if `camera`) renders a 320x240 frame.
/// Returns simulated seconds per wall second.
fn realtime_factor(world_name: &str, n: usize, camera: bool, sim_seconds: f64) -> f64 {
    let w = world(world_name);
    let starts: Vec<(f64, f64)> = match world_name {
        "building" => (0..n)
            .map(|k| (1500.0 + 1500.0 * k as f64, 7500.0))
            .collect(),
        _ => (0..n)
            .map(|k| {
                (
                    700.0 + 500.0 * (k % 5) as f64,
                    600.0 + 2700.0 * (k / 5) as f64,
                )
            })
            .collect(),
    };
    let runs: Vec<f64> = (0..REPS)
        .map(|_| {
            let mut sim = Sim::new(w.clone(), 1);
            for (k, &(x, y)) in starts.iter().enumerate() {
                sim.add_robot(&format!("r{k}"), RobotModel::default(), x, y, 90.0);
                sim.set_motors(
                    k,
                    Motors {
                        v: 400.0,
                        w: 15.0 + k as f32,
                    },
                );
            }
            let mut laser = Laser::default();
            let mut sonars = Sonars::default();
            let mut img = Image::new(320, 240);
            let mut rend = Renderer::new();
            let steps = (sim_seconds / DT).round() as usize;
            let t0 = Instant::now();
            for s in 0..steps {
                sim.step(DT);
                if s % 10 == 0 {
                    for k in 0..n {
                        sim.laser(k, &mut laser);
                        sim.sonars(k, &mut sonars);
                        if camera {
                            let cam = sim.camera(k, 320, 240);
                            rend.render(&sim, k, &cam, &mut img);
                        }
                    }
                    black_box((&laser, &sonars, &img));
                }
            }
            sim_seconds / t0.elapsed().as_secs_f64()
        })
        .collect();
    median(runs)
}

/// Frames per second of one robot's 320x240 camera, turning in place.
fn camera_fps(world_name: &str, x: f64, y: f64, frames: usize) -> f64 {
    let mut sim = Sim::new(world(world_name), 1);
    sim.add_robot("r", RobotModel::default(), x, y, 0.0);
    let mut img = Image::new(320, 240);
    let mut rend = Renderer::new();
    let runs: Vec<f64> = (0..REPS)
        .map(|_| {
            let t0 = Instant::now();
            for f in 0..frames {
                sim.robots[0].pose.theta = f as f64 * 0.05;
                sim.robots[0].tilt = -10.0 + (f % 20) as f64;
                let cam = sim.camera(0, 320, 240);
                rend.render(&sim, 0, &cam, &mut img);
                black_box(&img);
            }
            frames as f64 / t0.elapsed().as_secs_f64()
        })
        .collect();
    median(runs)
}

fn main() {
    if std::env::args().any(|a| a == "--list") {
        return; // `cargo test --benches` asks for the list of benchmarks
    }
    println!(
        "simulator benchmark: medians of {REPS} runs, physics step {} ms",
        DT * 1000.0
    );
    println!(
        "sensors at 10 Hz per robot: laser 180 readings, 16 sonars; camera 320x240 where noted"
    );
    let r = realtime_factor("simple", 1, false, 200.0);
    println!("  1 robot, simple.world, no camera:     {r:>10.0}x real time (goal >= 1000x)");
    let r = realtime_factor("building", 1, false, 200.0);
    println!("  1 robot, building.world, no camera:   {r:>10.0}x real time");
    let r = realtime_factor("simple", 1, true, 60.0);
    println!("  1 robot, simple.world, camera:        {r:>10.0}x real time");
    let r = realtime_factor("simple", 10, false, 60.0);
    println!("  10 robots, simple.world, no camera:   {r:>10.0}x real time");
    let r = realtime_factor("simple", 10, true, 10.0);
    println!("  10 robots, simple.world, camera:      {r:>10.0}x real time");
    let r = realtime_factor("building", 10, true, 10.0);
    println!("  10 robots, building.world, camera:    {r:>10.0}x real time");
    let f = camera_fps("simple", 1000.0, 2000.0, 2000);
    println!("  camera 320x240, simple.world:         {f:>10.0} frames/s (goal >= 1000)");
    let f = camera_fps("building", 1500.0, 7500.0, 2000);
    println!("  camera 320x240, building.world:       {f:>10.0} frames/s");
    let f = camera_fps("field", -2000.0, 0.0, 2000);
    println!("  camera 320x240, field.world:          {f:>10.0} frames/s");
}
