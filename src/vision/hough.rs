//! Hough lines: standard ([`hough_lines`], OpenCV's `HoughLines`) and probabilistic
//! ([`hough_lines_p`], OpenCV's `HoughLinesP`), on an edge image (any non-zero pixel
//! is an edge point).
//!
//! Both follow OpenCV 4's definitions step by step so results are the same lines in
//! the same order: the trigonometric tables in f32 (`sin`/`cos` of the f32 angle in
//! f64, times 1/ρ), `r = round_half_even(x·cos + y·sin) + (numrho − 1)/2`, the
//! angle count `floor(π/θ) + 1` less one when the last angle is π, local maxima with
//! OpenCV's strict/non-strict neighbour tests, sorted by votes then index; the
//! probabilistic transform visits points in the order of OpenCV's `cv::RNG` seeded
//! with `(uint64)-1` and walks segments in 16-bit fixed point.
//!
//! The standard transform votes angle by angle (one accumulator row, which stays in
//! L1, per pass over the points) instead of point by point, and computes the rows'
//! indices in vectorised blocks; the counts are the same.

use super::GrayImage;

/// A line in normal form: `x·cos θ + y·sin θ = ρ` (pixels, radians 0..π).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PolarLine {
    pub rho: f32,
    pub theta: f32,
    /// The accumulator votes.
    pub votes: u32,
}

/// A segment from (x1, y1) to (x2, y2), pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Segment {
    pub x1: i32,
    pub y1: i32,
    pub x2: i32,
    pub y2: i32,
}

fn numangle(theta: f64) -> usize {
    let pi = std::f64::consts::PI;
    let mut n = (pi / theta).floor() as i64 + 1;
    if n > 1 && (pi - (n - 1) as f64 * theta).abs() < theta / 2.0 {
        n -= 1;
    }
    n.max(1) as usize
}

fn numrho(width: u32, height: u32, rho: f64) -> usize {
    ((((width + height) * 2 + 1) as f64 / rho).round_ties_even() as i64).max(1) as usize
}

/// (cos, sin) tables times 1/ρ, as OpenCV's `createTrigTable` (f32 angle steps).
fn trig(n: usize, theta: f64, irho: f64) -> (Vec<f32>, Vec<f32>) {
    let mut c = Vec::with_capacity(n);
    let mut s = Vec::with_capacity(n);
    let mut ang = 0.0f32;
    for _ in 0..n {
        s.push((f64::from(ang).sin() * irho) as f32);
        c.push((f64::from(ang).cos() * irho) as f32);
        ang += theta as f32;
    }
    (c, s)
}

/// The most accumulator cells (ρ steps × θ steps) a transform allocates: 2^26, a
/// quarter GiB of counts. A step so fine that it asks for more (ρ = 1e-9 asked for
/// ~10^12 cells and aborted the process) gives no lines instead.
const MAX_CELLS: f64 = (1u64 << 26) as f64;

/// Positive finite steps, θ ≤ π, a non-empty image, and an accumulator of at most
/// [`MAX_CELLS`].
fn valid(edges: &GrayImage, rho: f64, theta: f64) -> bool {
    let steps_ok = rho.is_finite()
        && theta.is_finite()
        && rho > 0.0
        && theta > 0.0
        && theta <= std::f64::consts::PI;
    // In f64: the product of two huge counts would overflow usize.
    let cells = || numrho(edges.width, edges.height, rho) as f64 * numangle(theta) as f64;
    steps_ok && edges.width > 0 && edges.height > 0 && cells() <= MAX_CELLS
}

/// `round_half_even(v)` for |v| < 2^22 (clamped there), by the float trick that
/// vectorises (no libm call, no saturating cast): adding 1.5·2^23 leaves the
/// rounded integer in the low mantissa bits, in the default rounding mode (to
/// nearest, ties to even), exactly as OpenCV's `cvRound`.
#[inline(always)]
fn round_even(v: f32) -> i32 {
    const MAGIC: f32 = 12_582_912.0; // 1.5 * 2^23
    (v.clamp(-4_000_000.0, 4_000_000.0) + MAGIC).to_bits() as i32 - MAGIC.to_bits() as i32
}

super::multiversion! {
    /// The accumulator indices of point (x, y) for every angle: row n's cell
    /// `n * stride + round(x·cos n + y·sin n) + off`, clamped into the row's `len`.
    fn indices(x: f32, y: f32, c: &[f32], s: &[f32], off: i32, rows: (usize, usize), out: &mut [u32]) {
        let (len, stride) = rows;
        let last = len as i32 - 1;
        for (n, ((o, &cn), &sn)) in out.iter_mut().zip(c).zip(s).enumerate() {
            let r = (round_even(x * cn + y * sn) + off).clamp(0, last);
            *o = (n * stride) as u32 + r as u32;
        }
    }
}

