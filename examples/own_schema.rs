//! Your own schema in your own crate.
//!
//! A crate that depends on `jderobot` registers schemas with
//! `jderobot::register_schema!` and calls `jderobot::cli::main()`: the result is the
//! whole jderobot binary (conf loader, shell, GUI, drivers) plus your schemas, which
//! `jderobot list` shows and a conf loads like any other.
//!
//! ```sh
//! cargo run --example own_schema -- examples/own_schema.conf
//! ```
//!
//! This schema, `wanderer`, reads the laser and drives the robot: forward when the
//! way ahead is clear, turning away from the nearer side when it is not.
//!
//! Its lines are declared once (`jderobot::declare_lines!`: each field of the struct
//! that receives them beside its declaration; the struct derives serde's
//! `Deserialize`, so your crate depends on `serde`): `jderobot check` validates them and
//! `cargo run --example own_schema -- help wanderer` prints them, with their units,
//! ranges and defaults. A value out of range is an error at its file:line.

use std::time::Duration;

use jderobot::{
    Context, Runtime, Schema,
    conf::{
        ComponentConf,
        settings::{CYCLE, Setting, float},
    },
    interfaces::{Laser, Motors},
};

jderobot::declare_lines! {
    /// The lines `wanderer` takes: key, arguments (type, unit, range), default, help.
    struct Lines {
        clearance: f32 = Setting::new(
            "clearance",
            "the closest an obstacle ahead may be before the robot turns",
            &[float("MM", "mm", 1.0, 10_000.0)],
        )
        .default("700"),
        cycle: u64 = CYCLE.default("100"),
    }
}
struct Wanderer {
    /// Closest allowed obstacle ahead, mm.
    clearance: f32,
    cycle: Duration,
}

impl Schema for Wanderer {
    fn cycle(&self) -> Duration {
        self.cycle
    }

    fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
        // Running the interfaces as children resumes them (the driver computes the
        // laser only while someone uses it) and suspends them when we stop.
        ctx.run_children(&["laser", "motors"], None)?;
        Ok(())
    }

    fn iteration(&mut self, ctx: &Context) -> anyhow::Result<()> {
        let laser = ctx.interfaces().get::<Laser>("laser")?;
        let motors = ctx.interfaces().get::<Motors>("motors")?;
        let scan = laser.read();
        let n = scan.readings.len();
        if n == 0 {
            return Ok(());
        }
        // Readings run from the robot's right (index 0) to its left; the middle third
        // looks ahead.
        let ahead = scan.readings[n / 3..2 * n / 3]
            .iter()
            .copied()
            .min()
            .unwrap_or(0) as f32;
        let right: i64 = scan.readings[..n / 2].iter().map(|&r| r as i64).sum();
        let left: i64 = scan.readings[n / 2..].iter().map(|&r| r as i64).sum();
        let command = if ahead > self.clearance {
            Motors { v: 300.0, w: 0.0 }
        } else {
            Motors {
                v: 0.0,
                w: if left > right { 30.0 } else { -30.0 },
            }
        };
        motors.publish(command).map_err(anyhow::Error::msg)?;
        Ok(())
    }
}

fn create(conf: &ComponentConf, _rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let lines: Lines = conf.read()?;
    Ok(Box::new(Wanderer {
        clearance: lines.clearance,
        cycle: Duration::from_millis(lines.cycle),
    }))
}

jderobot::register_schema!(
    "wanderer",
    "example of a user's own schema: wanders, turning away from obstacles",
    create,
    "",
    lines = Lines
);

fn main() -> std::process::ExitCode {
    jderobot::cli::main()
}
