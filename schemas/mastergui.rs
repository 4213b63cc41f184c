//! mastergui: the control panel of the suite (4.3's mastergui).
//!
//! Its panel, docked on the left of the window, lists every loaded schema with its
//! state, iterations per second, a run/stop toggle and a show/hide toggle, and every
//! driver and service with the interfaces it provides (clock, rate in new values per
//! second, users = how many have resumed it). It is live: it reads the runtime at
//! every frame. The toggles act on the same state as the shell's `run`/`stop`/
//! `show`/`hide` and the conf's `run`/`show` lines.
//!
//! While mastergui runs (`run mastergui`), each iteration samples every schema's ips
//! into a plot of the last 60 s shown under the table.
//!
//! Conf (optional):
//! ```text
//! schema mastergui
//! cycle 100        # ms between samples (default 100, as in 4.3)
//! end_schema
//! load_service gui
//! load_schema mastergui
//! run mastergui
//! show mastergui
//! ```
//! Interfaces: none (it reads the runtime's tables).

use std::{sync::Arc, time::Duration};

use egui::{Color32, RichText, WidgetInfo};
use parking_lot::Mutex;

use crate::{
    conf::{ComponentConf, settings::CYCLE},
    runtime::Panel,
    runtime::{Context, Runtime, Schema, State},
    widgets::TimePlot,
};

/// The mastergui schema: samples ips for the plot; the panel does the rest.
pub struct MasterGui {
    cycle: Duration,
    history: Arc<Mutex<TimePlot>>,
    panel_taken: bool,
}

impl Schema for MasterGui {
    fn cycle(&self) -> Duration {
        self.cycle
    }
    fn iteration(&mut self, ctx: &Context) -> anyhow::Result<()> {
        let status = ctx.runtime().status();
        let mut h = self.history.lock();
        for s in status.iter().filter(|s| s.state.iterates()) {
            h.push(&s.name, s.timing.ips);
        }
        Ok(())
    }
    fn panel(&mut self) -> Option<Box<dyn Panel>> {
        if self.panel_taken {
            return None;
        }
        self.panel_taken = true;
        Some(Box::new(MasterPanel {
            history: self.history.clone(),
            message: None,
        }))
    }
}

/// mastergui's panel.
pub struct MasterPanel {
    history: Arc<Mutex<TimePlot>>,
    /// The outcome of the last toggle that failed.
    message: Option<String>,
}

/// A checkbox with no text whose accessibility label is `access` (`run myschema`).
fn toggle(ui: &mut egui::Ui, on: &mut bool, access: &str, hover: &str) -> egui::Response {
    let r = ui.checkbox(on, "");
    let (label, value) = (access.to_string(), *on);
    r.widget_info(move || WidgetInfo::selected(egui::Role::CheckBox, true, value, label.clone()));
    r.on_hover_text(hover)
}

fn state_color(s: State) -> Color32 {
    match s {
        State::Winner | State::Forced => Color32::from_rgb(40, 160, 60),
        State::Ready | State::Active => Color32::from_rgb(200, 150, 30),
        State::NotReady => Color32::from_rgb(200, 90, 30),
        State::Slept => Color32::GRAY,
    }
}

impl MasterPanel {
    fn schemas(&mut self, ui: &mut egui::Ui, rt: &Runtime) {
        let status = rt.status();
        ui.heading("Schemas");
        if status.is_empty() {
            ui.label("no schema loaded");
            return;
        }
        egui::Grid::new("mastergui_schemas")
            .striped(true)
            .num_columns(5)
            .show(ui, |ui| {
                ui.strong("schema");
                ui.strong("state");
                ui.strong("ips");
                ui.strong("run");
                ui.strong("show");
                ui.end_row();
                for s in &status {
                    let name = ui.label(&s.name);
                    let mut tip =
                        format!("{} (id {}), cycle {} ms", s.name, s.id, s.cycle.as_millis());
                    if !s.children.is_empty() {
                        tip.push_str(&format!("\nchildren: {}", s.children.join(" ")));
                    }
                    if let Some(e) = &s.last_error {
                        tip.push_str(&format!("\nlast error: {e}"));
                    }
                    name.on_hover_text(tip);
                    ui.label(RichText::new(s.state.as_str()).color(state_color(s.state)));
                    ui.label(format!("{:.1}", s.timing.ips));
                    let mut running = s.state != State::Slept;
                    if toggle(
                        ui,
                        &mut running,
                        &format!("run {}", s.name),
                        "run / stop the schema",
                    )
                    .changed()
                    {
                        let r = if running {
                            rt.run(&s.name)
                        } else {
                            rt.stop(&s.name)
                        };
                        self.message = r.err().map(|e| e.to_string());
                    }
                    let mut shown = s.shown;
                    if toggle(
                        ui,
                        &mut shown,
                        &format!("show {}", s.name),
                        "show / hide the schema's panel",
                    )
                    .changed()
                    {
                        let r = if shown {
                            rt.show(&s.name)
                        } else {
                            rt.hide(&s.name)
                        };
                        self.message = r.err().map(|e| e.to_string());
                    }
                    ui.end_row();
                }
            });
        if let Some(m) = &self.message {
            ui.colored_label(Color32::from_rgb(200, 60, 40), m);
        }
        for s in status.iter().filter(|s| s.last_error.is_some()) {
            if let Some(e) = &s.last_error {
                ui.colored_label(Color32::from_rgb(200, 60, 40), format!("{}: {e}", s.name));
            }
        }
    }

