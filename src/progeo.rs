//! progeo: projective geometry with the pinhole camera of JDE 4.3, on nalgebra.
//!
//! Units: 3D positions in **mm**, `roll` in **radians**, focal distances `fdistx`,
//! `fdisty`, the optical centre `u0`, `v0` and all 2D points in **pixels**.
//!
//! # Pixel conventions
//! progeo works in **optical** coordinates: `x` is the row counted from the *bottom*
//! of the image (vertical, up) and `y` the column from the left (horizontal). `u0`
//! goes with `x` (rows) and `v0` with `y` (columns): a 320x240 camera has its centre
//! at `u0 = 120`, `v0 = 160`. Images are stored in **graphic** coordinates: (0,0) at
//! the top-left, column to the right, row down. [`optical_to_graphic`] and
//! [`graphic_to_optical`] convert (graphic row = rows − 1 − optical x, graphic
//! column = optical y), exactly like the manual's `GRAPHIC_TO_OPTICAL_X` macros.
//!
//! # Camera file (4.3's extrinsics `save_cam` format)
//! One `key value` per line; `#` starts a comment; unknown keys are ignored (4.3
//! wrote ` #intrinsics` with a leading space, which is read as a comment here).
//! `f` sets both `fx` and `fy`; `columns` and `rows` are integers.
//! ```text
//! #extrinsics, position
//! positionX 0.000000
//! positionY 1298.800000
//! positionZ 0.000000
//! positionH 1.000000
//!
//!  #extrinsics, orientation
//! FOApositionX 0.000000
//! FOApositionY 5298.800000
//! FOApositionZ 0.000000
//! FOApositionH 1.000000
//! roll 0.000000
//!
//!  #intrinsics
//! fx 505.850000
//! fy 505.850000
//! skew 0.000000
//! u0 120.000000
//! v0 160.000000
//! columns 320
//! rows 240
//! ```
//!
//! # World file (extrinsics / simulated3D)
//! ```text
//! worldline 0 0 0 1  4000 0 0 1     # X1 Y1 Z1 H1 X2 Y2 Z2 H2, mm: one 3D segment
//! cameraINfile assets/cameras/cam-in
//! cameraOUTfile /tmp/cam-out
//! maxX 4000                         # maxX minX maxY minY maxZ minZ: read, unused
//! ```
//! Other lines (e.g. a `schema extrinsics` section header) are ignored, because in
//! 4.3 the world file is also the extrinsics schema's conf.
//!
//! # OpenGL cameras
//! OpenGL describes a camera's intrinsics by an aperture and an aspect ratio
//! (`gluPerspective(fovy, aspect, near, far)`), progeo by focal distances and an
//! optical centre; the extrinsics (position, focus of attention, roll) are the same
//! in both (`gluLookAt`). [`GlCamera`] is the OpenGL side and converts both ways:
//! [`GlCamera::to_progeo`] gives `fdistx = rows / (2 tan(fovy/2))`, `fdisty =
//! fdistx · (columns/rows) / aspect` and the centred optical centre (rows/2,
//! columns/2), as the manual says for Gazebo (the aperture on the height) and
//! Webots (on the width: [`GlCamera::from_horizontal_fov`]);
//! [`GlCamera::from_progeo`] goes back (`fovy = 2 atan(rows / (2 fdistx))`).
//! [`PinholeCamera::gl_projection`] and [`PinholeCamera::gl_view`] are the
//! OpenGL matrices that put every 3D point on the pixel [`PinholeCamera::project`]
//! gives, off-centre optical centres and skew included, so a real OpenGL view and
//! progeo agree to the pixel.
//!
//! Every error names `file:line` and what was expected ([`ProgeoError`]).

pub use crate::files::FileError as ProgeoError;
use std::{
    fmt,
    path::{Path, PathBuf},
};

use nalgebra::{Matrix3, Matrix3x4, Matrix4, Vector3, Vector4};

/// The iSight defaults of 4.3 (`ISIGHT_PINHOLE_FDIST`, `_U0`, `_V0`).
pub const ISIGHT_PINHOLE_FDIST: f64 = 405.4;
pub const ISIGHT_PINHOLE_U0: f64 = 142.6;
pub const ISIGHT_PINHOLE_V0: f64 = 150.4;
/// Gazebo's OpenGL aperture (60°, applied to the image height), radians.
pub const GAZEBO_FOV: f64 = std::f64::consts::FRAC_PI_3;
/// Webots' OpenGL aperture (45°, applied to the image width), radians.
pub const WEBOTS_FOV: f64 = std::f64::consts::FRAC_PI_4;

