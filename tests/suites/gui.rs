//! Test binary `gui`: the GUI: mastergui and the panels headless (egui_kittest), real windows and screenshots under Xvfb, the 3D views, the vision schemas.
//!
//! One binary per area so the suite links a few times, not once per file
//! (docs/benchmarks.md, CI); each module is one of the files beside it.

#[path = "../common/mod.rs"]
mod common;

#[path = "../gui.rs"]
mod gui;
#[path = "../gui_screenshot.rs"]
mod gui_screenshot;
#[path = "../gui_window.rs"]
mod gui_window;
#[path = "../introrob_panel.rs"]
mod introrob_panel;
#[path = "../introrob_screenshot.rs"]
mod introrob_screenshot;
#[path = "../opengl.rs"]
mod opengl;
#[path = "../opengl_screenshot.rs"]
mod opengl_screenshot;
#[path = "../vision_schemas.rs"]
mod vision_schemas;
