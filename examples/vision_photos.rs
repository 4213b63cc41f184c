//! Times jderobot's HoughLinesP and pyramidal LK flow on one photograph written by
//! `scripts/compare_photos.py` (any size), writes the outputs next to the inputs and
//! prints the median time of each op (milliseconds, one thread) as JSON. The script
//! runs it once per photograph and round, alternating with OpenCV.
//!
//! ```text
//! cargo run --release --example vision_photos -- DIR WIDTH HEIGHT REPEATS
//! ```
//! Inputs in DIR: `a.gray`, `b.gray` (u8 grey frames, `b` shifted), `edges.raw` (u8
//! Canny edges), `points.txt` (`x y` per line). Outputs: `rs_houghp.txt` (`x1 y1 x2
//! y2` per segment), `rs_lk.txt` (`x y found error` per point).

#[path = "vision_common/mod.rs"]
mod vision_common;

fn main() -> anyhow::Result<()> {
    let mut run = vision_common::Run::from_args("vision_photos")?;
    let (a, b, edges) = (
        run.gray("a.gray")?,
        run.gray("b.gray")?,
        run.gray("edges.raw")?,
    );
    run.hough_lines_p(&edges)?;
    run.optical_flow_lk(&a, &b)?;
    run.print_times();
    Ok(())
}