super::multiversion! {
    /// Votes of every point for one angle into `row`. Runs of points along an edge
    /// vote for the same cell, and increments of one address wait for each other:
    /// four interleaved u16 counters per cell (`sub`, zero on entry and on return)
    /// keep four in flight; they are folded into `row` at most every 4·65535 points.
    fn vote_row(pts: (&[f32], &[f32]), cs: (f32, f32), off: i32, row: &mut [u32], sub: &mut [u16], buf: &mut [u32]) {
        let ((xs, ys), (c, s)) = (pts, cs);
        let last = row.len() as i32 - 1;
        let fold = 4 * 65_535 / buf.len() * buf.len();
        for (fx, fy) in xs.chunks(fold).zip(ys.chunks(fold)) {
            for (cx, cy) in fx.chunks(buf.len()).zip(fy.chunks(buf.len())) {
                let b = &mut buf[..cx.len()];
                for (k, ((r, &x), &y)) in b.iter_mut().zip(cx).zip(cy).enumerate() {
                    let cell = (round_even(x * c + y * s) + off).clamp(0, last);
                    *r = cell as u32 * 4 + (k & 3) as u32;
                }
                for &r in b.iter() {
                    sub[r as usize] += 1;
                }
            }
            for (v, s4) in row.iter_mut().zip(sub.chunks_exact_mut(4)) {
                *v += s4.iter().map(|&x| x as u32).sum::<u32>();
                s4.fill(0);
            }
        }
    }
}

/// OpenCV's `HoughLines(edges, rho, theta, threshold)` (srn = stn = 0,
/// θ in 0..π): lines with more than `threshold` votes, most voted first.
/// Bad steps (not positive, θ > π, finer than [`MAX_CELLS`] allows) give no lines.
pub fn hough_lines(edges: &GrayImage, rho: f64, theta: f64, threshold: u32) -> Vec<PolarLine> {
    if !valid(edges, rho, theta) {
        return Vec::new();
    }
    let (w, h) = (edges.width as usize, edges.height as usize);
    let na = numangle(theta);
    let nr = numrho(edges.width, edges.height, rho);
    let (tc, ts) = trig(na, theta, 1.0 / rho);
    let mut xs = Vec::new();
    let mut ys = Vec::new();
    for (i, row) in edges.data.chunks_exact(w).take(h).enumerate() {
        for (j, &v) in row.iter().enumerate() {
            if v != 0 {
                xs.push(j as f32);
                ys.push(i as f32);
            }
        }
    }
    // The accumulator with OpenCV's one-cell border: (na + 2) rows of nr + 2,
    // filled angle by angle (one row, in L1, per pass over the points).
    let stride = nr + 2;
    let mut acc = vec![0u32; (na + 2) * stride];
    let off = (nr as i32 - 1) / 2 + 1;
    let mut sub = vec![0u16; stride * 4];
    let mut buf = vec![0u32; 256];
    for n in 0..na {
        let row = &mut acc[(n + 1) * stride..(n + 2) * stride];
        vote_row((&xs, &ys), (tc[n], ts[n]), off, row, &mut sub, &mut buf);
    }
    // Local maxima, row by row (the sort below fixes the order).
    let mut found = Vec::new();
    for n in 0..na {
        let b0 = (n + 1) * stride;
        let (up, row, down) = (
            &acc[b0 - stride..b0],
            &acc[b0..b0 + stride],
            &acc[b0 + stride..b0 + 2 * stride],
        );
        for r in 1..=nr {
            let v = row[r];
            if v > threshold && v > row[r - 1] && v >= row[r + 1] && v > up[r] && v >= down[r] {
                found.push(b0 + r);
            }
        }
    }
    found.sort_unstable_by(|&a, &b| acc[b].cmp(&acc[a]).then(a.cmp(&b)));
    found
        .iter()
        .map(|&idx| {
            let n = idx / stride - 1;
            let r = idx - (n + 1) * stride - 1;
            PolarLine {
                rho: (r as f32 - (nr as f32 - 1.0) * 0.5) * rho as f32,
                theta: n as f32 * theta as f32,
                votes: acc[idx],
            }
        })
        .collect()
}

