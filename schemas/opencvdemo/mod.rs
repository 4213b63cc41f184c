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
//! Without a valid kernel the default is 4.3's `[1 1 1; 1 -7 1; 1 1 1]`.
//! Interfaces used: the `image` (BGR); provided: `output` if given.
//!
//! Headless the schema filters each new frame and exports, component `opencvdemo`,
//! `state` ([`Demo`]: the filter, parameters, last view, its ms, frames processed and
//! dropped). System packages: none (the filters are [`crate::vision`]'s).

pub mod filters;
#[cfg(feature = "gui")]
pub mod panel;

use std::{collections::HashMap, sync::Arc, time::Duration};

use parking_lot::Mutex;

pub use filters::{Filter, Params, Pipeline};

use crate::{
    colorspaces::HsvRange,
    conf::{ComponentConf, ConfLine},
    interfaces::{Image, InUse, Interface},
    runtime::{Context, Runtime, Schema},
    vision::Kernel,
};

const TAU: f32 = std::f32::consts::TAU;

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
    pub source: Mutex<String>,
    pub view: Mutex<View>,
    /// The last ms of every filter run so far.
    pub times: Mutex<HashMap<Filter, f64>>,
    /// Frames processed, and frames of the source skipped (clock jumps).
    pub frames: Mutex<(u64, u64)>,
    /// Every image interface of the run (the panel's choice).
    pub choices: Vec<String>,
}

/// The schema.
pub struct OpencvDemo {
    pub state: Arc<Demo>,
    used: InUse<Image>,
    output: Option<Arc<Interface<Image>>>,
    pipeline: Pipeline,
    last: Option<(String, u64, Filter, Params)>,
    cycle: Duration,
    #[cfg(feature = "gui")]
    panel: Option<Box<dyn crate::runtime::Panel>>,
}

impl OpencvDemo {
    fn follow_source(&mut self, rt: &Runtime) -> anyhow::Result<Arc<Interface<Image>>> {
        let name = self.state.source.lock().clone();
        Ok(self.used.follow(&rt.interfaces, &name)?)
    }
}

impl Schema for OpencvDemo {
    fn cycle(&self) -> Duration {
        self.cycle
    }
    fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
        self.follow_source(ctx.runtime())?;
        self.last = None;
        Ok(())
    }
    fn iteration(&mut self, ctx: &Context) -> anyhow::Result<()> {
        let src = self.follow_source(ctx.runtime())?;
        let s = src.snapshot();
        let filter = *self.state.filter.lock();
        let params = self.state.params.lock().clone();
        let key = (src.name().to_string(), s.clock, filter, params);
        if s.clock == 0 || self.last.as_ref() == Some(&key) {
            return Ok(());
        }
        if let Some((name, clock, ..)) = &self.last
            && *name == key.0
            && s.clock > clock + 1
        {
            self.state.frames.lock().1 += s.clock - clock - 1;
        }
        let (image, ms) = self.pipeline.run(filter, &s.value, &key.3);
        if let Some(o) = &self.output {
            o.publish(image.clone()).map_err(anyhow::Error::msg)?;
        }
        self.state.times.lock().insert(filter, ms);
        self.state.frames.lock().0 += 1;
        *self.state.view.lock() = View {
            image,
            clock: s.clock,
            filter: Some(filter),
            ms,
        };
        self.last = Some(key);
        Ok(())
    }
    fn on_stop(&mut self, _ctx: &Context) {
        self.used.release();
    }
    #[cfg(feature = "gui")]
    fn panel(&mut self) -> Option<Box<dyn crate::runtime::Panel>> {
        self.panel.take()
    }
}

