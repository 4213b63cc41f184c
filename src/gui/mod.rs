//! The GUI host: one eframe window with mastergui and the shown schema panels, in
//! place of 4.3's graphics_gtk / graphics_xforms / graphics_glut services.
//!
//! - The window opens when a GUI service is loaded (`load_service gui`, or 4.3's
//!   `graphics_gtk`, `graphics_xforms`, `graphics_glut`), from the conf or later
//!   from the shell, provided there is a display and `--headless` was not given.
//! - A schema offers a [`Panel`] from [`Schema::panel`](crate::runtime::Schema::panel).
//!   Shown panels (`show NAME` in the conf or the shell, or mastergui's show toggle:
//!   one state, [`Runtime::show`]) appear in the window: docked ones (mastergui) in a
//!   left side panel, the others as movable windows. Closing a panel's window hides it.
//! - The host never locks a schema: it reads [`Runtime::status`] (short locks) and
//!   calls panels, which share data with their schemas through interfaces or
//!   atomics.
//! - It repaints when something changed, not on a fixed loop: on input, when an
//!   interface's value changes (its fingerprint, taken when its clock moves) or a
//!   schema's state or shown flag does, and once per [`HEARTBEAT`] for the rates
//!   and ages on screen. A frame that saw a change asks for the next one a
//!   [`FRAME_PERIOD`] later (at most ~30 fps); an idle window is woken by a watcher
//!   thread that compares what was last drawn with the runtime every
//!   [`FRAME_PERIOD`]. A robot standing still costs about one frame a second.
//! - Schema panels open tiled in the area beside the docked mastergui and stay
//!   inside it, so they never cover its columns; where the user moves them is saved
//!   when the window closes (`panels` beside the shell's history) and used the next
//!   time.
//! - Quitting the shell closes the window; closing the window shuts the runtime
//!   down and the program exits with status 0.

mod layout;

use std::{
    collections::VecDeque,
    panic::{AssertUnwindSafe, catch_unwind},
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    time::{Duration, Instant},
};

use parking_lot::Mutex;

use crate::runtime::{Panel, Runtime, SchemaSlot, SchemaStatus};

/// The services that open the window: `gui` and 4.3's names for it.
pub const GUI_SERVICES: [&str; 4] = ["gui", "graphics_gtk", "graphics_xforms", "graphics_glut"];

/// Whether a GUI service is loaded.
pub fn gui_loaded(rt: &Runtime) -> bool {
    rt.drivers()
        .iter()
        .any(|(n, _)| GUI_SERVICES.contains(&n.as_str()))
}

/// How often the watcher looks for changes (at most about 30 frames per second).
pub const FRAME_PERIOD: Duration = Duration::from_millis(33);

/// The slowest repaint: rates and ages on screen move even when no value does.
pub const HEARTBEAT: Duration = Duration::from_secs(1);

/// Size a panel window opens with.
const PANEL_SIZE: egui::Vec2 = egui::vec2(480.0, 520.0);

/// Closes a running window from another thread (the shell's).
#[derive(Clone, Default)]
pub struct CloseHandle {
    inner: Arc<CloseInner>,
}

struct CloseInner {
    close: AtomicBool,
    ctx: Mutex<Option<egui::Context>>,
    /// When the host last drew a frame, and what it showed then.
    last_frame: Mutex<(Instant, Option<Signature>)>,
}

impl Default for CloseInner {
    fn default() -> Self {
        CloseInner {
            close: AtomicBool::new(false),
            ctx: Mutex::new(None),
            last_frame: Mutex::new((Instant::now(), None)),
        }
    }
}

impl CloseHandle {
    /// Asks the window to close (at its next frame, woken at once).
    pub fn close(&self) {
        self.inner.close.store(true, Ordering::Release);
        if let Some(ctx) = self.inner.ctx.lock().as_ref() {
            ctx.request_repaint();
        }
    }
    /// Whether closing was asked for.
    pub fn requested(&self) -> bool {
        self.inner.close.load(Ordering::Acquire)
    }
}

/// A panel that panicked is replaced by this note, so the window goes on.
struct Broken(String);

impl Panel for Broken {
    fn ui(&mut self, ui: &mut egui::Ui, _rt: &Runtime) {
        ui.colored_label(egui::Color32::RED, format!("this panel failed: {}", self.0));
    }
}