/// OpenCV's `cv::RNG` (multiply-with-carry), for the same visiting order.
struct CvRng(u64);

impl CvRng {
    fn next(&mut self) -> u32 {
        self.0 = u64::from(self.0 as u32) * 4_164_903_690 + (self.0 >> 32);
        self.0 as u32
    }
    fn uniform(&mut self, a: u32, b: u32) -> u32 {
        if a == b { a } else { self.next() % (b - a) + a }
    }
}

/// OpenCV's `HoughLinesP(edges, rho, theta, threshold, min_line_length,
/// max_line_gap)`: segments, in the order found.
pub fn hough_lines_p(
    edges: &GrayImage,
    rho: f64,
    theta: f64,
    threshold: u32,
    min_line_length: i32,
    max_line_gap: i32,
) -> Vec<Segment> {
    if !valid(edges, rho, theta) {
        return Vec::new();
    }
    let limits = (threshold, min_line_length, max_line_gap);
    // A cell counts votes of its pixels, less the pixels that a segment took before
    // they voted (it goes below 0, as OpenCV's), so |count| is at most the edge
    // pixels and at most the pixels of one ρ-wide strip: ρ·√2 + 1 a column (or row).
    let side = f64::from(edges.width.max(edges.height));
    let nz = edge_pixels(edges);
    let max = i16::MAX as usize;
    if nz.len() <= max || side * (2.0 * rho + 2.0) < max as f64 {
        segments(Ppht::<i16>::new(edges, rho, theta), nz, limits)
    } else {
        segments(Ppht::<i32>::new(edges, rho, theta), nz, limits)
    }
}

/// The edge pixels (x, y) of `edges`, in row order. Blocks of 32 zero bytes are
/// skipped with one vector test (sparse edge maps are mostly zeros).
fn edge_pixels(edges: &GrayImage) -> Vec<(i32, i32)> {
    let w = edges.width as usize;
    let mut nz = Vec::new();
    for (i, row) in edges
        .data
        .chunks_exact(w)
        .take(edges.height as usize)
        .enumerate()
    {
        for (b, block) in row.chunks(32).enumerate() {
            if block.iter().fold(0, |a, &v| a | v) == 0 {
                continue;
            }
            for (k, &v) in block.iter().enumerate() {
                if v != 0 {
                    nz.push(((b * 32 + k) as i32, i as i32));
                }
            }
        }
    }
    nz
}

/// [`hough_lines_p`]'s loop over the edge pixels `nz` in OpenCV's random order,
/// with `(threshold, min_line_length, max_line_gap)`.
fn segments<C: Cell>(
    mut state: Ppht<C>,
    mut nz: Vec<(i32, i32)>,
    limits: (u32, i32, i32),
) -> Vec<Segment> {
    let (threshold, min_line_length, max_line_gap) = limits;
    let mut lines = Vec::new();
    let mut rng = CvRng(u64::MAX);
    let mut count = nz.len();
    while count > 0 {
        // A random edge pixel not yet taken by a segment votes.
        let idx = rng.uniform(0, count as u32) as usize;
        let seed = nz[idx];
        nz[idx] = nz[count - 1];
        count -= 1;
        if !state.is_edge(seed) {
            continue;
        }
        let Some(n) = state.vote(seed, threshold) else {
            continue;
        };
        // Its best line reached the threshold: walk it both ways from the seed.
        let walk = Walk::new(seed, -state.ts[n], state.tc[n]);
        let end = state.ends(&walk, seed, max_line_gap);
        let good = (end[1].0 - end[0].0).abs() >= min_line_length
            || (end[1].1 - end[0].1).abs() >= min_line_length;
        state.take(&walk, &end, good);
        if good {
            lines.push(Segment {
                x1: end[0].0,
                y1: end[0].1,
                x2: end[1].0,
                y2: end[1].1,
            });
        }
    }
    lines
}

/// A vote counter of [`Ppht`]'s accumulator. OpenCV counts in `int`; i16 halves
/// the accumulator (a 640x480 one, 180 x 2241 cells, then fits in a 1 MB L2 cache,
/// which matters because the random visiting order touches it at random).
trait Cell: Copy + Default {
    /// Adds a vote; the new count.
    fn add(&mut self) -> i32;
    fn remove(&mut self);
}

impl Cell for i16 {
    #[inline(always)]
    fn add(&mut self) -> i32 {
        *self += 1;
        i32::from(*self)
    }
    #[inline(always)]
    fn remove(&mut self) {
        *self -= 1;
    }
}

