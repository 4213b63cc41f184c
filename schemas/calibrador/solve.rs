//! Calibration from a known 3D pattern: normalised DLT, RQ decomposition into
//! K, R, t, Levenberg-Marquardt refinement of (fx, fy, cx, cy, rotation, t) with
//! nalgebra, and the conversion to a progeo camera.
//!
//! Image points are graphic pixels (u = column to the right, v = row down); the
//! camera frame is OpenCV's (x right, y down, z forward): u = fx·x/z + cx,
//! v = fy·y/z + cy, zero skew.

use nalgebra::{DMatrix, DVector, Matrix3, Matrix3x4, Rotation3, Vector3};

use crate::progeo::{HPoint3D, PinholeCamera};

/// A calibrated camera.
#[derive(Clone, Debug, PartialEq)]
pub struct Calibration {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// World → camera rotation.
    pub r: Matrix3<f64>,
    /// World → camera translation (mm).
    pub t: Vector3<f64>,
    /// Root-mean-square reprojection error, pixels.
    pub rms: f64,
}

impl Calibration {
    /// The camera centre in the world, mm.
    pub fn position(&self) -> Vector3<f64> {
        -(self.r.transpose() * self.t)
    }
    /// The pixel (u, v) of a world point, `None` behind the camera.
    pub fn project(&self, p: [f64; 3]) -> Option<(f64, f64)> {
        let c = self.r * Vector3::from(p) + self.t;
        (c.z > 1e-9).then(|| (self.fx * c.x / c.z + self.cx, self.fy * c.y / c.z + self.cy))
    }
    fn rms_of(&self, world: &[[f64; 3]], image: &[(f64, f64)]) -> f64 {
        let mut s = 0.0;
        for (w, i) in world.iter().zip(image) {
            match self.project(*w) {
                Some(p) => s += (p.0 - i.0).powi(2) + (p.1 - i.1).powi(2),
                None => return f64::INFINITY,
            }
        }
        (s / world.len().max(1) as f64).sqrt()
    }

    /// The progeo camera (4.3's conventions) of a `columns` x `rows` image: position,
    /// FOA one metre ahead, roll, fdistx = fy (rows), fdisty = fx (columns),
    /// u0 = rows − 1 − cy, v0 = cx.
    pub fn to_progeo(&self, columns: u32, rows: u32) -> PinholeCamera {
        let c = self.position();
        let fwd = self.r.row(2).transpose();
        let foa = c + fwd * 1000.0;
        let mut cam = PinholeCamera::new(
            HPoint3D::point(c.x, c.y, c.z),
            HPoint3D::point(foa.x, foa.y, foa.z),
            self.fy,
            columns,
            rows,
        );
        cam.fdistx = self.fy;
        cam.fdisty = self.fx;
        cam.u0 = rows as f64 - 1.0 - self.cy;
        cam.v0 = self.cx;
        cam.roll = 0.0;
        cam.update_camera_matrix();
        // progeo's first row is rc(roll)·(u, v, w): r1 = cos·u + sin·v, and r1 is the
        // optical x axis (up) = −(OpenCV's y axis).
        let rab = cam.rotation();
        let want = -self.r.row(1).transpose();
        let (u, v) = (rab.row(0).transpose(), rab.row(1).transpose());
        cam.roll = want.dot(&v).atan2(want.dot(&u));
        cam.update_camera_matrix();
        cam
    }
}

/// Why a calibration failed.
#[derive(Clone, Debug, thiserror::Error, PartialEq)]
pub enum CalibrationError {
    #[error("{0} points with image coordinates: 6 or more are needed")]
    TooFew(usize),
    #[error("the pattern's points are degenerate (all in one plane or a line?)")]
    Degenerate,
}