/// The window's contents: a top bar, the docked panels (mastergui) on the left, and
/// the other shown panels as windows. Usable without eframe (tests, benchmarks):
/// call [`GuiHost::ui`] from any egui pass.
pub struct GuiHost {
    rt: Arc<Runtime>,
    handle: CloseHandle,
    frames: VecDeque<Instant>,
    quit_clicked: bool,
    layout: layout::Layout,
    prints: Fingerprints,
}

impl GuiHost {
    pub fn new(rt: Arc<Runtime>) -> Self {
        GuiHost {
            rt,
            handle: CloseHandle::default(),
            frames: VecDeque::new(),
            quit_clicked: false,
            layout: layout::Layout::default(),
            prints: Fingerprints::default(),
        }
    }

    /// Uses (and on [`save_layout`](Self::save_layout) writes) panel positions kept
    /// in `file`.
    pub fn with_layout_file(mut self, file: Option<std::path::PathBuf>) -> Self {
        self.layout = layout::Layout::load(file);
        self
    }

    /// Saves where the panels are, for the next run.
    pub fn save_layout(&self) {
        self.layout.save();
    }

    /// The screen rectangle of each panel window drawn in the last frame, by schema.
    pub fn panel_rects(&self) -> Vec<(String, egui::Rect)> {
        self.layout.current()
    }

    /// The area beside the docked panels, where panel windows live (last frame).
    pub fn free_area(&self) -> Option<egui::Rect> {
        self.layout.free
    }

    /// A handle that closes the window from another thread.
    pub fn close_handle(&self) -> CloseHandle {
        self.handle.clone()
    }

    /// Frames drawn per second over the last second.
    pub fn fps(&self) -> f64 {
        match (self.frames.front(), self.frames.back()) {
            (Some(a), Some(b)) if self.frames.len() > 1 => {
                let span = b.duration_since(*a).as_secs_f64();
                if span > 0.0 {
                    (self.frames.len() - 1) as f64 / span
                } else {
                    0.0
                }
            }
            _ => 0.0,
        }
    }

    /// Whether the user asked to quit (the Quit button) or the shell did.
    pub fn should_close(&self) -> bool {
        self.quit_clicked || self.handle.requested()
    }

    /// Draws one frame into `ui` (the whole window's area).
    pub fn ui(&mut self, ui: &mut egui::Ui) {
        self.count_frame();
        {
            let mut c = self.handle.inner.ctx.lock();
            if c.is_none() {
                *c = Some(ui.ctx().clone());
            }
        }
        if ui.input(|i| i.modifiers.command && i.key_pressed(egui::Key::Q)) {
            self.quit_clicked = true;
        }
        let rt = self.rt.clone();
        let status = rt.status();
        let (docked, windows) = shown_panels(&rt, &status);
        self.top_bar(ui, &rt, &status);
        if !docked.is_empty() {
            docked_panels(ui, &rt, &docked);
        }
        let free = central_area(ui, windows.is_empty());
        self.layout.free = Some(free);
        let ctx = ui.ctx().clone();
        self.panel_windows(&ctx, &rt, &windows, free);
        // Busy (something changed since the last frame): the next frame in one
        // frame period, as a 30 fps loop would. Idle: the heartbeat, or the watcher
        // wakes the window at the next change.
        let now = signature(&rt, &mut self.prints);
        let mut last = self.handle.inner.last_frame.lock();
        let busy = last.1.as_ref() != Some(&now);
        *last = (Instant::now(), Some(now));
        drop(last);
        ctx.request_repaint_after(if busy { FRAME_PERIOD } else { HEARTBEAT });
    }

    /// Keeps the times of the frames of the last second, for [`fps`](Self::fps).
    fn count_frame(&mut self) {
        let now = Instant::now();
        self.frames.push_back(now);
        while self
            .frames
            .front()
            .is_some_and(|t| now.duration_since(*t) > Duration::from_secs(1))
        {
            self.frames.pop_front();
        }
    }