    fn drivers(&self, ui: &mut egui::Ui, rt: &Runtime) {
        ui.heading("Drivers and services");
        let drivers = rt.drivers();
        let ifaces = rt.interfaces.all();
        if drivers.is_empty() && ifaces.is_empty() {
            ui.label("none loaded");
            return;
        }
        let mut providers: Vec<(String, String)> = drivers
            .iter()
            .map(|(n, k)| (n.clone(), k.to_string()))
            .collect();
        for i in &ifaces {
            if !providers.iter().any(|(n, _)| n == i.provider()) {
                providers.push((i.provider().to_string(), "provider".into()));
            }
        }
        for (name, kind) in &providers {
            let mine: Vec<_> = ifaces.iter().filter(|i| i.provider() == name).collect();
            ui.label(RichText::new(format!("{name} ({kind})")).strong());
            #[cfg(feature = "_mcap")]
            if name == "recorder" {
                recorder_row(ui, rt);
                continue;
            }
            if mine.is_empty() {
                ui.label("  no interfaces");
                continue;
            }
            egui::Grid::new(("mastergui_ifaces", name.as_str()))
                .striped(true)
                .num_columns(5)
                .show(ui, |ui| {
                    ui.label("interface");
                    ui.label("type");
                    ui.label("clock");
                    ui.label("rate (Hz)");
                    ui.label("users");
                    ui.end_row();
                    for i in &mine {
                        match i.stale() {
                            Some(why) => ui
                                .label(
                                    RichText::new(format!(
                                        "{} (stale {:.0} s)",
                                        i.name(),
                                        i.age().as_secs_f64()
                                    ))
                                    .color(egui::Color32::from_rgb(220, 60, 40)),
                                )
                                .on_hover_text(why),
                            None => ui.label(i.name()).on_hover_text(i.describe()),
                        };
                        ui.label(i.kind().name());
                        ui.label(i.clock().to_string());
                        ui.label(format!("{:.1}", i.rate()));
                        ui.label(i.users().to_string());
                        ui.end_row();
                    }
                });
        }
    }
}

/// The recorder's line (file, time, messages, size, dropped) and a start/stop
/// toggle, through its `recorder.status` export (as the shell's `record`).
#[cfg(feature = "_mcap")]
fn recorder_row(ui: &mut egui::Ui, rt: &Runtime) {
    use std::sync::atomic::Ordering;
    let Ok(status) = rt
        .names
        .import::<crate::mcapfmt::RecorderStatus>("recorder", "status")
    else {
        ui.label("  recorder status not exported");
        return;
    };
    ui.horizontal(|ui| {
        let mut on = status.want.load(Ordering::Acquire);
        if toggle(
            ui,
            &mut on,
            "record",
            "start or stop recording (the shell's `record start|stop`)",
        )
        .changed()
        {
            status.want.store(on, Ordering::Release);
        }
        ui.label(status.line());
    });
}

impl Panel for MasterPanel {
    fn ui(&mut self, ui: &mut egui::Ui, rt: &Runtime) {
        self.schemas(ui, rt);
        ui.separator();
        self.drivers(ui, rt);
        ui.separator();
        let plot = self.history.lock().clone();
        if plot.is_empty() {
            ui.label("ips history: run mastergui to record it");
        } else {
            ui.label("ips of iterating schemas (last 60 s)");
            plot.show(ui, 140.0);
        }
    }
    fn title(&self) -> Option<String> {
        Some("mastergui".into())
    }
    fn docked(&self) -> bool {
        true
    }
}

crate::declare_lines! {
    /// mastergui's lines, declared once (`jderobot help mastergui`).
    struct Lines {
        cycle: u64 = CYCLE.default("100"),
    }
}
fn create(conf: &ComponentConf, _rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let lines: Lines = conf.read()?;
    Ok(Box::new(MasterGui {
        cycle: Duration::from_millis(lines.cycle),
        history: Arc::new(Mutex::new(TimePlot::new("mastergui_ips", 60.0))),
        panel_taken: false,
    }))
}

crate::register_schema!(
    "mastergui",
    "the control panel: every schema's state, ips, run/stop and show/hide; every driver's interfaces",
    create,
    lines = Lines
);
