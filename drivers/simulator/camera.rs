//! The camera: a pinhole camera on the robot's pan-tilt unit, with progeo's model
//! and pixel conventions, and a small scanline renderer (floor with tiles, lines
//! painted on it, sky, walls with their heights, boxes, balls and the other
//! robots), depth-tested
//! with an inverse-depth buffer.
//!
//! The camera is a [`PinholeCamera`] from [`crate::progeo`] (`position`, `foa`,
//! `roll`, `fdistx`, `fdisty`, `u0`, `v0`), with its pixel conventions: optical
//! x = row counted from the bottom, y = column from the left; graphic column =
//! optical y, graphic row = rows − 1 − optical x. Optical pixel (x, y) covers
//! [x, x+1) x [y, y+1), so a point that progeo projects to (x, y) lands in graphic
//! pixel (column ⌊y⌋, row rows − 1 − ⌊x⌋).

use crate::{
    interfaces::Image,
    progeo::{HPoint3D, PinholeCamera, focal_from_fov},
    world::{Paint, Rgb},
};

use super::physics::Sim;

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl Sim {
    /// Robot `i`'s camera for an image of `columns` x `rows`, as a progeo pinhole
    /// camera: on its pan-tilt unit, looking along heading + pan, tilted up by
    /// tilt; no roll, no skew, `fx = fy` from the field of view, `u0 = rows/2`,
    /// `v0 = columns/2`.
    pub fn camera(&self, i: usize, columns: u32, rows: u32) -> PinholeCamera {
        let (pose, m, pan, tilt) = match self.robots.get(i) {
            Some(r) => (r.pose, r.model.clone(), r.pan, r.tilt),
            None => Default::default(),
        };
        let p = pose.apply(m.camera_pos);
        let position = [p[0], p[1], m.camera_height];
        let az = pose.theta + pan.to_radians();
        let el = tilt.to_radians();
        let foa = [
            position[0] + 1000.0 * el.cos() * az.cos(),
            position[1] + 1000.0 * el.cos() * az.sin(),
            position[2] + 1000.0 * el.sin(),
        ];
        // The conf's declaration bounds it (0.001..169.999 deg); used as given.
        let fov = m.camera_fov.to_radians();
        PinholeCamera::new(
            HPoint3D::point(position[0], position[1], position[2]),
            HPoint3D::point(foa[0], foa[1], foa[2]),
            focal_from_fov(columns as f64, fov),
            columns,
            rows,
        )
    }
}

/// Near clipping distance, mm.
const NEAR: f64 = 10.0;

/// Paint is drawn this high above the floor (mm), so that it wins the depth
/// test against the floor and loses it against everything else.
const PAINT_Z: f64 = 1.0;
/// The longest piece a painted line is drawn in, mm (see `paint`).
const PAINT_PIECE: f64 = 250.0;

/// The body of a robot as the camera sees it: length, width, height (mm).
const ROBOT_BODY: [f64; 3] = [450.0, 380.0, 240.0];
const ROBOT_COLOR: Rgb = [60, 60, 70];

/// Reusable rendering buffers.
#[derive(Default)]
pub struct Renderer {
    inv_z: Vec<f32>,
    w: usize,
    h: usize,
    // The current camera, unpacked.
    rot: [[f64; 3]; 3],
    pos: [f64; 3],
    fx: f64,
    fy: f64,
    u0: f64,
    v0: f64,
}

fn shade(c: Rgb, k: f64) -> [u8; 3] {
    // BGR out.
    let s = |x: u8| (x as f64 * k).clamp(0.0, 255.0) as u8;
    [s(c[2]), s(c[1]), s(c[0])]
}

impl Renderer {
    pub fn new() -> Renderer {
        Renderer::default()
    }

    fn cam(&self, p: [f64; 3]) -> [f64; 3] {
        let q = sub(p, self.pos);
        [
            dot(self.rot[0], q),
            dot(self.rot[1], q),
            dot(self.rot[2], q),
        ]
    }

    /// Graphic (x = column, y = row) of a camera-space point in front of the camera.
    fn to_graphic(&self, a: [f64; 3]) -> [f64; 2] {
        [
            self.fy * a[1] / a[2] + self.v0,
            self.h as f64 - (self.fx * a[0] / a[2] + self.u0),
        ]
    }