    /// The bar with the Panels menu, Quit and the counts.
    fn top_bar(&mut self, ui: &mut egui::Ui, rt: &Runtime, status: &[SchemaStatus]) {
        egui::Panel::top("jde_top").show(ui, |ui| {
            ui.horizontal(|ui| {
                ui.strong("jderobot");
                ui.menu_button("Panels", |ui| {
                    for s in status {
                        let mut shown = s.shown;
                        if ui.checkbox(&mut shown, &s.name).changed() {
                            let _ = if shown {
                                rt.show(&s.name)
                            } else {
                                rt.hide(&s.name)
                            };
                        }
                    }
                    if status.is_empty() {
                        ui.label("no schema loaded");
                    }
                });
                if ui.button("Quit").on_hover_text("Ctrl+Q").clicked() {
                    self.quit_clicked = true;
                }
                let running = status.iter().filter(|s| s.state.iterates()).count();
                ui.label(format!(
                    "{} schemas ({running} iterating), {} drivers/services, {:.0} fps",
                    status.len(),
                    rt.drivers().len(),
                    self.fps()
                ));
            });
        });
    }

    /// The undocked panels as windows tiled in `free`; closing one hides it.
    fn panel_windows(
        &mut self,
        ctx: &egui::Context,
        rt: &Runtime,
        windows: &[PanelWindow],
        free: egui::Rect,
    ) {
        // A lone panel gets the whole free width; several share it as tiles.
        let size = if windows.len() == 1 {
            egui::vec2((free.width() - 2.0).max(PANEL_SIZE.x), PANEL_SIZE.y)
        } else {
            PANEL_SIZE
        };
        for (i, w) in windows.iter().enumerate() {
            let name = w.name.as_str();
            let mut open = true;
            let shown = egui::Window::new(w.title.as_str())
                .id(egui::Id::unique(("jde_panel", name)))
                .open(&mut open)
                .default_pos(self.layout.place(name, i, free, size))
                // Tall enough for introrob's and teleoperator's panels; it scrolls
                // both ways (and resizes) when a panel is larger than the free area.
                .default_size(size)
                .constrain_to(free)
                .scroll(true)
                .show(ctx, |ui| {
                    if w.has_panel {
                        draw_panel(ui, rt, name, &w.slot.panel);
                    } else {
                        ui.label(format!("schema `{name}` has no panel"));
                    }
                });
            if let Some(r) = shown {
                self.layout.seen(name, r.response.rect);
            }
            if !open {
                let _ = rt.hide(name);
            }
        }
    }
}

/// A shown schema drawn in a window of its own.
struct PanelWindow {
    name: String,
    title: String,
    slot: Arc<SchemaSlot>,
    has_panel: bool,
}

/// The shown schemas: those whose panels dock (by name), and the others.
fn shown_panels(
    rt: &Runtime,
    status: &[SchemaStatus],
) -> (Vec<(String, Arc<SchemaSlot>)>, Vec<PanelWindow>) {
    let mut docked = Vec::new();
    let mut windows = Vec::new();
    for s in status.iter().filter(|s| s.shown) {
        let Some(slot) = rt.schema(&s.name) else {
            continue;
        };
        let (has_panel, dock, title) = match slot.panel.lock().as_ref() {
            Some(p) => (true, p.docked(), p.title()),
            None => (false, false, None),
        };
        if has_panel && dock {
            docked.push((s.name.clone(), slot));
        } else {
            windows.push(PanelWindow {
                name: s.name.clone(),
                title: title.unwrap_or_else(|| s.name.clone()),
                slot,
                has_panel,
            });
        }
    }
    (docked, windows)
}

/// The docked panels (mastergui), one under the other in a left side panel.
fn docked_panels(ui: &mut egui::Ui, rt: &Runtime, docked: &[(String, Arc<SchemaSlot>)]) {
    egui::Panel::left("jde_docked")
        .default_size(380.0)
        .show(ui, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| {
                for (name, slot) in docked {
                    draw_panel(ui, rt, name, &slot.panel);
                    ui.separator();
                }
            });
        });
}

/// The central area, with a hint while no panel window is open; its rectangle is
/// where panel windows may go.
fn central_area(ui: &mut egui::Ui, no_windows: bool) -> egui::Rect {
    egui::CentralPanel::default_margins()
        .show(ui, |ui| {
            if no_windows {
                ui.centered_and_justified(|ui| {
                    ui.weak(
                        "Schema panels appear here. Show one with `show NAME` in the shell, \
                         the Panels menu, or mastergui's show toggle.",
                    );
                });
            }
        })
        .response
        .rect
}