impl Cell for i32 {
    #[inline(always)]
    fn add(&mut self) -> i32 {
        *self += 1;
        *self
    }
    #[inline(always)]
    fn remove(&mut self) {
        *self -= 1;
    }
}

/// Adds a vote to each of the `cells` of `acc`; their new counts into `counts`.
/// Kept out of line: inlined into the large loop of [`segments`], its registers
/// spilled to the stack in some builds, and the whole transform ran 25 % slower.
#[inline(never)]
fn add_votes<C: Cell>(acc: &mut [C], cells: &[u32], counts: &mut [i32]) {
    for (v, &k) in counts.iter_mut().zip(cells) {
        *v = acc[k as usize].add();
    }
}

/// Takes a vote from each of the `cells` of `acc` (out of line, as [`add_votes`]).
#[inline(never)]
fn remove_votes<C: Cell>(acc: &mut [C], cells: &[u32]) {
    for &k in cells {
        acc[k as usize].remove();
    }
}

/// [`hough_lines_p`]'s state: OpenCV's angle table (cos/sin of n·θ in f64, over
/// ρ), the votes of the pixels seen so far, and the mask of edge pixels that no
/// segment has taken yet.
struct Ppht<C> {
    tc: Vec<f32>,
    ts: Vec<f32>,
    acc: Vec<C>,
    cells: Vec<u32>,
    /// The counts of `cells` after a vote.
    counts: Vec<i32>,
    half: i32,
    nr: usize,
    /// The accumulator's row stride (cells) and the mask's (bytes).
    stride: usize,
    w: usize,
    mask: Vec<u8>,
    size: (i32, i32),
}

/// A row stride for rows of `n` items of `size` bytes: whole cache lines, an odd
/// number of them. Rows a power of two apart (a 512-pixel-wide image gives 2049
/// accumulator cells = 4098 bytes, 64.03 lines) put the same column of every row in
/// the same few cache sets, and the 180 cells of one vote then evict each other
/// (perf: HoughLinesP at 512x512 took 1.4x its time at 640x480). An odd number of
/// lines spreads consecutive rows over every set.
fn spread_stride(n: usize, size: usize) -> usize {
    let lines = (n * size).div_ceil(64);
    (lines | 1) * 64 / size
}

impl<C: Cell> Ppht<C> {
    /// The state for `edges`.
    fn new(edges: &GrayImage, rho: f64, theta: f64) -> Ppht<C> {
        let (w, h) = (edges.width as usize, edges.height as usize);
        // OpenCV's HoughLinesP takes ρ and θ as float: its tables come from the
        // rounded steps (the f64 θ = π/180 gave other segments on 4 of 40 photos).
        let (rho, theta) = (f64::from(rho as f32), f64::from(theta as f32));
        let na = numangle(theta);
        let nr = numrho(edges.width, edges.height, rho);
        let irho = f64::from(1.0 / rho as f32);
        let tc = (0..na)
            .map(|n| ((n as f64 * theta).cos() * irho) as f32)
            .collect();
        let ts = (0..na)
            .map(|n| ((n as f64 * theta).sin() * irho) as f32)
            .collect();
        let mw = spread_stride(w, 1);
        let mut mask = vec![0u8; mw * h];
        for (m, e) in mask.chunks_exact_mut(mw).zip(edges.data.chunks_exact(w)) {
            for (m, &v) in m.iter_mut().zip(e) {
                *m = u8::from(v != 0);
            }
        }
        let stride = spread_stride(nr, std::mem::size_of::<C>());
        Ppht {
            tc,
            ts,
            acc: vec![C::default(); na * stride],
            cells: vec![0; na],
            counts: vec![0; na],
            half: (nr as i32 - 1) / 2,
            nr,
            stride,
            w: mw,
            mask,
            size: (edges.width as i32, edges.height as i32),
        }
    }

    /// The mask index of (x, y), or None outside the image.
    fn index(&self, (j, i): (i32, i32)) -> Option<usize> {
        let inside = j >= 0 && j < self.size.0 && i >= 0 && i < self.size.1;
        inside.then(|| i as usize * self.w + j as usize)
    }

    fn is_edge(&self, (j, i): (i32, i32)) -> bool {
        self.mask[i as usize * self.w + j as usize] != 0
    }

    /// Fills `cells` with the accumulator cells of (x, y), one per angle.
    fn find_cells(&mut self, (j, i): (i32, i32)) {
        let (c, s) = (&self.tc, &self.ts);
        indices(
            j as f32,
            i as f32,
            c,
            s,
            self.half,
            (self.nr, self.stride),
            &mut self.cells,
        );
    }