/// A homogeneous 2D point (optical pixel coordinates). After [`PinholeCamera::project`]
/// `h` is 1 (in front of the camera), −1 (behind it; x, y still filled) or 0 (at
/// infinity).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct HPoint2D {
    pub x: f64,
    pub y: f64,
    pub h: f64,
}

/// A homogeneous 3D point, mm.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct HPoint3D {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub h: f64,
}

impl HPoint2D {
    pub const fn new(x: f64, y: f64, h: f64) -> Self {
        HPoint2D { x, y, h }
    }
    pub fn to_vector(self) -> Vector3<f64> {
        Vector3::new(self.x, self.y, self.h)
    }
    /// x/h, y/h with h = 1 (unchanged when h is 0).
    pub fn normalized(self) -> Self {
        if self.h == 0.0 {
            self
        } else {
            HPoint2D::new(self.x / self.h, self.y / self.h, 1.0)
        }
    }
}

impl HPoint3D {
    pub const fn new(x: f64, y: f64, z: f64, h: f64) -> Self {
        HPoint3D { x, y, z, h }
    }
    /// A Euclidean point (h = 1).
    pub const fn point(x: f64, y: f64, z: f64) -> Self {
        HPoint3D { x, y, z, h: 1.0 }
    }
    pub fn to_vector(self) -> Vector4<f64> {
        Vector4::new(self.x, self.y, self.z, self.h)
    }
    /// The Euclidean part (x/h, y/h, z/h); `None` at infinity.
    pub fn euclidean(self) -> Option<Vector3<f64>> {
        (self.h != 0.0).then(|| Vector3::new(self.x, self.y, self.z) / self.h)
    }
}

impl From<Vector3<f64>> for HPoint2D {
    fn from(v: Vector3<f64>) -> Self {
        HPoint2D::new(v.x, v.y, v.z)
    }
}
impl From<Vector4<f64>> for HPoint3D {
    fn from(v: Vector4<f64>) -> Self {
        HPoint3D::new(v.x, v.y, v.z, v.w)
    }
}

/// Optical (x up from the bottom row, y = column) to graphic (column, row from the
/// top) for an image of `rows` rows: `(y, rows - 1 - x)`.
pub fn optical_to_graphic(x: f64, y: f64, rows: u32) -> (f64, f64) {
    (y, rows as f64 - 1.0 - x)
}

/// Graphic (column, row from the top) to optical (x, y): `(rows - 1 - row, column)`.
pub fn graphic_to_optical(column: f64, row: f64, rows: u32) -> (f64, f64) {
    (rows as f64 - 1.0 - row, column)
}

/// The OpenGL aperture (radians) that gives focal distance `f` (pixels) on an image
/// side of `size_px` pixels: `2 atan(size / (2 f))` (the inverse of [`focal_from_fov`]).
pub fn fov_from_focal(size_px: f64, f: f64) -> f64 {
    2.0 * (size_px / (2.0 * f)).atan()
}

/// An OpenGL perspective camera: `gluLookAt(position, foa, up)` with `roll` about
/// the optical axis, and `gluPerspective(fovy, aspect, near, far)`. Lengths in mm,
/// angles in radians. See the module doc for the mapping to [`PinholeCamera`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GlCamera {
    /// The camera's position, mm.
    pub position: [f64; 3],
    /// The focus of attention (a point on the optical axis), mm.
    pub foa: [f64; 3],
    /// Rotation about the optical axis, radians.
    pub roll: f64,
    /// Vertical aperture (gluPerspective's `fovy`), radians.
    pub fovy: f64,
    /// Width / height of the image (gluPerspective's `aspect`).
    pub aspect: f64,
    /// Near and far clipping distances, mm.
    pub near: f64,
    pub far: f64,
}

impl GlCamera {
    /// A camera whose aperture `fovx` (radians) is on the image width, as Webots
    /// gives it: `fovy = 2 atan(tan(fovx/2) / aspect)`.
    pub fn from_horizontal_fov(
        position: [f64; 3],
        foa: [f64; 3],
        fovx: f64,
        aspect: f64,
    ) -> GlCamera {
        GlCamera {
            position,
            foa,
            roll: 0.0,
            fovy: 2.0 * ((fovx / 2.0).tan() / aspect).atan(),
            aspect,
            near: 10.0,
            far: 1.0e6,
        }
    }

    /// The horizontal aperture, radians: `2 atan(aspect tan(fovy/2))`.
    pub fn fovx(&self) -> f64 {
        2.0 * (self.aspect * (self.fovy / 2.0).tan()).atan()
    }