fn normaliser2(p: &[(f64, f64)]) -> Matrix3<f64> {
    let n = p.len() as f64;
    let (mx, my) = p
        .iter()
        .fold((0.0, 0.0), |a, q| (a.0 + q.0 / n, a.1 + q.1 / n));
    let d = p
        .iter()
        .map(|q| ((q.0 - mx).powi(2) + (q.1 - my).powi(2)).sqrt())
        .sum::<f64>()
        / n;
    let s = if d > 1e-12 {
        std::f64::consts::SQRT_2 / d
    } else {
        1.0
    };
    Matrix3::new(s, 0.0, -s * mx, 0.0, s, -s * my, 0.0, 0.0, 1.0)
}

fn normaliser3(p: &[[f64; 3]]) -> nalgebra::Matrix4<f64> {
    let n = p.len() as f64;
    let m = p.iter().fold([0.0; 3], |a, q| {
        [a[0] + q[0] / n, a[1] + q[1] / n, a[2] + q[2] / n]
    });
    let d = p
        .iter()
        .map(|q| ((q[0] - m[0]).powi(2) + (q[1] - m[1]).powi(2) + (q[2] - m[2]).powi(2)).sqrt())
        .sum::<f64>()
        / n;
    let s = if d > 1e-12 { 3f64.sqrt() / d } else { 1.0 };
    let mut u = nalgebra::Matrix4::identity() * s;
    u[(3, 3)] = 1.0;
    u[(0, 3)] = -s * m[0];
    u[(1, 3)] = -s * m[1];
    u[(2, 3)] = -s * m[2];
    u
}

/// The 3x4 projection matrix by the normalised DLT.
pub fn dlt(world: &[[f64; 3]], image: &[(f64, f64)]) -> Result<Matrix3x4<f64>, CalibrationError> {
    if world.len() < 6 || world.len() != image.len() {
        return Err(CalibrationError::TooFew(world.len().min(image.len())));
    }
    let t = normaliser2(image);
    let u = normaliser3(world);
    let mut a = DMatrix::<f64>::zeros(2 * world.len(), 12);
    for (k, (w, i)) in world.iter().zip(image).enumerate() {
        let x = u * nalgebra::Vector4::new(w[0], w[1], w[2], 1.0);
        let p = t * Vector3::new(i.0, i.1, 1.0);
        for j in 0..4 {
            a[(2 * k, j)] = x[j];
            a[(2 * k, 8 + j)] = -p.x * x[j];
            a[(2 * k + 1, 4 + j)] = x[j];
            a[(2 * k + 1, 8 + j)] = -p.y * x[j];
        }
    }
    let ata = a.transpose() * &a;
    let eig = ata.symmetric_eigen();
    let (imin, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .ok_or(CalibrationError::Degenerate)?;
    let h = eig.eigenvectors.column(imin);
    let pn = Matrix3x4::from_row_slice(h.as_slice());
    let tinv = t.try_inverse().ok_or(CalibrationError::Degenerate)?;
    let p = tinv * pn * u;
    if p.iter().any(|v| !v.is_finite()) {
        return Err(CalibrationError::Degenerate);
    }
    Ok(p)
}

/// K (intrinsics), R (world → camera rotation), t (translation, mm).
pub type Krt = (Matrix3<f64>, Matrix3<f64>, Vector3<f64>);

/// K, R, t of a projection matrix (RQ decomposition, positive focal lengths,
/// det R = +1, the pattern in front).
pub fn decompose(p: &Matrix3x4<f64>) -> Result<Krt, CalibrationError> {
    let mut p = *p;
    let m = p.fixed_view::<3, 3>(0, 0).into_owned();
    if m.determinant() < 0.0 {
        p = -p;
    }
    let m = p.fixed_view::<3, 3>(0, 0).into_owned();
    let j = Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0);
    let qr = (j * m).transpose().qr();
    let (q, r) = (qr.q(), qr.r());
    let mut k = j * r.transpose() * j;
    let mut rot = j * q.transpose();
    for i in 0..3 {
        if k[(i, i)] < 0.0 {
            k.set_column(i, &(-k.column(i)));
            rot.set_row(i, &(-rot.row(i)));
        }
    }
    if k[(2, 2)].abs() < 1e-15 {
        return Err(CalibrationError::Degenerate);
    }
    let kinv = k.try_inverse().ok_or(CalibrationError::Degenerate)?;
    let t = kinv * p.column(3);
    let k = k / k[(2, 2)];
    if rot.determinant() < 0.0 {
        return Err(CalibrationError::Degenerate);
    }
    Ok((k, rot, t))
}

