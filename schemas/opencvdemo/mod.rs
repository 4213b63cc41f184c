//! opencvdemo: 4.3's image-processing demo on a live image — original, gray, colour
//! filter, Canny, Sobel, optical flow, pyramid, convolution, and Hough lines
//! (standard and probabilistic) — with the milliseconds each filter takes.
//!
//! Conf (every line optional; 4.3's keys and defaults):
//! ```text
//! schema opencvdemo
//! image colorA            # colorA..D or varcolorA..D (the panel can switch)
//! filter canny            # original gray color canny sobel flow pyramid
//!                         #   convolution hough houghp (default original)
//! hmax 4.5                # colour filter: H radians 0..2π (wraps when hmin > hmax),
//! hmin 3.3                #   S 0..1, V 0..255 (4.3's sample values)
//! smax 1
//! smin 0.2
//! vmax 255
//! vmin 80
//! canny 50                # Canny's low threshold (high = 3x), 4.3's 50
//! hough 100               # votes a standard Hough line needs
//! houghp 50 30 10         # probabilistic Hough: votes, min length, max gap (px)
//! size 3                  # the convolution kernel, 4.3's keys: size (odd, 1..15;
//! modulo 1                #   4.3 took 3 or 5), modulo (divides the rows when > 1),
//! offset 0                #   offset (added before saturation), and `row N v1..vsize`
//! row 1 0 -1 0
//! row 2 -1 5 -1
//! row 3 0 -1 0
//! kernel ../assets/kernels/gaussian5.kernel   # or a kernel file (instead of rows)
//! output varcolorD        # optional: publish the filtered image on this new interface
//! cycle 33                # ms (a 30 fps source needs ≤ 33)
//! end_schema
//! ```
//! `jderobot help opencvdemo` prints these lines with their ranges and defaults.
//! Without a valid kernel the default is 4.3's `[1 1 1; 1 -7 1; 1 1 1]`.
//! Interfaces used: the `image` (BGR); provided: `output` if given.
//!
//! Headless the schema filters each new frame and exports, component `opencvdemo`,
//! `state` ([`Demo`]: the filter, parameters, last view, its ms, frames processed and
//! dropped). System packages: none (the filters are [`crate::vision`]'s).

pub mod filters;
#[cfg(feature = "gui")]
pub mod panel;

use std::{collections::HashMap, sync::Arc};

use parking_lot::Mutex;

pub use filters::{Filter, Params, Pipeline};

use crate::{
    colorspaces::HsvRange,
    conf::{
        ComponentConf, ConfLine,
        settings::{CYCLE, Setting, choice, float, int, numbers, path},
    },
    imagesource::{self, Frame, Frames, Source, Work},
    interfaces::Image,
    runtime::{Runtime, Schema},
    vision::Kernel,
};

/// The last view.
#[derive(Clone, Debug, Default)]
pub struct View {
    pub image: Image,
    /// The source frame's clock.
    pub clock: u64,
    pub filter: Option<Filter>,
    /// Milliseconds the filter took.
    pub ms: f64,
}

/// The state shared by the schema, its panel and the name space.
pub struct Demo {
    pub filter: Mutex<Filter>,
    pub params: Mutex<Params>,
    /// The image interface filtered (the panel may switch it).
    pub source: Source,
    pub view: Mutex<View>,
    /// The last ms of every filter run so far.
    pub times: Mutex<HashMap<Filter, f64>>,
    /// Frames processed, and frames of the source skipped (clock jumps).
    pub frames: Mutex<(u64, u64)>,
}

/// What opencvdemo does with a frame: runs the chosen filter on it and times it.
pub struct DemoWork {
    pub state: Arc<Demo>,
    pipeline: Pipeline,
}

impl Work for DemoWork {
    type Key = (Filter, Params);
    fn source(&self) -> &Source {
        &self.state.source
    }
    fn key(&self) -> Self::Key {
        (*self.state.filter.lock(), self.state.params.lock().clone())
    }
    fn work(
        &mut self,
        f: &Frame,
        (filter, params): &Self::Key,
        out: &Frames<Self::Key>,
    ) -> anyhow::Result<()> {
        self.state.frames.lock().1 += f.skipped;
        let (image, ms) = self.pipeline.run(*filter, &f.sample.value, params);
        out.publish(&image)?;
        self.state.times.lock().insert(*filter, ms);
        self.state.frames.lock().0 += 1;
        *self.state.view.lock() = View {
            image,
            clock: f.sample.clock,
            filter: Some(*filter),
            ms,
        };
        Ok(())
    }
}