    /// The progeo camera of this OpenGL camera for a `columns` x `rows` image:
    /// centred optical centre (`u0 = rows/2`, `v0 = columns/2`), `fdistx = rows /
    /// (2 tan(fovy/2))`, `fdisty = fdistx · (columns/rows) / aspect` (equal when the
    /// aspect is the image's), no skew.
    pub fn to_progeo(&self, columns: u32, rows: u32) -> PinholeCamera {
        let (columns, rows) = (columns.max(1), rows.max(1));
        let fovy = self.fovy.clamp(1e-6, std::f64::consts::PI - 1e-6);
        let fx = focal_from_fov(rows as f64, fovy);
        let aspect = if self.aspect > 0.0 && self.aspect.is_finite() {
            self.aspect
        } else {
            columns as f64 / rows as f64
        };
        let fy = fx * (columns as f64 / rows as f64) / aspect;
        let [x, y, z] = self.position;
        let [fx_, fy_, fz] = self.foa;
        let mut c = PinholeCamera::new(
            HPoint3D::point(x, y, z),
            HPoint3D::point(fx_, fy_, fz),
            fx,
            columns,
            rows,
        );
        c.fdisty = fy;
        c.roll = self.roll;
        c.update_camera_matrix();
        c
    }

    /// The OpenGL camera of a progeo camera: `fovy = 2 atan(rows / (2 fdistx))`,
    /// `aspect = (columns / fdisty) / (rows / fdistx)`; its optical centre is taken
    /// as centred (use [`PinholeCamera::gl_projection`] to keep an off-centre one).
    pub fn from_progeo(cam: &PinholeCamera, near: f64, far: f64) -> GlCamera {
        let p = xyz(&cam.position);
        let f = xyz(&cam.foa);
        let (rows, columns) = (cam.rows.max(1) as f64, cam.columns.max(1) as f64);
        GlCamera {
            position: [p.x, p.y, p.z],
            foa: [f.x, f.y, f.z],
            roll: cam.roll,
            fovy: fov_from_focal(rows, cam.fdistx),
            aspect: (columns / cam.fdisty) / (rows / cam.fdistx),
            near,
            far,
        }
    }
}

/// Focal distance in pixels from an OpenGL aperture: `size / (2 tan(fov / 2))`
/// (the manual's Gazebo/Webots formula; `size` is the image height for Gazebo, the
/// width for Webots).
pub fn focal_from_fov(size_px: f64, fov_rad: f64) -> f64 {
    size_px / (2.0 * (fov_rad / 2.0).tan())
}

/// The pinhole camera (4.3's `TPinHoleCamera`). Change the public parameters, then
/// call [`update_camera_matrix`](Self::update_camera_matrix) to refresh `k` and `rt`.
#[derive(Clone, Debug, PartialEq)]
pub struct PinholeCamera {
    /// Optical centre position, mm.
    pub position: HPoint3D,
    /// Focus of attention (a point the optical axis goes through), mm.
    pub foa: HPoint3D,
    /// Rotation about the optical axis, radians.
    pub roll: f64,
    /// Focal distances, pixels.
    pub fdistx: f64,
    pub fdisty: f64,
    /// Optical centre: `u0` on the optical x (rows), `v0` on y (columns), pixels.
    pub u0: f64,
    pub v0: f64,
    pub skew: f64,
    pub rows: u32,
    pub columns: u32,
    /// Intrinsics `[[fx, skew*fy, u0, 0], [0, fy, v0, 0], [0, 0, 1, 0]]`.
    pub k: Matrix3x4<f64>,
    /// World to camera: rotation rows u, v, w (optical axis) and translation.
    pub rt: Matrix4<f64>,
    pub name: String,
}

impl Default for PinholeCamera {
    /// The sample `cam-in` camera: at (0, 1298.8, 0) looking at (0, 5298.8, 0),
    /// fx = fy = 505.85, u0 = 120, v0 = 160, 320x240.
    fn default() -> Self {
        let mut c = PinholeCamera {
            position: HPoint3D::point(0.0, 1298.8, 0.0),
            foa: HPoint3D::point(0.0, 5298.8, 0.0),
            roll: 0.0,
            fdistx: 505.85,
            fdisty: 505.85,
            u0: 120.0,
            v0: 160.0,
            skew: 0.0,
            rows: 240,
            columns: 320,
            k: Matrix3x4::zeros(),
            rt: Matrix4::identity(),
            name: String::new(),
        };
        c.update_camera_matrix();
        c
    }
}