fn unpack(x: &DVector<f64>) -> Calibration {
    Calibration {
        fx: x[0],
        fy: x[1],
        cx: x[2],
        cy: x[3],
        r: Rotation3::from_scaled_axis(Vector3::new(x[4], x[5], x[6])).into_inner(),
        t: Vector3::new(x[7], x[8], x[9]),
        rms: 0.0,
    }
}

fn residuals(x: &DVector<f64>, world: &[[f64; 3]], image: &[(f64, f64)]) -> DVector<f64> {
    let c = unpack(x);
    let mut r = DVector::zeros(2 * world.len());
    for (k, (w, i)) in world.iter().zip(image).enumerate() {
        let q = c.r * Vector3::from(*w) + c.t;
        let z = if q.z.abs() < 1e-9 { 1e-9 } else { q.z };
        r[2 * k] = c.fx * q.x / z + c.cx - i.0;
        r[2 * k + 1] = c.fy * q.y / z + c.cy - i.1;
    }
    r
}

/// Calibrates from ≥ 6 non-coplanar pattern points (mm) and their pixels: DLT,
/// decomposition, then Levenberg-Marquardt on the reprojection error.
pub fn calibrate(
    world: &[[f64; 3]],
    image: &[(f64, f64)],
) -> Result<Calibration, CalibrationError> {
    let p = dlt(world, image)?;
    let (k, r, t) = decompose(&p)?;
    let rv = Rotation3::from_matrix(&r).scaled_axis();
    let mut x = DVector::from_vec(vec![
        k[(0, 0)],
        k[(1, 1)],
        k[(0, 2)],
        k[(1, 2)],
        rv.x,
        rv.y,
        rv.z,
        t.x,
        t.y,
        t.z,
    ]);
    let mut res = residuals(&x, world, image);
    let mut cost = res.norm_squared();
    let mut lambda = 1e-3;
    for _ in 0..100 {
        // Numerical Jacobian (central differences).
        let mut jac = DMatrix::zeros(res.len(), 10);
        for c in 0..10 {
            let h = 1e-6 * x[c].abs().max(1e-3);
            let mut xp = x.clone();
            xp[c] += h;
            let mut xm = x.clone();
            xm[c] -= h;
            let d = (residuals(&xp, world, image) - residuals(&xm, world, image)) / (2.0 * h);
            jac.set_column(c, &d);
        }
        let jtj = jac.transpose() * &jac;
        let g = jac.transpose() * &res;
        let mut improved = false;
        for _ in 0..10 {
            let mut a = jtj.clone();
            for i in 0..10 {
                a[(i, i)] += lambda * jtj[(i, i)].max(1e-12);
            }
            let Some(step) = a.lu().solve(&(-&g)) else {
                lambda *= 10.0;
                continue;
            };
            let xn = &x + &step;
            let rn = residuals(&xn, world, image);
            let cn = rn.norm_squared();
            if cn < cost {
                let done = (cost - cn) < 1e-12 * cost.max(1e-30);
                x = xn;
                res = rn;
                cost = cn;
                lambda = (lambda / 10.0).max(1e-12);
                improved = !done;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    let mut c = unpack(&x);
    c.rms = c.rms_of(world, image);
    if !c.rms.is_finite() {
        return Err(CalibrationError::Degenerate);
    }
    Ok(c)
}
