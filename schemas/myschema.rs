//! myschema: the seed's hello world.
//!
//! Prints `-->Hello world!` each cycle while running; the runtime prints
//! `myschema: on` / `myschema: off` on run and stop.
//!
//! Conf (optional):
//! ```text
//! schema myschema
//! cycle 150        # ms between iterations (default 150, as in the seed)
//! end_schema
//! load_schema myschema
//! run myschema
//! ```
//! Interfaces: none.

use std::time::Duration;

use crate::{
    conf::{ComponentConf, settings::CYCLE},
    runtime::{Context, Runtime, Schema},
};

/// The hello-world schema.
pub struct MySchema {
    cycle: Duration,
}

impl Schema for MySchema {
    fn cycle(&self) -> Duration {
        self.cycle
    }
    fn iteration(&mut self, ctx: &Context) -> anyhow::Result<()> {
        ctx.println("-->Hello world!");
        Ok(())
    }
}

crate::declare_lines! {
    /// myschema's lines, declared once (`jderobot help myschema`).
    struct Lines {
        cycle: u64 = CYCLE.default("150"),
    }
}
fn create(conf: &ComponentConf, _rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let lines: Lines = conf.read()?;
    Ok(Box::new(MySchema {
        cycle: Duration::from_millis(lines.cycle),
    }))
}

crate::register_schema!(
    "myschema",
    "the seed's hello world: prints -->Hello world! each cycle",
    create,
    lines = Lines
);