/// Rows u, v, w of the world-to-camera rotation (before roll) for an optical axis
/// from `position` to `foa` (4.3's "second method").
fn axes(position: Vector3<f64>, foa: Vector3<f64>) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
    let d = foa - position;
    let n = d.norm();
    // Degenerate (foa == position): look along +Y rather than produce NaNs.
    let w = if n > 0.0 && n.is_finite() {
        d / n
    } else {
        Vector3::new(0.0, 1.0, 0.0)
    };
    let t = (-w.x).atan2(w.y);
    let mut v = Vector3::new(t.cos(), t.sin(), 0.0);
    let mut u = v.cross(&w);
    if u.z < 0.0 {
        u = -u;
        v = -v;
    }
    (u, v, w)
}

fn xyz(p: &HPoint3D) -> Vector3<f64> {
    p.euclidean().unwrap_or_else(|| Vector3::new(p.x, p.y, p.z))
}

impl PinholeCamera {
    /// A camera at `position` looking at `foa` with focal distance `f` (pixels),
    /// centred optical centre, `columns` x `rows`.
    pub fn new(position: HPoint3D, foa: HPoint3D, f: f64, columns: u32, rows: u32) -> Self {
        let mut c = PinholeCamera {
            position,
            foa,
            fdistx: f,
            fdisty: f,
            u0: rows as f64 / 2.0,
            v0: columns as f64 / 2.0,
            rows,
            columns,
            ..Default::default()
        };
        c.update_camera_matrix();
        c
    }

    /// Intrinsics of a simulated OpenGL camera: centred optical centre and
    /// `f = size / (2 tan(fov/2))`, `size` = rows (Gazebo, [`GAZEBO_FOV`]) when
    /// `fov_on_height`, else columns (Webots, [`WEBOTS_FOV`]).
    pub fn set_intrinsics_from_fov(&mut self, fov_rad: f64, fov_on_height: bool) {
        let size = if fov_on_height {
            self.rows
        } else {
            self.columns
        };
        let f = focal_from_fov(size as f64, fov_rad);
        self.fdistx = f;
        self.fdisty = f;
        self.skew = 0.0;
        self.u0 = self.rows as f64 / 2.0;
        self.v0 = self.columns as f64 / 2.0;
        self.update_camera_matrix();
    }

