//! Service `gui`: the egui window (one eframe window with mastergui and the shown
//! schema panels; see [`crate::gui`]).
//!
//! Loading it asks for the window: it opens when there is a display and
//! `--headless` was not given. 4.3's GUI services `graphics_gtk`, `graphics_xforms`
//! and `graphics_glut` are accepted as aliases: they load the same window and say so
//! in one line, so 4.3 confs run unchanged.
//!
//! Conf:
//! ```text
//! load_service gui
//! load_schema mastergui
//! run mastergui
//! show mastergui
//! ```
//! Interfaces: none.

use crate::{
    conf::ComponentConf,
    runtime::{Driver, Runtime},
};

/// The GUI service (the window itself runs on the main thread, see `crate::cli`).
pub struct GuiService;

impl Driver for GuiService {}

fn create(conf: &ComponentConf, _rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    conf.read::<crate::conf::settings::NoLines>()?;
    Ok(Box::new(GuiService))
}

fn alias(_conf: &ComponentConf, name: &str) -> anyhow::Result<Box<dyn Driver>> {
    // 4.3's GUI services had no settings that mean anything here: their lines are
    // ignored. They declare none (no `lines =`): neither the manual nor
    // reference/jde43-behaviour.md says which lines 4.3 accepted, so `check` does not
    // refuse a 4.3 conf's lines for them.
    eprintln!("{name}: replaced by the egui window (service gui)");
    Ok(Box::new(GuiService))
}

fn create_gtk(conf: &ComponentConf, _rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    alias(conf, "graphics_gtk")
}

fn create_xforms(conf: &ComponentConf, _rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    alias(conf, "graphics_xforms")
}

fn create_glut(conf: &ComponentConf, _rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    alias(conf, "graphics_glut")
}

crate::register_driver!(
    Service,
    "gui",
    "the egui window: mastergui and the shown schema panels",
    create,
    lines = crate::conf::settings::NoLines
);
crate::register_driver!(
    Service,
    "graphics_gtk",
    "4.3's GTK GUI service: loads the egui window (service gui)",
    create_gtk,
    "gui"
);
crate::register_driver!(
    Service,
    "graphics_xforms",
    "4.3's XForms GUI service: loads the egui window (service gui)",
    create_xforms,
    "gui"
);
crate::register_driver!(
    Service,
    "graphics_glut",
    "4.3's GLUT GUI service: loads the egui window (service gui)",
    create_glut,
    "gui"
);
