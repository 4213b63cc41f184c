//! pingpong: a parent schema with two children and an arbitration function.
//!
//! `pingpong` runs `ping` and `pong` as brothers. Both are always ready, so the
//! arbitration function decides which one iterates: it follows the parent's turn,
//! which the parent flips every `turn` iterations of its own. Only the winner
//! prints (`ping 3` / `pong 4`); `ps` shows the loser as `ready`. Stopping
//! `pingpong` stops both children.
//!
//! Conf (optional):
//! ```text
//! schema pingpong
//! turn 5           # parent iterations per turn (default 5)
//! end_schema
//! load_schema ping
//! load_schema pong
//! load_schema pingpong
//! run pingpong
//! ```
//! Interfaces: none. Exports `pingpong.turn` (`AtomicBool`, true = ping's turn).

use std::sync::{
    Arc,
    atomic::{AtomicBool, Ordering},
};
use std::time::Duration;

use crate::{
    conf::{
        ComponentConf,
        settings::{Setting, int},
    },
    runtime::{Context, Runtime, Schema},
};

/// The parent: flips the turn and arbitrates between its children.
pub struct PingPong {
    turn: Arc<AtomicBool>,
    every: u64,
    count: u64,
}

impl Schema for PingPong {
    fn cycle(&self) -> Duration {
        Duration::from_millis(100)
    }
    fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
        let turn = self.turn.clone();
        // The arbitration: among the ready brothers, pick the one whose turn it is.
        let arbitration = Arc::new(move |ready: &[&str]| {
            let wanted = if turn.load(Ordering::Acquire) {
                "ping"
            } else {
                "pong"
            };
            ready.iter().position(|n| *n == wanted).unwrap_or(0)
        });
        ctx.run_children(&["ping", "pong"], Some(arbitration))?;
        Ok(())
    }
    fn iteration(&mut self, _ctx: &Context) -> anyhow::Result<()> {
        self.count += 1;
        if self.count.is_multiple_of(self.every) {
            self.turn.fetch_xor(true, Ordering::AcqRel);
        }
        Ok(())
    }
}

/// A child: prints its name and how many times it has won.
pub struct Player {
    name: &'static str,
    wins: u64,
}

impl Schema for Player {
    fn cycle(&self) -> Duration {
        Duration::from_millis(100)
    }
    fn iteration(&mut self, ctx: &Context) -> anyhow::Result<()> {
        self.wins += 1;
        ctx.println(format!("{} {}", self.name, self.wins));
        Ok(())
    }
}

crate::declare_lines! {
    /// pingpong's lines, declared once (`jderobot help pingpong`).
    struct Lines {
        turn: u64 = Setting::new(
        "turn",
        "the parent's iterations per turn",
        &[int("N", "iterations", 1, 1_000_000)],
    )
    .default("5"),
    }
}
fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let lines: Lines = conf.read()?;
    let turn = Arc::new(AtomicBool::new(true));
    // Shared through the name space so the children (or anyone) can see whose turn it is.
    let _ = rt.names.export_arc("pingpong", "turn", turn.clone());
    Ok(Box::new(PingPong {
        turn,
        every: lines.turn,
        count: 0,
    }))
}

fn create_ping(_: &ComponentConf, _: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    Ok(Box::new(Player {
        name: "ping",
        wins: 0,
    }))
}

fn create_pong(_: &ComponentConf, _: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    Ok(Box::new(Player {
        name: "pong",
        wins: 0,
    }))
}

crate::register_schema!(
    "pingpong",
    "example parent: runs ping and pong as brothers and arbitrates between them",
    create,
    lines = Lines
);
crate::register_schema!(
    "ping",
    "child of pingpong: prints ping N when it wins",
    create_ping,
    "pingpong",
    lines = crate::conf::settings::NoLines
);
crate::register_schema!(
    "pong",
    "child of pingpong: prints pong N when it wins",
    create_pong,
    "pingpong",
    lines = crate::conf::settings::NoLines
);
