//! opencvdemo's pipeline at 640x480: per filter the median and worst time of one
//! frame on one core, against the 33.3 ms a 30 fps source allows. Run with
//! `cargo bench --features full --bench vision_schemas`.
//!
//! The frame is the testcard (assets/images/testcard.pnm) scaled 2x with noise and a
//! slow shift per frame (so optical flow has motion), ~20-40k Canny edge pixels.

use std::{hint::black_box, path::Path, time::Instant};

use jderobot::{
    interfaces::Image,
    schemas::opencvdemo::{Filter, Params, Pipeline},
    vision,
};

const FRAMES: usize = 60;

fn testcard_640() -> Image {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/images/testcard.pnm");
    let bytes = std::fs::read(&p).expect("testcard");
    // P6 with a comment: skip 4 header tokens (magic, width, height, maxval).
    let mut i = 0;
    let mut tokens = 0;
    while tokens < 4 {
        while bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        if bytes[i] == b'#' {
            while bytes[i] != b'\n' {
                i += 1;
            }
            continue;
        }
        while !bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        tokens += 1;
    }
    let rgb = &bytes[i + 1..];
    let mut img = Image::new(640, 480);
    let mut seed = 43u32;
    for y in 0..480 {
        for x in 0..640 {
            let s = ((y / 2) * 320 + x / 2) * 3;
            let d = (y * 640 + x) * 3;
            for c in 0..3 {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let n = ((seed >> 24) % 9) as i32 - 4;
                img.data[d + c] = (rgb[s + 2 - c] as i32 + n).clamp(0, 255) as u8;
            }
        }
    }
    img
}

fn shifted(img: &Image, k: usize) -> Image {
    let mut out = img.clone();
    let s = k % 4;
    for y in 0..480 {
        let row = &img.data[y * 1920..(y + 1) * 1920];
        out.data[y * 1920 + s * 3..(y + 1) * 1920].copy_from_slice(&row[..1920 - s * 3]);
    }
    out
}

fn main() {
    let base = testcard_640();
    let edges = vision::canny(&vision::grayscale(&base), 50.0, 150.0, false);
    let n_edges = edges.data.iter().filter(|&&v| v != 0).count();
    let frames: Vec<Image> = (0..FRAMES).map(|k| shifted(&base, k)).collect();
    let p = Params::default();
    println!("opencvdemo pipeline, 640x480, one core, {FRAMES} frames, {n_edges} Canny edge px");
    println!("| filter | median ms | worst ms | frames over 33.3 ms |");
    println!("|---|---|---|---|");
    for f in Filter::ALL {
        let mut pl = Pipeline::default();
        let _ = pl.run(f, &frames[0], &p); // warm-up
        let mut t: Vec<f64> = frames
            .iter()
            .map(|fr| {
                let s = Instant::now();
                black_box(pl.run(f, fr, &p));
                s.elapsed().as_secs_f64() * 1e3
            })
            .collect();
        let over = t.iter().filter(|&&ms| ms > 1000.0 / 30.0).count();
        t.sort_by(f64::total_cmp);
        println!(
            "| {} | {:.2} | {:.2} | {} |",
            f.name(),
            t[t.len() / 2],
            t[t.len() - 1],
            over
        );
    }
}