    /// Renders robot `me`'s view with progeo camera `cam` (its skew is ignored)
    /// into `img` (resized to the camera's size if needed).
    pub fn render(&mut self, sim: &Sim, me: usize, cam: &PinholeCamera, img: &mut Image) {
        let (w, h) = (cam.columns as usize, cam.rows as usize);
        if img.width as usize != w || img.height as usize != h || img.data.len() != w * h * 3 {
            *img = Image::new(w as u32, h as u32);
        }
        self.w = w;
        self.h = h;
        self.inv_z.clear();
        self.inv_z.resize(w * h, 0.0);
        let r = cam.rotation();
        self.rot = [0, 1, 2].map(|i| [r[(i, 0)], r[(i, 1)], r[(i, 2)]]);
        let hp = if cam.position.h != 0.0 {
            cam.position.h
        } else {
            1.0
        };
        self.pos = [
            cam.position.x / hp,
            cam.position.y / hp,
            cam.position.z / hp,
        ];
        (self.fx, self.fy, self.u0, self.v0) = (cam.fdistx, cam.fdisty, cam.u0, cam.v0);
        if w == 0 || h == 0 {
            return;
        }
        self.floor_and_sky(sim, img);
        for p in &sim.world.paint {
            self.paint(p, img);
        }
        let light = [0.6, 0.8];
        for s in &sim.world.segments {
            if let Some(n) = s.normal
                && (self.pos[0] - s.a[0]) * n[0] + (self.pos[1] - s.a[1]) * n[1] <= 0.0
            {
                continue; // back face
            }
            let e = [s.b[0] - s.a[0], s.b[1] - s.a[1]];
            let l = (e[0] * e[0] + e[1] * e[1]).sqrt().max(1e-9);
            let nw = [e[1] / l, -e[0] / l, 0.0];
            let k = 0.72 + 0.28 * (nw[0] * light[0] + nw[1] * light[1]).abs();
            let quad = [
                [s.a[0], s.a[1], 0.0],
                [s.b[0], s.b[1], 0.0],
                [s.b[0], s.b[1], s.height],
                [s.a[0], s.a[1], s.height],
            ];
            self.polygon(&quad, nw, shade(s.color, k), img);
        }
        for b in &sim.world.boxes {
            self.top(&b.corners(), b.height, b.color, img);
        }
        for (k, r) in sim.robots.iter().enumerate() {
            if k == me {
                continue;
            }
            let (hx, hy) = (ROBOT_BODY[0] / 2.0, ROBOT_BODY[1] / 2.0);
            let c = [[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]].map(|p| r.pose.apply(p));
            for j in 0..4 {
                let (p, q) = (c[j], c[(j + 1) % 4]);
                let e = [q[0] - p[0], q[1] - p[1]];
                let l = (e[0] * e[0] + e[1] * e[1]).sqrt();
                let n = [e[1] / l, -e[0] / l];
                if (self.pos[0] - p[0]) * n[0] + (self.pos[1] - p[1]) * n[1] <= 0.0 {
                    continue;
                }
                let kk = 0.72 + 0.28 * (n[0] * light[0] + n[1] * light[1]).abs();
                let quad = [
                    [p[0], p[1], 0.0],
                    [q[0], q[1], 0.0],
                    [q[0], q[1], ROBOT_BODY[2]],
                    [p[0], p[1], ROBOT_BODY[2]],
                ];
                self.polygon(&quad, [n[0], n[1], 0.0], shade(ROBOT_COLOR, kk), img);
            }
            self.top(&c, ROBOT_BODY[2], ROBOT_COLOR, img);
        }
        for b in &sim.balls {
            self.sphere([b.pos[0], b.pos[1], b.radius], b.radius, b.color, img);
        }
    }