    /// Recomputes `k` and `rt` from position, foa, roll and the intrinsics (4.3's
    /// `update_camera_matrix`; also sets `position.h = foa.h = 1`).
    pub fn update_camera_matrix(&mut self) {
        let pos = xyz(&self.position);
        let foa = xyz(&self.foa);
        self.position = HPoint3D::point(pos.x, pos.y, pos.z);
        self.foa = HPoint3D::point(foa.x, foa.y, foa.z);
        let (u, v, w) = axes(pos, foa);
        let rab = Matrix3::from_rows(&[u.transpose(), v.transpose(), w.transpose()]);
        let (s, c) = self.roll.sin_cos();
        let rc = Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0);
        let r = rc * rab;
        let t = -(r * pos);
        let mut rt = Matrix4::identity();
        rt.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
        rt.fixed_view_mut::<3, 1>(0, 3).copy_from(&t);
        self.rt = rt;
        self.k = Matrix3x4::new(
            self.fdistx,
            self.skew * self.fdisty,
            self.u0,
            0.0,
            0.0,
            self.fdisty,
            self.v0,
            0.0,
            0.0,
            0.0,
            1.0,
            0.0,
        );
    }

    /// The 3x3 intrinsic part of `k`.
    pub fn k3(&self) -> Matrix3<f64> {
        self.k.fixed_view::<3, 3>(0, 0).into_owned()
    }

    /// The 3x3 rotation part of `rt`.
    pub fn rotation(&self) -> Matrix3<f64> {
        self.rt.fixed_view::<3, 3>(0, 0).into_owned()
    }

    /// Projects a 3D point (mm) to optical pixel coordinates. The result's `h` is 1
    /// when the point is in front of the camera, −1 when it is behind (x and y are
    /// still filled, mirrored) and 0 when it projects to infinity (x, y unnormalised).
    pub fn project(&self, p: HPoint3D) -> HPoint2D {
        let a = self.rt * p.to_vector();
        let o = self.k3() * Vector3::new(a.x, a.y, a.z);
        if o.z == 0.0 {
            return HPoint2D::new(o.x, o.y, 0.0);
        }
        let h = if a.z * a.w <= 0.0 { -1.0 } else { 1.0 };
        HPoint2D::new(o.x / o.z, o.y / o.z, h)
    }

    /// The pixel of a point in front of the camera, `None` otherwise.
    pub fn project_visible(&self, p: HPoint3D) -> Option<HPoint2D> {
        let q = self.project(p);
        (q.h > 0.0).then_some(q)
    }

    /// The 3D point (mm, h = 1) on the ray through optical pixel `p` at depth `fdistx`
    /// in front of the camera (4.3's `backproject`: join it with `position` for the
    /// ray). `None` when `p.h <= 0`.
    pub fn backproject(&self, p: HPoint2D) -> Option<HPoint3D> {
        if p.h <= 0.0 || !p.h.is_finite() {
            return None;
        }
        let f = self.fdistx;
        let q = Vector3::new(p.x * f / p.h, p.y * f / p.h, f);
        let kinv = self.k3().try_inverse()?;
        let cam = kinv * q;
        let r = self.rotation();
        let world = r.transpose() * cam + xyz(&self.position);
        Some(HPoint3D::point(world.x, world.y, world.z))
    }

    /// The unit direction (world frame) of the ray through optical pixel `p`.
    pub fn ray(&self, p: HPoint2D) -> Option<Vector3<f64>> {
        let q = self.backproject(p)?;
        let d = xyz(&q) - xyz(&self.position);
        let n = d.norm();
        (n > 0.0).then(|| d / n)
    }

    /// Clips the image of a 3D segment whose ends were projected to `p1`, `p2` by
    /// [`project`](Self::project) (x, y in pixels; `h` = +1 in front, −1 behind) to the image `[0, rows−1] x [0,
    /// columns−1]` (optical). Returns the visible part, or `None` when nothing is
    /// visible. Unlike 4.3.0, a segment crossing the camera plane is drawn: its
    /// visible part is the ray from the point in front away from the other's image.
    pub fn displayline(&self, p1: HPoint2D, p2: HPoint2D) -> Option<(HPoint2D, HPoint2D)> {
        if p1.h == 0.0 || p2.h == 0.0 {
            return None;
        }
        let xmax = self.rows as f64 - 1.0;
        let ymax = self.columns as f64 - 1.0;
        // As in 4.3, x and y are already divided; h only says in front (+) or behind (−).
        let (a, b) = (p1, p2);
        let (front1, front2) = (p1.h > 0.0, p2.h > 0.0);
        let (origin, dir, tmax) = match (front1, front2) {
            (false, false) => return None,
            (true, true) => ((a.x, a.y), (b.x - a.x, b.y - a.y), 1.0),
            (true, false) => ((a.x, a.y), (a.x - b.x, a.y - b.y), f64::INFINITY),
            (false, true) => ((b.x, b.y), (b.x - a.x, b.y - a.y), f64::INFINITY),
        };
        let (t0, t1) = clip_liang_barsky(origin, dir, tmax, xmax, ymax)?;
        let at = |t: f64| HPoint2D::new(origin.0 + t * dir.0, origin.1 + t * dir.1, 1.0);
        if !t1.is_finite() {
            return None;
        }
        Some((at(t0), at(t1)))
    }

    /// Optical coordinates of a graphic pixel of this camera's image.
    pub fn graphic_to_optical(&self, column: f64, row: f64) -> HPoint2D {
        let (x, y) = graphic_to_optical(column, row, self.rows);
        HPoint2D::new(x, y, 1.0)
    }

    /// Graphic (column, row) of an optical point of this camera's image (`x`, `y` as
    /// [`project`](Self::project) leaves them; `h` is not used).
    pub fn optical_to_graphic(&self, p: HPoint2D) -> (f64, f64) {
        optical_to_graphic(p.x, p.y, self.rows)
    }

    /// The OpenGL view matrix (world mm to camera): `rt`, whose rows are the image's
    /// up (optical x), right (optical y) and forward (optical axis) directions.
    pub fn gl_view(&self) -> Matrix4<f64> {
        self.rt
    }

    /// The OpenGL projection matrix (camera coordinates of [`gl_view`](Self::gl_view)
    /// to clip space) for a `columns` x `rows` viewport, with clipping distances
    /// `near` and `far` (mm): the pixel centre of optical (x, y) lands at window
    /// coordinates (y + 0.5, x + 0.5), so OpenGL draws every point on the pixel
    /// [`project`](Self::project) gives (optical centre, skew and both focal distances
    /// included).
    pub fn gl_projection(&self, near: f64, far: f64) -> Matrix4<f64> {
        let (w, h) = (self.columns.max(1) as f64, self.rows.max(1) as f64);
        let (n, f) = (near.max(1e-6), far.max(near.max(1e-6) * 1.0001));
        let a = (f + n) / (f - n);
        let b = -2.0 * f * n / (f - n);
        Matrix4::new(
            0.0,
            2.0 * self.fdisty / w,
            (2.0 * self.v0 + 1.0) / w - 1.0,
            0.0,
            2.0 * self.fdistx / h,
            2.0 * self.skew * self.fdisty / h,
            (2.0 * self.u0 + 1.0) / h - 1.0,
            0.0,
            0.0,
            0.0,
            a,
            b,
            0.0,
            0.0,
            1.0,
            0.0,
        )
    }

    /// Reads a camera file (see the module doc) and updates the matrices.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, ProgeoError> {
        let path = path.as_ref();
        let text = ProgeoError::read(path)?;
        Self::parse(&text, path)
    }

    /// Parses camera-file text; `file` names it in errors. Missing keys keep the
    /// [`Default`] camera's values.
    pub fn parse(text: &str, file: &Path) -> Result<Self, ProgeoError> {
        let mut c = PinholeCamera::default();
        for (n, raw) in text.lines().enumerate() {
            let line = raw.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let mut words = line.split_whitespace();
            let key = words.next().unwrap_or_default();
            let known = matches!(
                key,
                "positionX"
                    | "positionY"
                    | "positionZ"
                    | "positionH"
                    | "FOApositionX"
                    | "FOApositionY"
                    | "FOApositionZ"
                    | "FOApositionH"
                    | "roll"
                    | "f"
                    | "fx"
                    | "fy"
                    | "skew"
                    | "u0"
                    | "v0"
                    | "columns"
                    | "rows"
            );
            if !known {
                tracing::debug!("{}:{}: ignoring unknown key `{key}`", file.display(), n + 1);
                continue;
            }
            let err = |message: String| ProgeoError::Syntax {
                file: file.to_path_buf(),
                line: n + 1,
                message,
            };
            let value = words
                .next()
                .ok_or_else(|| err(format!("`{key}` needs a number after it")))?;
            let v: f64 = value
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite())
                .ok_or_else(|| err(format!("`{key} {value}`: expected a number")))?;
            if let Some(extra) = words.next().filter(|w| !w.starts_with('#')) {
                return Err(err(format!(
                    "`{key}` takes one value; unexpected `{extra}`"
                )));
            }
            let count = |v: f64| -> Result<u32, ProgeoError> {
                if (1.0..=100_000.0).contains(&v) && v.fract() == 0.0 {
                    Ok(v as u32)
                } else {
                    Err(err(format!(
                        "`{key} {value}`: expected a whole number of pixels (1..100000)"
                    )))
                }
            };
            match key {
                "positionX" => c.position.x = v,
                "positionY" => c.position.y = v,
                "positionZ" => c.position.z = v,
                "positionH" => c.position.h = v,
                "FOApositionX" => c.foa.x = v,
                "FOApositionY" => c.foa.y = v,
                "FOApositionZ" => c.foa.z = v,
                "FOApositionH" => c.foa.h = v,
                "roll" => c.roll = v,
                "f" => {
                    c.fdistx = v;
                    c.fdisty = v;
                }
                "fx" => c.fdistx = v,
                "fy" => c.fdisty = v,
                "skew" => c.skew = v,
                "u0" => c.u0 = v,
                "v0" => c.v0 = v,
                "columns" => c.columns = count(v)?,
                _ => c.rows = count(v)?,
            }
        }
        if c.position.h == 0.0 || c.foa.h == 0.0 {
            return Err(ProgeoError::Invalid {
                file: file.to_path_buf(),
                message: "positionH and FOApositionH must not be 0".into(),
            });
        }
        if (xyz(&c.foa) - xyz(&c.position)).norm() == 0.0 {
            return Err(ProgeoError::Invalid {
                file: file.to_path_buf(),
                message: "the FOA equals the position: the camera looks nowhere".into(),
            });
        }
        if c.fdistx == 0.0 || c.fdisty == 0.0 {
            return Err(ProgeoError::Invalid {
                file: file.to_path_buf(),
                message: "fx and fy must not be 0".into(),
            });
        }
        c.update_camera_matrix();
        Ok(c)
    }

    /// The camera file text, in 4.3's `save_cam` layout.
    pub fn to_file_string(&self) -> String {
        let p = &self.position;
        let f = &self.foa;
        format!(
            "#extrinsics, position\npositionX {:.6}\npositionY {:.6}\npositionZ {:.6}\npositionH {:.6}\n\n \
             #extrinsics, orientation\nFOApositionX {:.6}\nFOApositionY {:.6}\nFOApositionZ {:.6}\n\
             FOApositionH {:.6}\nroll {:.6}\n\n #intrinsics\nfx {:.6}\nfy {:.6}\nskew {:.6}\nu0 {:.6}\n\
             v0 {:.6}\ncolumns {}\nrows {}\n",
            p.x,
            p.y,
            p.z,
            p.h,
            f.x,
            f.y,
            f.z,
            f.h,
            self.roll,
            self.fdistx,
            self.fdisty,
            self.skew,
            self.u0,
            self.v0,
            self.columns,
            self.rows
        )
    }

    /// Writes the camera file.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), ProgeoError> {
        let path = path.as_ref();
        std::fs::write(path, self.to_file_string()).map_err(|source| ProgeoError::Io {
            file: path.to_path_buf(),
            source,
        })
    }
}

