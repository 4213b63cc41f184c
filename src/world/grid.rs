//! A uniform grid over the walls: each cell lists the wall segments that cross it,
//! so a ray visits only the cells it crosses (Amanatides-Woo) and a proximity
//! query only the cells around a point. [`World::finish`](super::World::finish)
//! builds it.

use super::{
    Segment,
    geometry::{Point2, cross, ray_segment},
};

/// The nearest of the segments `idx` along the ray o + t·d within `max`: (t, index).
pub fn cast_every(
    segs: &[Segment],
    idx: impl Iterator<Item = usize>,
    o: Point2,
    d: Point2,
    max: f64,
) -> Option<(f64, usize)> {
    let mut best: Option<(f64, usize)> = None;
    for i in idx {
        if let Some(t) = ray_segment(o, d, &segs[i])
            && t <= max
            && best.is_none_or(|(b, _)| t < b)
        {
            best = Some((t, i));
        }
    }
    best
}

/// A uniform grid over the walls: each cell lists the segments that cross it.
#[derive(Clone, Debug)]
pub struct SegmentGrid {
    /// Walls were added since the grid was built (cast and near test every wall).
    pub dirty: bool,
    origin: Point2,
    cell: f64,
    nx: usize,
    ny: usize,
    /// CSR: segments of cell k are `items[start[k]..start[k+1]]`.
    start: Vec<u32>,
    items: Vec<u32>,
}

impl Default for SegmentGrid {
    fn default() -> Self {
        SegmentGrid {
            dirty: true,
            origin: [0.0, 0.0],
            cell: 1.0,
            nx: 0,
            ny: 0,
            start: vec![0],
            items: Vec::new(),
        }
    }
}