    fn floor_and_sky(&mut self, sim: &Sim, img: &mut Image) {
        let (w, h) = (self.w, self.h);
        let [r0, r1, r2] = self.rot;
        let sky = shade(sim.world.sky_color, 1.0);
        let f1 = shade(sim.world.floor_color, 1.0);
        let f2 = shade(sim.world.floor_color, 0.85);
        let tile = sim.world.tile;
        let inv_tile = if tile > 0.0 { 1.0 / tile } else { 0.0 };
        let cz = self.pos[2];
        let step = [r1[0] / self.fy, r1[1] / self.fy, r1[2] / self.fy];
        for row in 0..h {
            let px = (h as f64 - (row as f64 + 0.5) - self.u0) / self.fx;
            let py0 = (0.5 - self.v0) / self.fy;
            let base = [
                px * r0[0] + py0 * r1[0] + r2[0],
                px * r0[1] + py0 * r1[1] + r2[1],
                px * r0[2] + py0 * r1[2] + r2[2],
            ];
            let line = &mut img.data[row * w * 3..(row + 1) * w * 3];
            let zrow = &mut self.inv_z[row * w..(row + 1) * w];
            if step[2] == 0.0 {
                // No roll: the whole row is sky, or floor at one depth.
                if base[2] >= -1e-12 || cz <= 0.0 {
                    for px in line.chunks_exact_mut(3) {
                        px.copy_from_slice(&sky);
                    }
                    continue;
                }
                let t = -cz / base[2];
                zrow.fill((1.0 / t) as f32);
                if inv_tile == 0.0 {
                    for px in line.chunks_exact_mut(3) {
                        px.copy_from_slice(&f1);
                    }
                    continue;
                }
                // Floor point x(c) = x0 + c·dx, y likewise; tiles by parity.
                let (x0, y0) = (
                    (self.pos[0] + t * base[0]) * inv_tile,
                    (self.pos[1] + t * base[1]) * inv_tile,
                );
                let (dx, dy) = (t * step[0] * inv_tile, t * step[1] * inv_tile);
                for (c, px) in line.chunks_exact_mut(3).enumerate() {
                    let x = x0 + c as f64 * dx;
                    let y = y0 + c as f64 * dy;
                    let odd = ((x.floor() as i64) ^ (y.floor() as i64)) & 1 != 0;
                    px.copy_from_slice(if odd { &f2 } else { &f1 });
                }
            } else {
                for (c, px) in line.chunks_exact_mut(3).enumerate() {
                    let d = [
                        base[0] + c as f64 * step[0],
                        base[1] + c as f64 * step[1],
                        base[2] + c as f64 * step[2],
                    ];
                    if d[2] >= -1e-12 || cz <= 0.0 {
                        px.copy_from_slice(&sky);
                        continue;
                    }
                    let t = -cz / d[2];
                    zrow[c] = (1.0 / t) as f32;
                    let odd = inv_tile > 0.0 && {
                        let x = (self.pos[0] + t * d[0]) * inv_tile;
                        let y = (self.pos[1] + t * d[1]) * inv_tile;
                        ((x.floor() as i64) ^ (y.floor() as i64)) & 1 != 0
                    };
                    px.copy_from_slice(if odd { &f2 } else { &f1 });
                }
            }
        }
    }

    /// A painted line: a flat quad per piece (at most [`PAINT_PIECE`] long),
    /// square-capped by half the width so the joints of a bending line have no
    /// gaps. A piece under a pixel wide or long in the image is left out (the
    /// line fades out with distance): without anti-aliasing a far piece comes out
    /// as scattered specks, each a zero-area contour that a student's
    /// `cv2.findContours(...)[0]` would take for the line.
    fn paint(&mut self, p: &Paint, img: &mut Image) {
        let (bgr, h) = (shade(p.color, 1.0), p.width / 2.0);
        for (a, b) in p.segments() {
            let e = [b[0] - a[0], b[1] - a[1]];
            let l = e[0].hypot(e[1]);
            if l < 1e-9 {
                continue;
            }
            let pieces = (l / PAINT_PIECE).ceil().max(1.0) as usize;
            let (u, n) = ([e[0] / l * h, e[1] / l * h], [-e[1] / l * h, e[0] / l * h]);
            for k in 0..pieces {
                let (s0, s1) = (k as f64 / pieces as f64, (k + 1) as f64 / pieces as f64);
                let a = [a[0] + s0 * e[0], a[1] + s0 * e[1]];
                let b = [a[0] + (s1 - s0) * e[0], a[1] + (s1 - s0) * e[1]];
                let (thick, long) = self.on_screen(a, b, [n[0] * 2.0, n[1] * 2.0]);
                if thick < 1.0 || long < 1.0 {
                    continue;
                }
                let at = |p: [f64; 2], s: f64, t: f64| {
                    [
                        p[0] + s * u[0] + t * n[0],
                        p[1] + s * u[1] + t * n[1],
                        PAINT_Z,
                    ]
                };
                let quad = [
                    at(a, -1.0, -1.0),
                    at(b, 1.0, -1.0),
                    at(b, 1.0, 1.0),
                    at(a, -1.0, 1.0),
                ];
                self.polygon(&quad, [0.0, 0.0, 1.0], bgr, img);
            }
        }
    }