/// Clips `origin + t*dir`, t in [0, tmax], to [0,xmax]x[0,ymax]. Returns (t0, t1).
fn clip_liang_barsky(
    origin: (f64, f64),
    dir: (f64, f64),
    tmax: f64,
    xmax: f64,
    ymax: f64,
) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (0.0f64, tmax);
    let checks = [
        (-dir.0, origin.0),
        (dir.0, xmax - origin.0),
        (-dir.1, origin.1),
        (dir.1, ymax - origin.1),
    ];
    for (p, q) in checks {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    (t0 <= t1 && t0.is_finite()).then_some((t0, t1))
}

impl fmt::Display for PinholeCamera {
    /// 4.3's `display_camerainfo`: every parameter and both matrices.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p = &self.position;
        let a = &self.foa;
        writeln!(f, "------------------------------------------------------")?;
        writeln!(f, "Camera {}", self.name)?;
        writeln!(
            f,
            "     Position: (X,Y,Z,H)=({:.4},{:.4},{:.4},{:.4}) mm",
            p.x, p.y, p.z, p.h
        )?;
        writeln!(
            f,
            "     Focus of Attention: (x,y,z,h)=({:.4},{:.4},{:.4},{:.4}) mm",
            a.x, a.y, a.z, a.h
        )?;
        writeln!(
            f,
            "     Roll: {:.4} rad ({:.2} deg)",
            self.roll,
            self.roll.to_degrees()
        )?;
        writeln!(
            f,
            "     Focus distance: fx={:.4} fy={:.4} pixels",
            self.fdistx, self.fdisty
        )?;
        writeln!(f, "     Skew: {:.4}", self.skew)?;
        writeln!(
            f,
            "     Optical centre: (u0,v0)=({:.4},{:.4}) pixels (u0 on rows, v0 on columns)",
            self.u0, self.v0
        )?;
        writeln!(
            f,
            "     Image size: {} columns x {} rows",
            self.columns, self.rows
        )?;
        writeln!(f, "     K matrix:")?;
        for r in 0..3 {
            writeln!(
                f,
                "          {:12.4} {:12.4} {:12.4} {:12.4}",
                self.k[(r, 0)],
                self.k[(r, 1)],
                self.k[(r, 2)],
                self.k[(r, 3)]
            )?;
        }
        writeln!(f, "     RT matrix:")?;
        for r in 0..4 {
            writeln!(
                f,
                "          {:12.4} {:12.4} {:12.4} {:12.4}",
                self.rt[(r, 0)],
                self.rt[(r, 1)],
                self.rt[(r, 2)],
                self.rt[(r, 3)]
            )?;
        }
        write!(f, "------------------------------------------------------")
    }
}

