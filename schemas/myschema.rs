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
    conf::ComponentConf,
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

fn create(conf: &ComponentConf, _rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    for l in &conf.lines {
        if l.keyword() != "cycle" {
            return Err(conf.unknown(l, "`cycle MS`").into());
        }
    }
    let ms: u64 = conf.value_or("cycle", "milliseconds", 150)?;
    Ok(Box::new(MySchema {
        cycle: Duration::from_millis(ms.max(1)),
    }))
}

crate::register_schema!(
    "myschema",
    "the seed's hello world: prints -->Hello world! each cycle",
    create
);