    /// How thick and how long, in pixels, the floor strip from `a` to `b`,
    /// `width` wide (a world vector across it), is in the image, from the
    /// projections of its width and length at its middle: the thickness is the
    /// width's part across the strip's direction on the screen.
    fn on_screen(&self, a: [f64; 2], b: [f64; 2], width: [f64; 2]) -> (f64, f64) {
        let mid = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
        let c = self.cam([mid[0], mid[1], PAINT_Z]);
        if c[2] < NEAR {
            return (f64::INFINITY, f64::INFINITY); // at or behind the camera: clipping decides
        }
        let screen = |v: [f64; 2]| {
            let t = self.cam([mid[0] + v[0], mid[1] + v[1], PAINT_Z]);
            let z = t[2].max(NEAR);
            [
                self.fx * (t[0] / z - c[0] / c[2]),
                self.fy * (t[1] / z - c[1] / c[2]),
            ]
        };
        let (w, l) = (screen(width), screen([b[0] - a[0], b[1] - a[1]]));
        let long = l[0].hypot(l[1]);
        let thick = (w[0] * l[1] - w[1] * l[0]).abs() / long.max(1e-9);
        (thick, long)
    }

    /// The horizontal top face of a prism with footprint `c` at height `z`.
    fn top(&mut self, c: &[[f64; 2]; 4], z: f64, color: Rgb, img: &mut Image) {
        if self.pos[2] <= z {
            return;
        }
        let quad = c.map(|p| [p[0], p[1], z]);
        self.polygon(&quad, [0.0, 0.0, 1.0], shade(color, 1.08), img);
    }