crate::declare_lines! {
    /// opencvdemo's lines, declared once (`jderobot help opencvdemo`); defaults are 4.3's.
    struct Lines {
        image: String = imagesource::IMAGE,
        filter: String = Setting::new(
            "filter",
            "the filter shown at start",
            &[choice("FILTER", &Filter::NAMES)],
        )
        .default("original"),
        #[serde(deserialize_with = "imagesource::hsv_lines")]
        hsv: HsvRange = [
            imagesource::HMIN.default("3.3"),
            imagesource::HMAX.default("4.5"),
            imagesource::SMIN.default("0.2"),
            imagesource::SMAX.default("1"),
            imagesource::VMIN.default("80"),
            imagesource::VMAX.default("255"),
        ],
        canny: f64 = Setting::new(
            "canny",
            "Canny's low threshold (the high one is 3 times it)",
            &[float("LOW", "", 1.0, 1000.0)],
        )
        .default("50"),
        hough: u32 = Setting::new(
            "hough",
            "the votes a standard Hough line needs",
            &[int("VOTES", "", 1, 100_000)],
        )
        .default("100"),
        houghp: (u32, i32, i32) = Setting::new(
            "houghp",
            "probabilistic Hough: the votes a line needs, its minimum length, the largest gap in it",
            &[
                int("VOTES", "", 1, 100_000),
                int("MIN_LENGTH", "px", 0, 100_000),
                int("MAX_GAP", "px", 0, 100_000),
            ],
        )
        .default("50 30 10"),
        size: Option<usize> = Setting::new(
            "size",
            "the convolution kernel's size (odd; 4.3 took 3 or 5), given by `row` lines",
            &[int("N", "", 1, 15)],
        ),
        modulo: i32 = Setting::new(
            "modulo",
            "the kernel rows are divided by it when it is more than 1",
            &[int("DIVISOR", "", -1_000_000, 1_000_000)],
        )
        .default("1"),
        offset: i32 = Setting::new(
            "offset",
            "added to the convolution before saturation",
            &[int("OFFSET", "", -1_000_000, 1_000_000)],
        )
        .default("0"),
        /// `row N COEFFICIENTS...`, one per line.
        row: Vec<(usize, Vec<f32>)> = Setting::new(
            "row",
            "row N (1-based) of the kernel: `size` coefficients",
            &[
                int("N", "", 1, 15),
                numbers("COEFFICIENTS", "", f32::MIN as f64, f32::MAX as f64),
            ],
        )
        .repeats(),
        kernel: Option<String> = Setting::new(
            "kernel",
            "a kernel file (instead of size and rows; see assets/kernels)",
            &[path("FILE")],
        ),
        output: Option<String> = imagesource::OUTPUT,
        cycle: u64 = CYCLE
            .default("33")
            .help("the period of each iteration (a 30 fps source needs 33 or less)"),
    }
}
/// The kernel: a file, else the rows (all `size` of them, `size` values each).
fn kernel(conf: &ComponentConf, l: &Lines) -> anyhow::Result<Kernel> {
    if let Some(k) = &l.kernel {
        let Some(line) = conf.line("kernel") else {
            anyhow::bail!("kernel {k}: no kernel line");
        };
        let f = line.existing_file(0, "the kernel file")?;
        return Ok(Kernel::load(&f).map_err(|e| line.error(format!("kernel: {e}")))?);
    }
    let mut rows: Vec<(usize, Vec<f32>, &ConfLine)> = Vec::new();
    for (line, (n, v)) in conf.lines_with("row").zip(&l.row) {
        rows.push((*n, v.clone(), line));
    }
    let Some(n) = l.size else {
        if let Some((_, _, line)) = rows.first() {
            return Err(line.error("row without a `size N` line").into());
        }
        return Ok(Kernel {
            offset: l.offset,
            ..Kernel::default()
        });
    };
    if n.is_multiple_of(2) {
        return Err(imagesource::error_at(
            conf,
            "size",
            "must be odd (4.3 took 3 or 5)",
        ));
    }
    let mut grid: Vec<Option<Vec<f32>>> = vec![None; n];
    for (i, v, line) in rows {
        if i > n || v.len() != n {
            return Err(line
                .error(format!(
                    "row: kernel size is {n}: rows 1..{n} of {n} values"
                ))
                .into());
        }
        grid[i - 1] = Some(v);
    }
    if grid.iter().any(Option::is_none) {
        return Err(imagesource::error_at(
            conf,
            "size",
            format!("size {n}: every row 1..{n} must be given"),
        ));
    }
    let g: Vec<Vec<f32>> = grid.into_iter().flatten().collect();
    let refs: Vec<&[f32]> = g.iter().map(Vec::as_slice).collect();
    Ok(Kernel::from_rows(&refs, l.modulo, l.offset).unwrap_or_default())
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let l: Lines = conf.read()?;
    let p = Params {
        hsv: l.hsv,
        canny: l.canny,
        hough_votes: l.hough,
        houghp: l.houghp,
        kernel: kernel(conf, &l)?,
    };
    let (source, output) =
        imagesource::Source::open(conf, &rt.interfaces, &l.image, l.output.as_deref())?;
    let state = Arc::new(Demo {
        filter: Mutex::new(Filter::from_name(&l.filter).unwrap_or(Filter::Original)),
        params: Mutex::new(p),
        source,
        view: Mutex::new(View::default()),
        times: Mutex::new(HashMap::new()),
        frames: Mutex::new((0, 0)),
    });
    rt.names
        .export_arc(&conf.name, "state", state.clone())
        .map_err(anyhow::Error::msg)?;
    let work = DemoWork {
        state: state.clone(),
        pipeline: Pipeline::default(),
    };
    let schema = imagesource::FrameSchema::new(work, output, l.cycle);
    #[cfg(feature = "gui")]
    let schema = schema.with_panel(panel::DemoPanel::new(state));
    Ok(Box::new(schema))
}

crate::register_schema!(
    "opencvdemo",
    "4.3's image-processing demo: gray, colour filter, Canny, Sobel, flow, pyramid, convolution, Hough",
    create,
    lines = Lines
);