fn one(l: &ConfLine, lo: f32, hi: f32, what: &str) -> anyhow::Result<f32> {
    l.expect_args(1, 1, &format!("{} <{what}>", l.keyword()))?;
    Ok(l.number(0, what, lo..=hi)?)
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Schema>> {
    let mut h = [3.3f32, 4.5, 0.2, 1.0, 80.0, 255.0];
    let mut p = Params::default();
    let mut filter = Filter::Original;
    let mut source = "colorA".to_string();
    let mut output = None;
    let mut cycle = Duration::from_millis(33);
    let (mut size, mut modulo, mut offset) = (None::<(usize, ConfLine)>, 1i32, 0i32);
    let mut rows: Vec<(usize, Vec<f32>, ConfLine)> = Vec::new();
    let mut kernel_file: Option<Kernel> = None;
    for l in &conf.lines {
        match l.keyword() {
            "hmin" => h[0] = one(l, 0.0, TAU, "hue in radians, 0..2π")?,
            "hmax" => h[1] = one(l, 0.0, TAU, "hue in radians, 0..2π")?,
            "smin" => h[2] = one(l, 0.0, 1.0, "saturation 0..1")?,
            "smax" => h[3] = one(l, 0.0, 1.0, "saturation 0..1")?,
            "vmin" => h[4] = one(l, 0.0, 255.0, "value 0..255")?,
            "vmax" => h[5] = one(l, 0.0, 255.0, "value 0..255")?,
            "canny" => p.canny = one(l, 1.0, 1000.0, "Canny's low threshold")? as f64,
            "hough" => {
                l.expect_args(1, 1, "hough VOTES")?;
                p.hough_votes = l.number(0, "votes", 1..=100_000)?;
            }
            "houghp" => {
                l.expect_args(3, 3, "houghp VOTES MIN_LENGTH MAX_GAP")?;
                p.houghp = (
                    l.number(0, "votes", 1..=100_000)?,
                    l.number(1, "minimum length in px", 0..=100_000)?,
                    l.number(2, "maximum gap in px", 0..=100_000)?,
                );
            }
            "filter" => {
                let names: Vec<&str> = Filter::ALL.iter().map(|f| f.name()).collect();
                l.expect_args(1, 1, &format!("filter {}", names.join("|")))?;
                filter = Filter::from_name(l.choice(0, "the filter", &names)?)
                    .unwrap_or(Filter::Original);
            }
            "size" => {
                l.expect_args(1, 1, "size N (odd, 1..15)")?;
                let n: usize = l.number(0, "kernel size", 1..=15)?;
                if n.is_multiple_of(2) {
                    return Err(l.error("size must be odd (4.3 took 3 or 5)").into());
                }
                size = Some((n, l.clone()));
            }
            "modulo" => {
                l.expect_args(1, 1, "modulo N")?;
                modulo = l.number(0, "divisor", -1_000_000..=1_000_000)?;
            }
            "offset" => {
                l.expect_args(1, 1, "offset N")?;
                offset = l.number(0, "offset", -1_000_000..=1_000_000)?;
            }
            "row" => {
                l.expect_args(2, 16, "row N v1 .. vsize")?;
                let n: usize = l.number(0, "row number (1-based)", 1..=15)?;
                let v = (1..l.args().len())
                    .map(|i| l.number::<f32>(i, "coefficient", ..))
                    .collect::<Result<Vec<_>, _>>()?;
                rows.push((n, v, l.clone()));
            }
            "kernel" => {
                l.expect_args(1, 1, "kernel FILE")?;
                let f = l.existing_file(0, "the kernel file")?;
                kernel_file = Some(Kernel::load(&f).map_err(|e| l.error(format!("kernel: {e}")))?);
            }
            "image" => {
                l.expect_args(1, 1, "image INTERFACE (colorA..D, varcolorA..D)")?;
                source = rt.image_interface(l, 0)?;
            }
            "output" => {
                l.expect_args(1, 1, "output INTERFACE (a new image interface)")?;
                output = Some((l.interface(0)?, l.clone()));
            }
            "cycle" => {
                l.expect_args(1, 1, "cycle MS")?;
                cycle = l.millis(0, "period in ms", 1..=10_000)?;
            }
            _ => {
                return Err(conf
                    .unknown(
                        l,
                        "image, filter, hmin, hmax, smin, smax, vmin, vmax, canny, hough, \
                         houghp, size, modulo, offset, row, kernel, output or cycle",
                    )
                    .into());
            }
        }
    }
    p.hsv = HsvRange::from_radians(h[0], h[1], h[2], h[3], h[4], h[5]);
    // The kernel: a file, else the rows (all `size` of them, `size` values each).
    p.kernel = match (kernel_file, size) {
        (Some(k), _) => k,
        (None, Some((n, sl))) => {
            let mut grid: Vec<Option<Vec<f32>>> = vec![None; n];
            for (i, v, l) in &rows {
                if *i > n || v.len() != n {
                    return Err(l
                        .error(format!(
                            "row: kernel size is {n}: rows 1..{n} of {n} values"
                        ))
                        .into());
                }
                grid[i - 1] = Some(v.clone());
            }
            if grid.iter().any(Option::is_none) {
                return Err(sl
                    .error(format!("size {n}: every row 1..{n} must be given"))
                    .into());
            }
            let g: Vec<Vec<f32>> = grid.into_iter().flatten().collect();
            let refs: Vec<&[f32]> = g.iter().map(Vec::as_slice).collect();
            Kernel::from_rows(&refs, modulo, offset).unwrap_or_default()
        }
        (None, None) => {
            if let Some((_, _, l)) = rows.first() {
                return Err(l.error("row without a `size N` line").into());
            }
            Kernel {
                offset,
                ..Kernel::default()
            }
        }
    };
    rt.interfaces.get::<Image>(&source)?;
    let output = match output {
        Some((name, l)) => Some(
            rt.interfaces
                .provide::<Image>(&name, &conf.name)
                .map_err(|e| l.error(format!("output: {e}")))?,
        ),
        None => None,
    };
    let choices = rt
        .interfaces
        .names_of::<Image>()
        .into_iter()
        .filter(|n| output.as_ref().is_none_or(|o| o.name() != n))
        .collect();
    let state = Arc::new(Demo {
        filter: Mutex::new(filter),
        params: Mutex::new(p),
        source: Mutex::new(source),
        view: Mutex::new(View::default()),
        times: Mutex::new(HashMap::new()),
        frames: Mutex::new((0, 0)),
        choices,
    });
    rt.names
        .export_arc(&conf.name, "state", state.clone())
        .map_err(anyhow::Error::msg)?;
    Ok(Box::new(OpencvDemo {
        #[cfg(feature = "gui")]
        panel: Some(Box::new(panel::DemoPanel::new(state.clone()))),
        state,
        used: InUse::default(),
        output,
        pipeline: Pipeline::default(),
        last: None,
        cycle,
    }))
}

crate::register_schema!(
    "opencvdemo",
    "4.3's image-processing demo: gray, colour filter, Canny, Sobel, flow, pyramid, convolution, Hough",
    create
);
