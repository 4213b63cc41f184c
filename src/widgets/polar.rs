//! Laser and sonar ranges drawn around the robot.

use egui::{Color32, Pos2, Response, Sense, Stroke, Ui, Vec2, pos2};

use super::*;
use crate::interfaces::{Laser, Sonars};

/// Screen point of a range reading: `angle_deg` counter-clockwise from straight
/// ahead (0 = up on screen, +90 = left), `range_mm` from `center`.
pub fn polar_to_screen(center: Pos2, px_per_mm: f32, angle_deg: f32, range_mm: f32) -> Pos2 {
    let a = angle_deg.to_radians();
    pos2(
        center.x - range_mm * a.sin() * px_per_mm,
        center.y - range_mm * a.cos() * px_per_mm,
    )
}

/// Laser readings as (angle from the robot's heading in degrees, range mm), the
/// angles from the scan's own geometry and mounting yaw.
pub fn laser_points(laser: &Laser) -> Vec<(f32, f32)> {
    laser
        .readings
        .iter()
        .enumerate()
        .map(|(i, &r)| (laser.robot_angle(i), r as f32))
        .collect()
}

/// Angles (deg from straight ahead, counter-clockwise) of a Pioneer's sonar ring:
/// 8 front sonars from left to right, then 8 rear ones from right to left. Other
/// counts are spread evenly around the robot.
pub fn sonar_angles(n: usize) -> Vec<f32> {
    const PIONEER: [f32; 16] = [
        90.0, 50.0, 30.0, 10.0, -10.0, -30.0, -50.0, -90.0, -90.0, -130.0, -150.0, -170.0, 170.0,
        150.0, 130.0, 90.0,
    ];
    if (8..=16).contains(&n) {
        PIONEER[..n].to_vec()
    } else {
        (0..n).map(|i| i as f32 * 360.0 / n.max(1) as f32).collect()
    }
}

/// Sonar readings as (angle deg, range mm).
pub fn sonar_points(sonars: &Sonars) -> Vec<(f32, f32)> {
    sonar_angles(sonars.us.len())
        .into_iter()
        .zip(sonars.us.iter().copied())
        .collect()
}

/// How to draw a polar view's readings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PolarStyle {
    /// A closed outline with rays (laser).
    Laser,
    /// A 15° wedge per reading (sonars).
    Sonar,
}

/// Draws range readings `(angle deg, range mm)` around a robot at the centre (ahead
/// is up), with range rings every metre up to `max_range_mm`.
pub fn polar_view(
    ui: &mut Ui,
    label: &str,
    size: Vec2,
    points: &[(f32, f32)],
    max_range_mm: f32,
    style: PolarStyle,
) -> Response {
    let (rect, response) = ui.allocate_exact_size(size, Sense::hover());
    label_response(&response, label);
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 2.0, Color32::from_gray(20));
    let max_range = if max_range_mm > 0.0 {
        max_range_mm
    } else {
        8000.0
    };
    let radius = rect.width().min(rect.height()) * 0.5 - 4.0;
    let center = rect.center();
    let k = radius.max(1.0) / max_range;
    let ring = Stroke::new(1.0, Color32::from_gray(60));
    let mut m = 1000.0;
    while m <= max_range {
        painter.circle_stroke(center, m * k, ring);
        m += 1000.0;
    }
    let clamp = |r: f32| r.clamp(0.0, max_range);
    match style {
        PolarStyle::Laser => {
            let pts: Vec<Pos2> = points
                .iter()
                .map(|&(a, r)| polar_to_screen(center, k, a, clamp(r)))
                .collect();
            let ray = Stroke::new(1.0, Color32::from_rgb(60, 60, 120));
            for p in &pts {
                painter.line_segment([center, *p], ray);
            }
            if pts.len() > 1 {
                painter.line(pts, Stroke::new(1.5, Color32::from_rgb(80, 160, 255)));
            }
        }
        PolarStyle::Sonar => {
            for &(a, r) in points {
                let r = clamp(r);
                let arc: Vec<Pos2> = (0..=6)
                    .map(|j| polar_to_screen(center, k, a - 7.5 + j as f32 * 2.5, r))
                    .collect();
                let mut wedge = vec![center];
                wedge.extend(arc.iter().copied());
                wedge.push(center);
                painter.line(wedge, Stroke::new(1.0, Color32::from_rgb(90, 200, 90)));
            }
        }
    }
    // The robot, pointing up.
    let s = 6.0;
    painter.add(egui::Shape::convex_polygon(
        vec![
            pos2(center.x, center.y - s * 1.5),
            pos2(center.x - s, center.y + s),
            pos2(center.x + s, center.y + s),
        ],
        Color32::from_rgb(230, 80, 60),
        Stroke::NONE,
    ));
    response
}