    /// Adds the votes of (x, y); the angle of its most voted cell when that
    /// reaches `threshold` (the first such angle on ties).
    fn vote(&mut self, (j, i): (i32, i32), threshold: u32) -> Option<usize> {
        self.find_cells((j, i));
        // The increments first, then the maximum over their counts (vector code):
        // a running maximum in the same loop chains every cell's compare to the
        // previous one, and that chain, not the cache misses, set the loop's pace.
        add_votes(&mut self.acc, &self.cells, &mut self.counts);
        let max = self.counts.iter().copied().max().unwrap_or(0);
        if max < threshold as i32 {
            return None;
        }
        self.counts.iter().position(|&v| v == max)
    }

    fn unvote(&mut self, (j, i): (i32, i32)) {
        self.find_cells((j, i));
        remove_votes(&mut self.acc, &self.cells);
    }

    /// The last edge pixel each way from `seed` before a gap longer than
    /// `max_line_gap` or the image's border.
    fn ends(&self, walk: &Walk, seed: (i32, i32), max_line_gap: i32) -> [(i32, i32); 2] {
        let mut end = [seed; 2];
        for (k, e) in end.iter_mut().enumerate() {
            let (dx, dy) = walk.step(k);
            let (mut x, mut y, mut gap) = (walk.x0, walk.y0, 0);
            while let Some(at) = self.index(walk.at(x, y)) {
                if self.mask[at] != 0 {
                    gap = 0;
                    *e = walk.at(x, y);
                } else {
                    gap += 1;
                    if gap > max_line_gap {
                        break;
                    }
                }
                x += dx;
                y += dy;
            }
        }
        end
    }

    /// Takes the pixels from the seed to each end out of the mask and, for a
    /// `good` segment, their votes out of the accumulator.
    fn take(&mut self, walk: &Walk, end: &[(i32, i32); 2], good: bool) {
        for (k, e) in end.iter().enumerate() {
            let (dx, dy) = walk.step(k);
            let (mut x, mut y) = (walk.x0, walk.y0);
            // The walk ends at the segment's end, found inside the image by `ends`.
            while let Some(at) = self.index(walk.at(x, y)) {
                if self.mask[at] != 0 {
                    if good {
                        self.unvote(walk.at(x, y));
                    }
                    self.mask[at] = 0;
                }
                if walk.at(x, y) == *e {
                    break;
                }
                x += dx;
                y += dy;
            }
        }
    }
}

/// OpenCV's fixed-point walk along the line of direction (a, b) through a seed:
/// one pixel a step along the major axis, 16 fractional bits on the other.
struct Walk {
    x0: i32,
    y0: i32,
    dx0: i32,
    dy0: i32,
    xflag: bool,
}

impl Walk {
    const SHIFT: i32 = 16;

    fn new((j, i): (i32, i32), a: f32, b: f32) -> Walk {
        let (one, half) = (1 << Self::SHIFT, 1 << (Self::SHIFT - 1));
        if a.abs() > b.abs() {
            Walk {
                x0: j,
                y0: (i << Self::SHIFT) + half,
                dx0: if a > 0.0 { 1 } else { -1 },
                dy0: (b * one as f32 / a.abs()).round_ties_even() as i32,
                xflag: true,
            }
        } else {
            Walk {
                x0: (j << Self::SHIFT) + half,
                y0: i,
                dx0: (a * one as f32 / b.abs()).round_ties_even() as i32,
                dy0: if b > 0.0 { 1 } else { -1 },
                xflag: false,
            }
        }
    }

    /// The pixel of walk position (x, y).
    fn at(&self, x: i32, y: i32) -> (i32, i32) {
        if self.xflag {
            (x, y >> Self::SHIFT)
        } else {
            (x >> Self::SHIFT, y)
        }
    }