impl SegmentGrid {
    pub fn build(segs: &[Segment]) -> SegmentGrid {
        if segs.is_empty() {
            return SegmentGrid {
                dirty: false,
                ..SegmentGrid::default()
            };
        }
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        let mut total_len = 0.0;
        for s in segs {
            for p in [s.a, s.b] {
                lo = [lo[0].min(p[0]), lo[1].min(p[1])];
                hi = [hi[0].max(p[0]), hi[1].max(p[1])];
            }
            total_len += ((s.b[0] - s.a[0]).powi(2) + (s.b[1] - s.a[1]).powi(2)).sqrt();
        }
        let ext = [(hi[0] - lo[0]).max(1.0), (hi[1] - lo[1]).max(1.0)];
        // About 2 segments per occupied cell, and at most 256x256 cells.
        let mean = total_len / segs.len() as f64;
        let cell = mean.clamp(100.0, 2000.0).max(ext[0].max(ext[1]) / 256.0);
        let origin = [lo[0] - 1.0, lo[1] - 1.0];
        let nx = ((ext[0] + 2.0) / cell).ceil() as usize + 1;
        let ny = ((ext[1] + 2.0) / cell).ceil() as usize + 1;
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); nx * ny];
        for (k, s) in segs.iter().enumerate() {
            let ci =
                |v: f64, o: f64, n: usize| (((v - o) / cell).floor().max(0.0) as usize).min(n - 1);
            let (i0, i1) = (
                ci(s.a[0].min(s.b[0]), origin[0], nx),
                ci(s.a[0].max(s.b[0]), origin[0], nx),
            );
            let (j0, j1) = (
                ci(s.a[1].min(s.b[1]), origin[1], ny),
                ci(s.a[1].max(s.b[1]), origin[1], ny),
            );
            let e = [s.b[0] - s.a[0], s.b[1] - s.a[1]];
            for j in j0..=j1 {
                for i in i0..=i1 {
                    // Keep the cell unless all its corners lie strictly on one side.
                    let x0 = origin[0] + i as f64 * cell;
                    let y0 = origin[1] + j as f64 * cell;
                    let sides = [
                        [x0, y0],
                        [x0 + cell, y0],
                        [x0, y0 + cell],
                        [x0 + cell, y0 + cell],
                    ]
                    .map(|c| cross(e, [c[0] - s.a[0], c[1] - s.a[1]]).signum());
                    if sides.iter().all(|&v| v > 0.0) || sides.iter().all(|&v| v < 0.0) {
                        continue;
                    }
                    lists[j * nx + i].push(k as u32);
                }
            }
        }
        let mut start = Vec::with_capacity(nx * ny + 1);
        let mut items = Vec::new();
        start.push(0);
        for l in &lists {
            items.extend_from_slice(l);
            start.push(items.len() as u32);
        }
        SegmentGrid {
            dirty: false,
            origin,
            cell,
            nx,
            ny,
            start,
            items,
        }
    }

    #[inline]
    fn cell_items(&self, i: usize, j: usize) -> &[u32] {
        let k = j * self.nx + i;
        &self.items[self.start[k] as usize..self.start[k + 1] as usize]
    }

    pub fn near(&self, p: Point2, r: f64, mut f: impl FnMut(u32)) {
        if self.nx == 0 {
            return;
        }
        let ci = |v: f64, o: f64, n: usize| -> Option<(usize, usize)> {
            let a = ((v - r - o) / self.cell).floor();
            let b = ((v + r - o) / self.cell).floor();
            if b < 0.0 || a >= n as f64 {
                return None;
            }
            Some((a.max(0.0) as usize, (b as usize).min(n - 1)))
        };
        let (Some((i0, i1)), Some((j0, j1))) = (
            ci(p[0], self.origin[0], self.nx),
            ci(p[1], self.origin[1], self.ny),
        ) else {
            return;
        };
        for j in j0..=j1 {
            for i in i0..=i1 {
                self.cell_items(i, j).iter().for_each(|&k| f(k));
            }
        }
    }

    /// Amanatides-Woo traversal of the cells the ray crosses.
    pub fn cast(&self, segs: &[Segment], o: Point2, d: Point2, max: f64) -> Option<(f64, usize)> {
        if self.nx == 0 {
            return None;
        }
        let size = [self.nx as f64 * self.cell, self.ny as f64 * self.cell];
        // Clip the ray to the grid's box.
        let mut t0: f64 = 0.0;
        let mut t1: f64 = max;
        for a in 0..2 {
            let lo = self.origin[a];
            let hi = lo + size[a];
            if d[a].abs() < 1e-15 {
                if o[a] < lo || o[a] > hi {
                    return None;
                }
            } else {
                let (mut ta, mut tb) = ((lo - o[a]) / d[a], (hi - o[a]) / d[a]);
                if ta > tb {
                    std::mem::swap(&mut ta, &mut tb);
                }
                t0 = t0.max(ta);
                t1 = t1.min(tb);
            }
        }
        if t0 > t1 {
            return None;
        }
        let p = [o[0] + d[0] * t0, o[1] + d[1] * t0];
        let mut i =
            (((p[0] - self.origin[0]) / self.cell).floor().max(0.0) as usize).min(self.nx - 1);
        let mut j =
            (((p[1] - self.origin[1]) / self.cell).floor().max(0.0) as usize).min(self.ny - 1);
        let step = |dv: f64| if dv > 0.0 { 1isize } else { -1 };
        let (si, sj) = (step(d[0]), step(d[1]));
        let next = |idx: usize, s: isize, a: usize| -> f64 {
            if d[a].abs() < 1e-15 {
                return f64::INFINITY;
            }
            let b = self.origin[a] + (idx as f64 + if s > 0 { 1.0 } else { 0.0 }) * self.cell;
            (b - o[a]) / d[a]
        };
        let mut tx = next(i, si, 0);
        let mut ty = next(j, sj, 1);
        let dtx = if d[0].abs() < 1e-15 {
            f64::INFINITY
        } else {
            self.cell / d[0].abs()
        };
        let dty = if d[1].abs() < 1e-15 {
            f64::INFINITY
        } else {
            self.cell / d[1].abs()
        };
        let mut best: Option<(f64, usize)> = None;
        loop {
            for &k in self.cell_items(i, j) {
                if let Some(t) = ray_segment(o, d, &segs[k as usize])
                    && t <= max
                    && best.is_none_or(|(b, _)| t < b)
                {
                    best = Some((t, k as usize));
                }
            }
            let exit = tx.min(ty);
            if best.is_some_and(|(b, _)| b <= exit) || exit > t1 {
                return best;
            }
            if tx < ty {
                let ni = i as isize + si;
                if ni < 0 || ni >= self.nx as isize {
                    return best;
                }
                i = ni as usize;
                tx += dtx;
            } else {
                let nj = j as isize + sj;
                if nj < 0 || nj >= self.ny as isize {
                    return best;
                }
                j = nj as usize;
                ty += dty;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::{BoxObstacle, World};

    #[test]
    fn grid_cast_matches_brute_force() {
        let mut w = World::new();
        w.add_room([0.0, 0.0], [10000.0, 8000.0], 1000.0, [1, 2, 3]);
        w.add_wall([2000.0, 1000.0], [7000.0, 6000.0], 1000.0, [1, 2, 3]);
        w.add_box(BoxObstacle {
            center: [8000.0, 2000.0],
            size: [600.0, 400.0],
            theta: 0.3,
            height: 500.0,
            color: [0, 0, 0],
        });
        w.finish();
        for k in 0..720 {
            let a = (k as f64 * 0.5f64).to_radians();
            let d = [a.cos(), a.sin()];
            for o in [[500.0, 500.0], [5000.0, 4000.0], [9000.0, 7000.0]] {
                let g = w.cast(o, d, 20000.0).map(|x| x.0);
                let b = cast_every(&w.segments, 0..w.segments.len(), o, d, 20000.0).map(|x| x.0);
                match (g, b) {
                    (Some(g), Some(b)) => assert!((g - b).abs() < 1e-6, "{g} vs {b}"),
                    (g, b) => assert_eq!(g.is_some(), b.is_some()),
                }
            }
        }
    }
}