/// Two pinhole cameras on a rigid bar (4.3's `TPinHoleStereocamera`).
#[derive(Clone, Debug, PartialEq)]
pub struct StereoCamera {
    /// Centre of the bar, mm.
    pub position: HPoint3D,
    /// Common focus of attention direction (the cameras' axes are parallel), mm.
    pub foa: HPoint3D,
    pub roll: f64,
    /// Left (−baseline/2) and right (+baseline/2) cameras; their intrinsics are
    /// kept, their extrinsics are set by [`update_stereocamera_matrix`](Self::update_stereocamera_matrix).
    pub camera1: PinholeCamera,
    pub camera2: PinholeCamera,
    /// Distance between the two optical centres, mm.
    pub baseline: f64,
    pub name: String,
}

impl StereoCamera {
    /// Places both cameras ±baseline/2 along the rig's horizontal image axis (row 2 of
    /// its rotation, before roll), with parallel optical axes, same roll, and updates
    /// both matrices.
    pub fn update_stereocamera_matrix(&mut self) {
        let pos = xyz(&self.position);
        let foa = xyz(&self.foa);
        let (_, v, _) = axes(pos, foa);
        let off = v * (self.baseline / 2.0);
        for (cam, sign) in [(&mut self.camera1, -1.0), (&mut self.camera2, 1.0)] {
            let p = pos + off * sign;
            let a = foa + off * sign;
            cam.position = HPoint3D::point(p.x, p.y, p.z);
            cam.foa = HPoint3D::point(a.x, a.y, a.z);
            cam.roll = self.roll;
            cam.update_camera_matrix();
        }
    }
}