/// Calls a panel; a panel that panics is replaced by a note.
fn draw_panel(ui: &mut egui::Ui, rt: &Runtime, name: &str, panel: &Mutex<Option<Box<dyn Panel>>>) {
    let mut p = panel.lock();
    let Some(inner) = p.as_mut() else { return };
    let r = catch_unwind(AssertUnwindSafe(|| {
        ui.push_id(("jde_panel_body", name), |ui| inner.ui(ui, rt));
    }));
    if let Err(e) = r {
        let msg = crate::output::panic_text(&*e);
        tracing::error!("{name}: panel failed: {msg}");
        *p = Some(Box::new(Broken(msg)));
    }
}

impl eframe::App for GuiHost {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        if self.should_close() {
            ui.ctx().send_viewport_cmd(egui::ViewportCommand::Close);
        }
        GuiHost::ui(self, ui);
    }

    fn on_exit(&mut self, _gl: Option<&eframe::glow::Context>) {
        // Closing by any way (Quit, Ctrl+Q, the window manager, the shell) ends here.
        self.handle.inner.close.store(true, Ordering::Release);
        self.save_layout();
    }
}

/// What the window shows changes with: each interface's value and staleness, each
/// schema's state and shown flag, the loaded drivers.
type Signature = (u64, Vec<(String, crate::runtime::State, bool)>, usize);

/// Fingerprints of interface values, recomputed only when a clock moved.
#[derive(Default)]
struct Fingerprints(std::collections::HashMap<String, (u64, u64)>);

impl Fingerprints {
    /// One number that changes when any interface's value or staleness changes
    /// (a new sample equal to the previous one does not change it).
    fn of(&mut self, rt: &Runtime) -> u64 {
        let mut all = 0u64;
        for i in rt.interfaces.all() {
            let clock = i.clock();
            let e = self.0.entry(i.name().to_string()).or_insert((u64::MAX, 0));
            if e.0 != clock {
                *e = (clock, i.fingerprint());
            }
            let stale = i.stale().is_some() as u64;
            all = all.wrapping_mul(31).wrapping_add(e.1 ^ stale);
        }
        all
    }
}

fn signature(rt: &Runtime, prints: &mut Fingerprints) -> Signature {
    let states = rt
        .status()
        .into_iter()
        .map(|s| (s.name, s.state, s.shown))
        .collect();
    (prints.of(rt), states, rt.drivers().len())
}

/// Wakes an idle window (one waiting for its heartbeat) as soon as something it
/// shows changes; a busy window paces itself (see [`GuiHost::ui`]). Ends when the
/// window closes.
fn watch_for_changes(rt: Arc<Runtime>, handle: CloseHandle) {
    let mut prints = Fingerprints::default();
    while !handle.requested() {
        std::thread::sleep(FRAME_PERIOD);
        // A busy window compares for itself at each frame: look only when idle.
        let drawn = {
            let last = handle.inner.last_frame.lock();
            if last.0.elapsed() <= 2 * FRAME_PERIOD {
                continue;
            }
            last.1.clone()
        };
        if drawn != Some(signature(&rt, &mut prints))
            && let Some(ctx) = handle.inner.ctx.lock().as_ref()
        {
            ctx.request_repaint();
        }
    }
}

/// Opens the window on this (the main) thread and returns when it closes.
pub fn run_window(host: GuiHost) -> Result<(), String> {
    let (rt, handle) = (host.rt.clone(), host.close_handle());
    let watcher = std::thread::Builder::new()
        .name("gui-watch".into())
        .spawn(move || watch_for_changes(rt, handle));
    if let Err(e) = watcher {
        tracing::warn!(
            "gui: no change watcher ({e}); the window repaints on input and every second"
        );
    }
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("jderobot")
            .with_app_id("jderobot")
            .with_inner_size([1180.0, 760.0]),
        // The 3D panels (opengldemo, opengl_viewer) draw with depth testing.
        depth_buffer: 24,
        ..Default::default()
    };
    eframe::run_native("jderobot", options, Box::new(move |_cc| Ok(Box::new(host))))
        .map_err(|e| e.to_string())
}