    /// Fills a planar convex polygon (world points, world normal) with a flat colour.
    fn polygon(&mut self, pts: &[[f64; 3]; 4], normal: [f64; 3], bgr: [u8; 3], img: &mut Image) {
        // To camera space, and clip against the near plane.
        let cam: [[f64; 3]; 4] = pts.map(|p| self.cam(p));
        if cam.iter().all(|a| a[2] < NEAR) {
            return;
        }
        let mut poly: [[f64; 3]; 8] = [[0.0; 3]; 8];
        let mut n = 0;
        for k in 0..4 {
            let (p, q) = (cam[k], cam[(k + 1) % 4]);
            if p[2] >= NEAR {
                poly[n] = p;
                n += 1;
            }
            if (p[2] >= NEAR) != (q[2] >= NEAR) {
                let t = (NEAR - p[2]) / (q[2] - p[2]);
                poly[n] = [p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1]), NEAR];
                n += 1;
            }
        }
        if n < 3 {
            return;
        }
        let mut g = [[0.0f64; 2]; 8];
        let (mut xmin, mut xmax, mut ymin, mut ymax) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for k in 0..n {
            g[k] = self.to_graphic(poly[k]);
            xmin = xmin.min(g[k][0]);
            xmax = xmax.max(g[k][0]);
            ymin = ymin.min(g[k][1]);
            ymax = ymax.max(g[k][1]);
        }
        let (wf, hf) = (self.w as f64, self.h as f64);
        if xmax < 0.0
            || ymax < 0.0
            || xmin > wf
            || ymin > hf
            || !(xmin.is_finite() && ymin.is_finite())
        {
            return;
        }
        // Inverse depth is affine in graphic coordinates on a plane.
        let nc = [
            dot(self.rot[0], normal),
            dot(self.rot[1], normal),
            dot(self.rot[2], normal),
        ];
        let d = dot(nc, poly[0]);
        if d.abs() < 1e-9 {
            return; // seen edge-on
        }
        let a = nc[1] / (self.fy * d);
        let b = -nc[0] / (self.fx * d);
        let c0 = (nc[0] * (hf - self.u0) / self.fx - nc[1] * self.v0 / self.fy + nc[2]) / d;
        let r0 = ((ymin - 0.5).ceil().max(0.0)) as usize;
        let r1 = (ymax - 0.5).floor().min(hf - 1.0);
        if r1 < 0.0 {
            return;
        }
        let w = self.w;
        for row in r0..=r1 as usize {
            let yc = row as f64 + 0.5;
            let (mut xl, mut xr) = (f64::INFINITY, f64::NEG_INFINITY);
            for k in 0..n {
                let (p, q) = (g[k], g[(k + 1) % n]);
                if (p[1] <= yc && yc < q[1]) || (q[1] <= yc && yc < p[1]) {
                    let x = p[0] + (yc - p[1]) * (q[0] - p[0]) / (q[1] - p[1]);
                    xl = xl.min(x);
                    xr = xr.max(x);
                }
            }
            if xl >= xr {
                continue;
            }
            let c_start = (xl - 0.5).ceil().max(0.0) as usize;
            let c_end = ((xr - 0.5).ceil().min(wf)) as usize;
            if c_start >= c_end {
                continue;
            }
            let mut iz = a * (c_start as f64 + 0.5) + b * yc + c0;
            let zrow = &mut self.inv_z[row * w..(row + 1) * w];
            let line = &mut img.data[row * w * 3..(row + 1) * w * 3];
            for c in c_start..c_end {
                let z = iz as f32;
                if z > zrow[c] {
                    zrow[c] = z;
                    line[c * 3..c * 3 + 3].copy_from_slice(&bgr);
                }
                iz += a;
            }
        }
    }

    /// A shaded sphere of radius `r` centred at `center` (world).
    fn sphere(&mut self, center: [f64; 3], r: f64, color: Rgb, img: &mut Image) {
        let cc = self.cam(center);
        if cc[2] + r < NEAR {
            return;
        }
        let (wf, hf) = (self.w as f64, self.h as f64);
        // Bounds of a1/a3 and a2/a3 over the sphere: tangent planes through the camera.
        let span = |ca: f64| -> Option<(f64, f64)> {
            let z = cc[2];
            let qa = z * z - r * r;
            if qa <= 1e-9 {
                return None;
            }
            let qb = -2.0 * ca * z;
            let qc = ca * ca - r * r;
            let disc = (qb * qb - 4.0 * qa * qc).max(0.0).sqrt();
            Some(((-qb - disc) / (2.0 * qa), (-qb + disc) / (2.0 * qa)))
        };
        let (c0, c1, r0, r1) = match (span(cc[0]), span(cc[1])) {
            (Some((xlo, xhi)), Some((ylo, yhi))) if cc[2] - r > NEAR => {
                // Graphic column from a2/a3 (ylo..yhi); row from a1/a3, reversed.
                let gc0 = self.fy * ylo + self.v0;
                let gc1 = self.fy * yhi + self.v0;
                let gr0 = hf - (self.fx * xhi + self.u0);
                let gr1 = hf - (self.fx * xlo + self.u0);
                if gc1 < 0.0 || gr1 < 0.0 || gc0 > wf || gr0 > hf {
                    return;
                }
                (
                    gc0.floor().max(0.0) as usize,
                    (gc1.ceil().min(wf - 1.0)).max(0.0) as usize,
                    gr0.floor().max(0.0) as usize,
                    (gr1.ceil().min(hf - 1.0)).max(0.0) as usize,
                )
            }
            _ => (0, self.w - 1, 0, self.h - 1),
        };
        let cdotc = dot(cc, cc) - r * r;
        let w = self.w;
        for row in r0..=r1 {
            let px = (hf - (row as f64 + 0.5) - self.u0) / self.fx;
            for col in c0..=c1 {
                let py = (col as f64 + 0.5 - self.v0) / self.fy;
                let d = [px, py, 1.0];
                let dd = dot(d, d);
                let dc = dot(d, cc);
                let disc = dc * dc - dd * cdotc;
                if disc < 0.0 {
                    continue;
                }
                let t = (dc - disc.sqrt()) / dd;
                if t <= NEAR {
                    continue;
                }
                let z = (1.0 / t) as f32;
                let k = row * w + col;
                if z <= self.inv_z[k] {
                    continue;
                }
                self.inv_z[k] = z;
                // Lambert-like: brighter where the surface faces the camera.
                let nrm = [
                    (t * d[0] - cc[0]) / r,
                    (t * d[1] - cc[1]) / r,
                    (t * d[2] - cc[2]) / r,
                ];
                let facing = -dot(nrm, d) / dd.sqrt();
                let px3 = shade(color, 0.55 + 0.5 * facing.max(0.0));
                img.data[k * 3..k * 3 + 3].copy_from_slice(&px3);
            }
        }
    }
}