/// A world file: 3D segments plus the camera files extrinsics reads and writes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct World {
    pub lines: Vec<(HPoint3D, HPoint3D)>,
    pub camera_in: Option<PathBuf>,
    pub camera_out: Option<PathBuf>,
    /// `maxX minX maxY minY maxZ minZ` when given (4.3 reads and ignores them).
    pub bounds: [Option<f64>; 6],
}

const BOUND_KEYS: [&str; 6] = ["maxX", "minX", "maxY", "minY", "maxZ", "minZ"];

impl World {
    pub fn load(path: impl AsRef<Path>) -> Result<Self, ProgeoError> {
        let path = path.as_ref();
        let text = ProgeoError::read(path)?;
        Self::parse(&text, path)
    }

    /// Parses world-file text; `file` names it in errors.
    pub fn parse(text: &str, file: &Path) -> Result<Self, ProgeoError> {
        let mut w = World::default();
        for (n, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or_default().trim();
            let mut words = line.split_whitespace();
            let Some(key) = words.next() else { continue };
            let err = |message: String| ProgeoError::Syntax {
                file: file.to_path_buf(),
                line: n + 1,
                message,
            };
            let rest: Vec<&str> = words.collect();
            match key {
                "worldline" => {
                    let v: Vec<f64> = rest
                        .iter()
                        .map(|s| s.parse::<f64>().ok().filter(|v| v.is_finite()))
                        .collect::<Option<_>>()
                        .filter(|v: &Vec<f64>| v.len() == 8)
                        .ok_or_else(|| {
                            err(format!(
                                "`worldline {}`: expected 8 numbers X1 Y1 Z1 H1 X2 Y2 Z2 H2 (mm)",
                                rest.join(" ")
                            ))
                        })?;
                    w.lines.push((
                        HPoint3D::new(v[0], v[1], v[2], v[3]),
                        HPoint3D::new(v[4], v[5], v[6], v[7]),
                    ));
                }
                "cameraINfile" | "cameraOUTfile" => {
                    let [f] = rest[..] else {
                        return Err(err(format!("`{key}` needs one file name")));
                    };
                    let f = Some(PathBuf::from(f));
                    if key == "cameraINfile" {
                        w.camera_in = f;
                    } else {
                        w.camera_out = f;
                    }
                }
                k if BOUND_KEYS.contains(&k) => {
                    let i = BOUND_KEYS.iter().position(|b| *b == k).unwrap_or(0);
                    let v = rest
                        .first()
                        .and_then(|s| s.parse::<f64>().ok())
                        .ok_or_else(|| err(format!("`{k}` needs a number (mm)")))?;
                    w.bounds[i] = Some(v);
                }
                _ => tracing::debug!("{}:{}: ignoring `{key}`", file.display(), n + 1),
            }
        }
        Ok(w)
    }

    /// The world file text (round-trips through [`parse`](Self::parse)).
    pub fn to_file_string(&self) -> String {
        let mut s = String::new();
        if let Some(f) = &self.camera_in {
            s += &format!("cameraINfile {}\n", f.display());
        }
        if let Some(f) = &self.camera_out {
            s += &format!("cameraOUTfile {}\n", f.display());
        }
        for (k, v) in BOUND_KEYS.iter().zip(self.bounds) {
            if let Some(v) = v {
                s += &format!("{k} {v}\n");
            }
        }
        for (a, b) in &self.lines {
            s += &format!(
                "worldline {} {} {} {} {} {} {} {}\n",
                a.x, a.y, a.z, a.h, b.x, b.y, b.z, b.h
            );
        }
        s
    }

    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), ProgeoError> {
        let path = path.as_ref();
        std::fs::write(path, self.to_file_string()).map_err(|source| ProgeoError::Io {
            file: path.to_path_buf(),
            source,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cam_in_projects_hand_computed_point() {
        let c = PinholeCamera::default();
        // Camera frame: u = +Z (up), v = +X (right), w = +Y (axis).
        let p = c.project(HPoint3D::point(100.0, 2298.8, 50.0));
        assert!((p.x - (505.85 * 50.0 / 1000.0 + 120.0)).abs() < 1e-9);
        assert!((p.y - (505.85 * 100.0 / 1000.0 + 160.0)).abs() < 1e-9);
        assert_eq!(p.h, 1.0);
    }
}
