//! Widgets for schema panels: the views robotics users expect.
//!
//! | widget | shows | interaction |
//! |---|---|---|
//! | [`ImageView`] | a BGR [`Image`](crate::interfaces::Image) of any size, scaled to fit | click → [`PixelPick`] (pixel coordinates and colour) |
//! | [`polar_view`] | laser or sonar ranges around the robot | none |
//! | [`WorldView`] | robot pose, walls, laser points, a target, a 1 m grid | drag pans, scroll zooms, click sets the target (world mm), right click recentres on the robot |
//! | [`TimePlot`] | scalars against time (egui_plot) | egui_plot's zoom and pan |
//! | [`Joystick`] | a v/w pad | drag gives v (mm/s) and w (deg/s) within the maxima; release → 0 |
//! | [`PanTiltPad`] | a pan/tilt positioner with sliders | drag or slide sets longitude/latitude (deg) within limits |
//! | [`Wireframe3D`] | 3D segments (mm) seen through a [`progeo`](crate::progeo) camera | drag orbits, scroll zooms |
//! | [`Gl3dView`] ([`gl3d`]) | line and triangle meshes drawn with real OpenGL (depth tested) through a progeo camera | drag orbits the camera about its focus of attention, scroll zooms ([`gl3d::LookAtCamera`]) |
//!
//! Each widget's mathematics lives in small pure functions (pixel picking, joystick
//! mapping, world↔screen transforms, orbit camera) so it can be tested without a
//! window. Every custom widget gives its response an accessibility label (its
//! `label`), so tests can find it by name.
//!
//! Widgets are a library under the components: a schema's panel uses them, and
//! they know nothing of the GUI host that draws the panels.

pub mod gl3d;
mod image_view;
mod joystick;
mod pantilt;
mod polar;
mod time_plot;
mod wireframe;
mod world_view;

pub use gl3d::Gl3dView;
pub use image_view::*;
pub use joystick::*;
pub use pantilt::*;
pub use polar::*;
pub use time_plot::*;
pub use wireframe::*;
pub use world_view::*;

use egui::{Response, WidgetInfo};

/// Gives a custom widget's response an accessibility label (so tests find it).
pub(crate) fn label_response(response: &Response, label: &str) {
    let label = label.to_string();
    response.widget_info(move || WidgetInfo::labeled(egui::Role::Canvas, true, label.clone()));
}

#[cfg(test)]
mod tests;