    /// The step of direction k (0 forward, 1 backward).
    fn step(&self, k: usize) -> (i32, i32) {
        if k > 0 {
            (-self.dx0, -self.dy0)
        } else {
            (self.dx0, self.dy0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_too_fine_for_memory_give_no_lines() {
        let g = image_with((0..50).map(|i| (i, i)), 64, 64);
        assert!(!hough_lines(&g, 1.0, std::f64::consts::PI / 180.0, 20).is_empty());
        assert!(hough_lines(&g, 1e-9, std::f64::consts::PI / 180.0, 20).is_empty());
        assert!(hough_lines_p(&g, 1.0, 1e-12, 20, 10, 2).is_empty());
        assert!(hough_lines_p(&g, 1e-9, 0.01, 20, 10, 2).is_empty());
    }

    fn image_with(points: impl Iterator<Item = (u32, u32)>, w: u32, h: u32) -> GrayImage {
        let mut g = GrayImage::new(w, h);
        for (x, y) in points {
            g.data[(y * w + x) as usize] = 255;
        }
        g
    }

    #[test]
    fn round_even_is_round_half_even() {
        for v in [
            0.5f32, 1.5, 2.5, -0.5, -1.5, -2.5, 3.49, -3.51, 1234.5, -99.25, 0.0, 7.0,
        ] {
            assert_eq!(round_even(v), v.round_ties_even() as i32, "{v}");
        }
    }

    #[test]
    fn opencv_angle_and_rho_counts() {
        assert_eq!(numangle(std::f64::consts::PI / 180.0), 180);
        assert_eq!(numrho(640, 480, 1.0), 2241);
    }

    #[test]
    fn a_vertical_and_a_horizontal_line() {
        // x = 40 (θ = 0, ρ = 40) and y = 30 (θ = π/2, ρ = 30), 100 points each.
        let pts = (0..100).map(|y| (40, y)).chain((0..100).map(|x| (x, 30)));
        let g = image_with(pts, 120, 100);
        let lines = hough_lines(&g, 1.0, std::f64::consts::PI / 180.0, 80);
        assert!(lines.len() >= 2, "{lines:?}");
        let has = |rho: f32, theta: f32| {
            lines
                .iter()
                .any(|l| (l.rho - rho).abs() < 0.6 && (l.theta - theta).abs() < 0.02)
        };
        assert!(
            has(40.0, 0.0) && has(30.0, std::f32::consts::FRAC_PI_2),
            "{lines:?}"
        );
        let segs = hough_lines_p(&g, 1.0, std::f64::consts::PI / 180.0, 50, 50, 3);
        assert!(
            segs.iter()
                .any(|s| s.x1 == 40 && s.x2 == 40 && (s.y1 - s.y2).abs() >= 95),
            "{segs:?}"
        );
        assert!(
            segs.iter()
                .any(|s| s.y1 == 30 && s.y2 == 30 && (s.x1 - s.x2).abs() >= 95),
            "{segs:?}"
        );
    }

    #[test]
    fn bad_steps_and_empty_images_give_nothing() {
        let g = image_with([(1, 1)].into_iter(), 4, 4);
        assert!(hough_lines(&g, 0.0, 0.1, 0).is_empty());
        assert!(hough_lines(&g, 1.0, f64::NAN, 0).is_empty());
        assert!(hough_lines_p(&g, -1.0, 0.1, 0, 1, 1).is_empty());
        assert!(hough_lines(&GrayImage::new(0, 0), 1.0, 0.1, 0).is_empty());
    }

    /// The i16 and i32 accumulators find the same segments, on a dense random edge
    /// map with lines through it.
    #[test]
    fn i16_and_i32_cells_give_the_same_segments() {
        let mut seed = 7u32;
        let mut rnd = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            seed >> 8
        };
        let (w, h) = (160u32, 120u32);
        let noise: Vec<(u32, u32)> = (0..3000).map(|_| (rnd() % w, rnd() % h)).collect();
        let lines = (0..120).flat_map(|t| [(t + 20, t / 2 + 10), (30, t), (t, 90)]);
        let g = image_with(noise.into_iter().chain(lines), w, h);
        let theta = std::f64::consts::PI / 180.0;
        let run = |wide: bool| {
            let limits = (20, 15, 3);
            if wide {
                segments(Ppht::<i32>::new(&g, 1.0, theta), edge_pixels(&g), limits)
            } else {
                segments(Ppht::<i16>::new(&g, 1.0, theta), edge_pixels(&g), limits)
            }
        };
        let narrow = run(false);
        assert!(narrow.len() > 5, "{narrow:?}");
        assert_eq!(narrow, run(true));
        assert_eq!(narrow, hough_lines_p(&g, 1.0, theta, 20, 15, 3));
    }

    #[test]
    fn cv_rng_matches_opencv_first_values() {
        // cv::RNG rng((uint64)-1): state = 0xffffffff * 4164903690 + 0xffffffff.
        let mut r = CvRng(u64::MAX);
        let s = 0xffff_ffffu64 * 4_164_903_690 + 0xffff_ffff;
        assert_eq!(r.next(), s as u32);
    }
}
