//! The vision schemas (image_viewer, hsvtuner, ...) on real image drivers
//! (imagefile with the images in `assets/`): headless results in the name space,
//! and their panels through egui_kittest (headless: no display, no GPU).
#![cfg(all(feature = "imagefile", feature = "gui"))]

use crate::common;

use common::{eventually, panel_harness, root, start_conf};
use std::sync::Arc;

use egui::vec2;
use egui_kittest::kittest::Queryable;
use jderobot::runtime::Runtime;

fn image(name: &str) -> String {
    root()
        .join("assets/images")
        .join(name)
        .display()
        .to_string()
}

fn start(schema: &str, body: &str) -> Arc<Runtime> {
    start_conf(&format!(
        "driver imagefile\nprovides colorA {}\nprovides varcolorB {}\nend_driver\n\
         schema {schema}\n{body}end_schema\nload_driver imagefile\nload_schema {schema}\n\
         run {schema}\n",
        image("testcard.pnm"),
        image("mandelbrot.png")
    ))
}

#[cfg(feature = "image_viewer")]
mod image_viewer {
    use super::*;
    use jderobot::schemas::image_viewer::{ViewStats, panel::pick_text, save_png};
    use parking_lot::Mutex;

    #[test]
    fn headless_stats_name_every_image_interface() {
        let rt = start("image_viewer", "cycle 20\n");
        let views = rt
            .names
            .import::<Mutex<Vec<ViewStats>>>("image_viewer", "views")
            .unwrap();
        eventually("both images published and measured", || {
            let v = views.lock();
            v.len() == 2 && v.iter().all(|s| s.clock > 0 && s.age_ms.is_some())
        });
        let v = views.lock().clone();
        assert_eq!(v[0].name, "colorA");
        assert_eq!((v[0].width, v[0].height), (320, 240));
        assert_eq!(v[1].name, "varcolorB");
        assert!(v[1].width > 0 && v[1].height > 0);
        rt.shutdown();
    }

    #[test]
    fn conf_errors_name_the_line() {
        let conf = format!(
            "driver imagefile\nprovides colorA {}\nend_driver\nschema image_viewer\n\
             images colorC\nend_schema\nload_driver imagefile\nload_schema image_viewer\n",
            image("testcard.pnm")
        );
        let c = jderobot::conf::Conf::parse(&conf, std::path::Path::new("t.conf")).unwrap();
        let e = jderobot::loader::start(&c)
            .err()
            .expect("colorC is not provided");
        let e = e.to_string();
        assert!(e.contains("t.conf:5") && e.contains("colorC"), "{e}");
    }

    #[test]
    fn panel_click_gives_bgr_and_hsv_and_save_writes_a_png() {
        let dir = tempfile::tempdir().unwrap();
        let rt = start(
            "image_viewer",
            &format!("images colorA\nsave_dir {}\n", dir.path().display()),
        );
        let colora = rt
            .interfaces
            .get::<jderobot::interfaces::Image>("colorA")
            .unwrap();
        eventually("colorA published", || colora.clock() > 0);
        let mut h = panel_harness(&rt, "image_viewer", vec2(500.0, 500.0));
        h.run();
        h.get_by_label("image_viewer colorA").click();
        h.run();
        // The click lands at the view's centre: (160, 120) of the testcard.
        let s = colora.snapshot();
        let i = (120 * 320 + 160) * 3;
        let d = &s.value.data[i..i + 3];
        let want = pick_text(&jderobot::widgets::PixelPick {
            x: 160,
            y: 120,
            bgr: [d[0], d[1], d[2]],
        });
        h.get_by_label(&want);
        h.get_by_label("Save colorA").click();
        h.run();
        let saved: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(saved.len(), 1, "one PNG written");
        let p = saved[0].as_ref().unwrap().path();
        let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&p).unwrap()));
        let r = decoder.read_info().unwrap();
        assert_eq!((r.info().width, r.info().height), (320, 240));
        rt.shutdown();
        // Saving nothing is an error, not a panic.
        let e = save_png(
            &jderobot::interfaces::Image::default(),
            &dir.path().join("x.png"),
        );
        assert!(e.is_err());
    }
}

/// Drags the pointer inside the widget labelled `label` from `a` to `b`
/// (fractions of its rectangle).
#[allow(dead_code)]
fn drag(h: &mut egui_kittest::Harness<'static>, label: &str, a: (f32, f32), b: (f32, f32)) {
    let r = h.get_by_label(label).rect();
    let at = |f: (f32, f32)| egui::pos2(r.min.x + f.0 * r.width(), r.min.y + f.1 * r.height());
    let (pa, pb) = (at(a), at(b));
    let button = |pos, pressed| egui::Event::PointerButton {
        pos,
        button: egui::PointerButton::Primary,
        pressed,
        modifiers: Default::default(),
    };
    h.input_mut().events.push(egui::Event::PointerMoved(pa));
    h.input_mut().events.push(button(pa, true));
    h.run();
    for k in 1..=8 {
        let t = k as f32 / 8.0;
        let p = pa + (pb - pa) * t;
        h.input_mut().events.push(egui::Event::PointerMoved(p));
        h.run();
    }
    h.input_mut().events.push(button(pb, false));
    h.run();
}

#[cfg(feature = "hsvtuner")]
mod hsvtuner {
    use super::*;
    use jderobot::{
        colorspaces::{HsvRange, Lookup, hsv_mask},
        interfaces::Image,
        schemas::hsvtuner::{Tuner, cheese, conf_lines, filter},
    };
    use std::sync::atomic::Ordering;

    const CONF: &str = "hmin 5.5\nhmax 0.7\nsmin 0.4\nsmax 1\nvmin 60\nvmax 255\ncycle 20\n";

    #[test]
    fn headless_filter_counts_and_publishes_the_output() {
        let rt = start("hsvtuner", &format!("{CONF}output varcolorD\n"));
        let st = rt.names.import::<Tuner>("hsvtuner", "state").unwrap();
        eventually("a filtered image", || st.result.lock().clock > 0);
        let r = st.result.lock().clone();
        let src = rt.interfaces.get::<Image>("colorA").unwrap().snapshot();
        let range = HsvRange::from_radians(5.5, 0.7, 0.4, 1.0, 60.0, 255.0);
        let mask = hsv_mask(&src.value, &range, Lookup::Exact);
        let want = mask.data.iter().filter(|&&m| m != 0).count();
        assert!(want > 0, "the testcard has reds");
        assert_eq!(r.passed, want);
        assert_eq!(r.hist.iter().map(|&n| n as usize).sum::<usize>(), 320 * 240);
        // Passing pixels keep their colour; others are grey at V·180/255.
        for (i, &m) in mask.data.iter().enumerate() {
            let (p, q) = (
                &src.value.data[i * 3..i * 3 + 3],
                &r.image.data[i * 3..i * 3 + 3],
            );
            if m != 0 {
                assert_eq!(p, q);
            } else {
                let g = (*p.iter().max().unwrap() as u32 * 180 / 255) as u8;
                assert_eq!(q, [g, g, g]);
            }
        }
        let out = rt.interfaces.get::<Image>("varcolorD").unwrap();
        eventually("varcolorD published", || out.clock() > 0);
        assert_eq!(out.snapshot().value.width, 320);
        rt.shutdown();
    }

    #[test]
    fn hue_wraps_when_hmin_exceeds_hmax() {
        let mut img = Image::new(3, 1);
        img.data = vec![0, 0, 255, 0, 255, 0, 255, 0, 0]; // red, green, blue (BGR)
        let wrap = HsvRange::from_radians(6.0, 0.5, 0.0, 1.0, 0.0, 255.0);
        let (out, passed, _) = filter(&img, &wrap, true);
        assert_eq!(passed, 1);
        assert_eq!(out.data, vec![0, 0, 255, 0, 0, 0, 0, 0, 0]);
        assert_eq!(
            conf_lines(&wrap),
            "hmin 6.000\nhmax 0.500\nsmin 0.000\nsmax 1.000\nvmin 0\nvmax 255\n"
        );
    }

    #[test]
    fn cheese_geometry_round_trips() {
        for &(h, s) in &[(0.3f32, 0.5f32), (3.0, 1.0), (5.9, 0.2)] {
            let (dx, dy) = cheese::to_screen(h, s, 100.0);
            let (h2, s2) = cheese::from_screen(dx, dy, 100.0);
            assert!((h - h2).abs() < 1e-4 && (s - s2).abs() < 1e-4, "{h} {s}");
        }
        // Up is hue π/2; a drag from the right (hue 0) to the top gives 0..π/2.
        let (a, b, smin, smax) = cheese::drag_sector((50.0, 0.0), (0.0, -100.0), 100.0);
        assert!(a.abs() < 1e-5 && (b - std::f32::consts::FRAC_PI_2).abs() < 1e-5);
        assert!((smin - 0.5).abs() < 1e-5 && (smax - 1.0).abs() < 1e-5);
    }

    #[test]
    fn conf_rejects_a_hue_in_degrees() {
        let conf = format!(
            "driver imagefile\nprovides colorA {}\nend_driver\nschema hsvtuner\n\
             hmin 30\nend_schema\nload_driver imagefile\nload_schema hsvtuner\n",
            image("testcard.pnm")
        );
        let c = jderobot::conf::Conf::parse(&conf, std::path::Path::new("t.conf")).unwrap();
        let e = jderobot::loader::start(&c)
            .err()
            .expect("30 rad is out of range");
        let e = e.to_string();
        assert!(e.contains("t.conf:5") && e.contains("radians"), "{e}");
    }

    #[test]
    fn panel_toggle_and_cheese_drag_set_the_state() {
        let rt = start("hsvtuner", CONF);
        let st = rt.names.import::<Tuner>("hsvtuner", "state").unwrap();
        eventually("a filtered image", || st.result.lock().clock > 0);
        let mut h = panel_harness(&rt, "hsvtuner", vec2(800.0, 600.0));
        h.run();
        h.get_by_label("toblack").click();
        h.run();
        assert!(st.toblack.load(Ordering::Relaxed));
        eventually("rejected pixels black", || {
            let r = st.result.lock();
            r.image.data.chunks_exact(3).any(|p| p == [0, 0, 0])
                && !r
                    .image
                    .data
                    .chunks_exact(3)
                    .any(|p| p[0] == p[1] && p[1] == p[2] && p[0] != 0 && p[0] < 180)
        });
        // Drag on the cheese from its right edge (hue 0, s 0.9·) to its top.
        drag(&mut h, "hsvtuner cheese", (0.9, 0.5), (0.5, 0.1));
        let r = *st.ranges.lock();
        let (hmin, hmax) = (r.hmin.to_radians(), r.hmax.to_radians());
        assert!(!(0.1..=6.2).contains(&hmin), "{r:?}");
        assert!((hmax - std::f32::consts::FRAC_PI_2).abs() < 0.1, "{r:?}");
        assert!(r.smax > 0.8 && r.smin > 0.7, "{r:?}");
        h.get_by_label("Print");
        h.get_by_label("Copy");
        rt.shutdown();
    }
}

#[cfg(feature = "opencvdemo")]
mod opencvdemo {
    use super::*;
    use jderobot::{
        interfaces::Image,
        schemas::opencvdemo::{Demo, Filter, Params, Pipeline, filters::draw_line},
        vision,
    };

    #[test]
    fn every_filter_runs_headless_and_reports_its_ms() {
        let rt = start("opencvdemo", "output varcolorD\ncycle 10\n");
        let st = rt.names.import::<Demo>("opencvdemo", "state").unwrap();
        for f in Filter::ALL {
            *st.filter.lock() = f;
            eventually(&format!("{} ran", f.name()), || {
                st.view.lock().filter == Some(f)
            });
        }
        let times = st.times.lock().clone();
        assert_eq!(times.len(), Filter::ALL.len(), "{times:?}");
        assert!(times.values().all(|ms| (0.0..10_000.0).contains(ms)));
        let out = rt.interfaces.get::<Image>("varcolorD").unwrap();
        eventually("output published", || out.clock() > 0);
        rt.shutdown();
    }

    #[test]
    fn filters_are_the_vision_library_ops() {
        let img = Image::new(320, 240); // black
        let mut src = img.clone();
        for x in 0..320 {
            draw_line(&mut src, (x, 0), (x, 239), [(x % 256) as u8, 90, 200]);
        }
        draw_line(&mut src, (0, 120), (319, 120), [255, 255, 255]);
        let p = Params::default();
        let mut pl = Pipeline::default();
        let (g, _) = pl.run(Filter::Gray, &src, &p);
        assert_eq!(g, vision::grayscale(&src).to_bgr());
        let (c, _) = pl.run(Filter::Convolution, &src, &p);
        assert_eq!(c, vision::convolve(&src, &p.kernel));
        let (d, _) = pl.run(Filter::Pyramid, &src, &p);
        assert_eq!((d.width, d.height), (160, 120));
        // The white row is a Hough line drawn in red (θ = π/2, ρ = 120 ± 1).
        let edges = vision::canny(&vision::grayscale(&src), 50.0, 150.0, false);
        let lines = vision::hough_lines(&edges, 1.0, std::f64::consts::PI / 180.0, 100);
        assert!(
            lines
                .iter()
                .any(|l| (l.theta - std::f32::consts::FRAC_PI_2).abs() < 0.02
                    && (l.rho - 120.0).abs() < 2.0),
            "{lines:?}"
        );
        let (hv, _) = pl.run(Filter::HoughStandard, &src, &p);
        assert!(hv.data.chunks_exact(3).any(|q| q == [0, 0, 255]));
    }

    #[test]
    fn conf_kernel_rows_and_errors() {
        let conf = |body: &str| {
            format!(
                "driver imagefile\nprovides colorA {}\nend_driver\nschema opencvdemo\n{body}\
                 end_schema\nload_driver imagefile\nload_schema opencvdemo\n",
                image("testcard.pnm")
            )
        };
        let rt = start_conf(&conf(
            "size 3\nmodulo 16\nrow 1 1 2 1\nrow 2 2 4 2\nrow 3 1 2 1\n",
        ));
        let st = rt.names.import::<Demo>("opencvdemo", "state").unwrap();
        let k = st.params.lock().kernel.clone();
        assert_eq!(k.values[4], 0.25);
        rt.shutdown();
        for (body, line, words) in [
            ("size 4\n", 5, "odd"),
            ("size 3\nrow 1 1 2\n", 6, "3 values"),
            ("size 3\nrow 1 1 1 1\n", 5, "every row"),
            ("filter blur\n", 5, "expected one of"),
            ("hmin 7\n", 5, "radians"),
        ] {
            let c =
                jderobot::conf::Conf::parse(&conf(body), std::path::Path::new("t.conf")).unwrap();
            let e = jderobot::loader::start(&c).err().expect(body).to_string();
            assert!(
                e.contains(&format!("t.conf:{line}")) && e.contains(words),
                "{body}: {e}"
            );
        }
    }

    #[test]
    fn panel_buttons_pick_the_filter() {
        let rt = start("opencvdemo", "cycle 10\n");
        let st = rt.names.import::<Demo>("opencvdemo", "state").unwrap();
        let mut h = panel_harness(&rt, "opencvdemo", vec2(900.0, 600.0));
        h.run();
        h.get_by_label("canny").click();
        h.run();
        assert_eq!(*st.filter.lock(), Filter::Canny);
        eventually("canny view", || {
            st.view.lock().filter == Some(Filter::Canny)
        });
        h.get_by_label("houghp").click();
        h.run();
        assert_eq!(*st.filter.lock(), Filter::HoughProbabilistic);
        assert!(h.query_all_by_label("min length").count() >= 1);
        rt.shutdown();
    }
}

#[cfg(feature = "colortuner")]
mod colortuner {
    use super::*;
    use jderobot::{
        colorspaces::{Background, Lookup, filter},
        interfaces::Image,
        schemas::colortuner::{ColorTuner, PLANE, Ranges, Space, plane_hist},
    };

    #[test]
    fn headless_filter_in_each_space_is_the_library_filter() {
        let rt = start("colortuner", "cycle 10\noutput varcolorD\n");
        let st = rt
            .names
            .import::<ColorTuner>("colortuner", "state")
            .unwrap();
        let src = rt.interfaces.get::<Image>("colorA").unwrap();
        for space in Space::ALL {
            let mut r = Ranges {
                space,
                ..Ranges::default()
            };
            r.rgb = [150.0, 255.0, 0.0, 100.0, 0.0, 100.0];
            r.yuv = [0.1, 0.9, -0.436, 0.0, 0.1, 0.615];
            *st.ranges.lock() = r;
            eventually(&format!("{} filtered", space.name()), || {
                let res = st.result.lock();
                let s = src.snapshot();
                res.clock > 0
                    && res.image == filter(&s.value, &r.filter(), Lookup::Exact, Background::Grey)
            });
            let res = st.result.lock().clone();
            assert_eq!(res.hist.iter().sum::<u32>(), 320 * 240);
        }
        let out = rt.interfaces.get::<Image>("varcolorD").unwrap();
        eventually("output published", || out.clock() > 0);
        rt.shutdown();
    }

    #[test]
    fn a_picked_pixel_passes_in_every_space() {
        for bgr in [[30u8, 40, 200], [200, 90, 10], [128, 128, 128], [0, 255, 0]] {
            for space in Space::ALL {
                let mut r = Ranges {
                    space,
                    ..Ranges::default()
                };
                r.pick(bgr);
                let mut img = Image::new(1, 1);
                img.data = bgr.to_vec();
                let out = filter(&img, &r.filter(), Lookup::Exact, Background::Black);
                assert_eq!(out.data, bgr.to_vec(), "{bgr:?} in {}: {r:?}", space.name());
            }
        }
        let mut img = Image::new(2, 1);
        img.data = vec![0, 0, 255, 255, 255, 255];
        let h = plane_hist(&img, Space::Rgb);
        assert_eq!(h.len(), PLANE * PLANE);
        assert_eq!(h[PLANE - 1], 1); // pure red: R right, G bottom
        assert_eq!(h[PLANE * PLANE - 1], 1); // white: top right
    }

    #[test]
    fn panel_click_picks_and_plane_drag_draws_the_box() {
        let rt = start("colortuner", "cycle 10\nspace rgb\n");
        let st = rt
            .names
            .import::<ColorTuner>("colortuner", "state")
            .unwrap();
        eventually("a filtered image", || st.result.lock().clock > 0);
        let mut h = panel_harness(&rt, "colortuner", vec2(900.0, 700.0));
        h.run();
        h.get_by_label("colortuner image").click();
        h.run();
        let src = rt.interfaces.get::<Image>("colorA").unwrap().snapshot();
        // The click lands at the view's centre pixel (160, 120).
        let i = (120 * 320 + 160) * 3;
        let bgr = [
            src.value.data[i],
            src.value.data[i + 1],
            src.value.data[i + 2],
        ];
        let mut want = Ranges {
            space: Space::Rgb,
            ..Ranges::default()
        };
        want.pick(bgr);
        assert_eq!(st.ranges.lock().rgb, want.rgb);
        // A drag over the lower-left quarter of the plane: R 0..~127, G 0..~127.
        drag(&mut h, "colortuner plane", (0.02, 0.98), (0.5, 0.5));
        let r = st.ranges.lock().rgb;
        assert!(r[0] < 10.0 && (r[1] - 127.5).abs() < 8.0, "{r:?}");
        assert!(r[2] < 10.0 && (r[3] - 127.5).abs() < 8.0, "{r:?}");
        h.get_by_label("yuv").click();
        h.run();
        assert_eq!(st.ranges.lock().space, Space::Yuv);
        rt.shutdown();
    }
}

/// Clicks inside the widget labelled `label` at `f` (fractions of its rectangle).
#[allow(dead_code)]
fn click_at(h: &mut egui_kittest::Harness<'static>, label: &str, f: (f32, f32)) {
    let r = h.get_by_label(label).rect();
    let p = egui::pos2(r.min.x + f.0 * r.width(), r.min.y + f.1 * r.height());
    let button = |pressed| egui::Event::PointerButton {
        pos: p,
        button: egui::PointerButton::Primary,
        pressed,
        modifiers: Default::default(),
    };
    h.input_mut().events.push(egui::Event::PointerMoved(p));
    h.input_mut().events.push(button(true));
    h.input_mut().events.push(button(false));
    h.run();
}

#[cfg(feature = "imagerectifier")]
mod imagerectifier {
    use super::*;
    use jderobot::{
        interfaces::Image,
        schemas::imagerectifier::{Points, Rectifier, eight_numbers},
        vision,
    };

    fn apply(h: &nalgebra::Matrix3<f64>, (x, y): (f64, f64)) -> (f64, f64) {
        let v = h * nalgebra::Vector3::new(x, y, 1.0);
        (v.x / v.z, v.y / v.z)
    }

    #[test]
    fn conf_points_solve_headless_and_warp_each_frame() {
        let dir = tempfile::tempdir().unwrap();
        let save = dir.path().join("h.txt");
        let rt = start(
            "imagerectifier",
            &format!(
                "points 40 30 290 50 270 215 50 200\nrectangle 0 0 319 239\nsave {}\n\
                 output varcolorD\ncycle 10\n",
                save.display()
            ),
        );
        let st = rt
            .names
            .import::<Rectifier>("imagerectifier", "state")
            .unwrap();
        let h = st.points.lock().homography.expect("solved at load");
        for (s, d) in [((40.0, 30.0), (0.0, 0.0)), ((270.0, 215.0), (319.0, 239.0))] {
            let p = apply(&h, s);
            assert!(
                (p.0 - d.0).abs() < 1e-6 && (p.1 - d.1).abs() < 1e-6,
                "{p:?}"
            );
        }
        let out = rt.interfaces.get::<Image>("varcolorD").unwrap();
        eventually("rectified frame published", || out.clock() > 0);
        let src = rt.interfaces.get::<Image>("colorA").unwrap().snapshot();
        assert_eq!(
            out.snapshot().value,
            vision::warp_perspective(&src.value, &h, 320, 240)
        );
        st.save();
        let text = std::fs::read_to_string(&save).unwrap();
        assert_eq!(text.trim(), eight_numbers(&h));
        assert_eq!(text.split_whitespace().count(), 8);
        rt.shutdown();
    }

    #[test]
    fn clicks_undo_discard_and_degenerate_points() {
        let mut p = Points::default();
        assert!(p.rectify().unwrap_err().contains("4 input points"));
        for (x, y) in [(0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (0.0, 10.0)] {
            p.click(x, y, false);
        }
        assert!(p.rectangle_mode);
        p.click(99.0, 99.0, false); // ignored: rectangle mode
        assert_eq!(p.src.len(), 4);
        p.click(0.0, 0.0, true);
        assert!(p.rectify().unwrap_err().contains("2 output corners"));
        p.click(20.0, 20.0, true);
        let h = p.rectify().unwrap();
        assert!((h[(0, 0)] - 2.0).abs() < 1e-9 && (h[(1, 1)] - 2.0).abs() < 1e-9);
        p.undo();
        assert_eq!((p.src.len(), p.rect.len(), p.homography), (4, 1, None));
        p.discard();
        assert_eq!(p, Points::default());
        for (x, y) in [(0.0, 0.0), (5.0, 0.0), (10.0, 0.0), (0.0, 10.0)] {
            p.click(x, y, false);
        }
        p.click(0.0, 0.0, true);
        p.click(9.0, 9.0, true);
        assert!(p.rectify().unwrap_err().contains("degenerate"));
    }

    #[test]
    fn panel_clicks_then_rectify() {
        let rt = start("imagerectifier", "cycle 10\n");
        let st = rt
            .names
            .import::<Rectifier>("imagerectifier", "state")
            .unwrap();
        let colora = rt.interfaces.get::<Image>("colorA").unwrap();
        eventually("colorA published", || colora.clock() > 0);
        let mut h = panel_harness(&rt, "imagerectifier", vec2(900.0, 500.0));
        h.run();
        for f in [(0.1, 0.1), (0.9, 0.15), (0.85, 0.9), (0.15, 0.85)] {
            click_at(&mut h, "imagerectifier input", f);
        }
        assert_eq!(st.points.lock().src.len(), 4);
        assert!(st.points.lock().rectangle_mode);
        click_at(&mut h, "imagerectifier output", (0.0, 0.0));
        click_at(&mut h, "imagerectifier output", (0.999, 0.999));
        h.get_by_label("Rectify").click();
        h.run();
        let p = st.points.lock().clone();
        let hm = p.homography.expect("solved");
        let q = apply(&hm, p.src[2]);
        assert!(
            (q.0 - 319.0).abs() < 1e-6 && (q.1 - 239.0).abs() < 1e-6,
            "{q:?}"
        );
        eventually("rectified", || st.result.lock().clock > 0);
        h.get_by_label("Undo").click();
        h.run();
        assert_eq!(st.points.lock().rect.len(), 1);
        h.get_by_label("Discard").click();
        h.run();
        assert!(st.points.lock().src.is_empty());
        rt.shutdown();
    }
}

#[cfg(feature = "extrinsics")]
mod extrinsics {
    use super::*;
    use jderobot::{
        interfaces::Image,
        progeo::PinholeCamera,
        schemas::extrinsics::{Extrinsics, projected_lines},
    };
    use std::sync::atomic::Ordering;

    /// room.world with its camera files in `dir` (cameraINfile: the sample cam-in).
    fn world_in(dir: &std::path::Path) -> String {
        let text = std::fs::read_to_string(root().join("assets/cameras/room.world")).unwrap();
        let text = text
            .replace(
                "cameraINfile assets/cameras/cam-in",
                &format!(
                    "cameraINfile {}",
                    root().join("assets/cameras/cam-in").display()
                ),
            )
            .replace("cameraOUTfile /tmp/cam-out", "cameraOUTfile cam-out");
        let w = dir.join("room.world");
        std::fs::write(&w, text).unwrap();
        w.display().to_string()
    }

    #[test]
    fn loads_the_sample_writes_camera_out_and_draws_the_horizon() {
        let dir = tempfile::tempdir().unwrap();
        let rt = start(
            "extrinsics",
            &format!(
                "world {}\noutput varcolorD\ncycle 10\n",
                world_in(dir.path())
            ),
        );
        let st = rt
            .names
            .import::<Extrinsics>("extrinsics", "state")
            .unwrap();
        let sample = PinholeCamera::load(root().join("assets/cameras/cam-in")).unwrap();
        // cameraOUTfile is written at load (beside the world file), the camera as read.
        let out = PinholeCamera::load(dir.path().join("cam-out")).unwrap();
        assert_eq!(out.to_file_string(), sample.to_file_string());
        // The sample world through cam-in: only the far floor edge, on the horizon
        // (optical row u0 = 120 = graphic row 119), across the whole width.
        let lines = projected_lines(&sample, &st.world, 320, 240);
        assert_eq!(lines.len(), 1, "{lines:?}");
        let img = rt.interfaces.get::<Image>("varcolorD").unwrap();
        eventually("drawn frame", || img.clock() > 0);
        let d = img.snapshot();
        // Red, but for the green cross at the optical centre (column v0 = 160).
        let px = |x: usize| &d.value.data[(119 * 320 + x) * 3..(119 * 320 + x) * 3 + 3];
        let red = (0..320).filter(|&x| px(x) == [0, 0, 255]).count();
        let green = (0..320).filter(|&x| px(x) == [0, 255, 0]).count();
        assert_eq!((red, green), (320 - 13, 13), "on the horizon row");
        assert_eq!(px(160), [0, 255, 0]);
        // Moving along the optical axis (+Y here) moves position and FOA; Undo reads
        // cameraOUTfile, Save writes it, Reload reads cameraINfile.
        st.advance(500.0);
        let c = st.camera.lock().clone();
        assert!((c.position.y - (sample.position.y + 500.0)).abs() < 1e-9);
        assert!((c.foa.y - (sample.foa.y + 500.0)).abs() < 1e-9);
        st.undo();
        assert_eq!(st.camera.lock().position.y, sample.position.y);
        st.fixed_foa.store(true, Ordering::Relaxed);
        st.translate([100.0, 0.0, 0.0]);
        assert_eq!(st.camera.lock().foa.x, sample.foa.x);
        st.save();
        st.reload();
        assert_eq!(st.camera.lock().position.x, sample.position.x);
        st.undo();
        assert_eq!(st.camera.lock().position.x, sample.position.x + 100.0);
        rt.shutdown();
    }

    #[test]
    fn a_world_without_camera_files_is_a_conf_error() {
        let dir = tempfile::tempdir().unwrap();
        let w = dir.path().join("w.world");
        std::fs::write(&w, "worldline 0 0 0 1 1 1 1 1\n").unwrap();
        let conf = format!(
            "driver imagefile\nprovides colorA {}\nend_driver\nschema extrinsics\n\
             world {}\nend_schema\nload_driver imagefile\nload_schema extrinsics\n",
            image("testcard.pnm"),
            w.display()
        );
        let c = jderobot::conf::Conf::parse(&conf, std::path::Path::new("t.conf")).unwrap();
        let e = jderobot::loader::start(&c)
            .err()
            .expect("no cameraINfile")
            .to_string();
        assert!(e.contains("t.conf:5") && e.contains("cameraINfile"), "{e}");
    }

    #[test]
    fn panel_toggles_and_buttons() {
        let dir = tempfile::tempdir().unwrap();
        let rt = start(
            "extrinsics",
            &format!("world {}\ncycle 10\n", world_in(dir.path())),
        );
        let st = rt
            .names
            .import::<Extrinsics>("extrinsics", "state")
            .unwrap();
        let mut h = panel_harness(&rt, "extrinsics", vec2(900.0, 700.0));
        h.run();
        h.get_by_label("fixed FOA").click();
        h.run();
        assert!(st.fixed_foa.load(Ordering::Relaxed));
        h.get_by_label("flip").click();
        h.run();
        assert!(st.flip.load(Ordering::Relaxed));
        h.get_by_label("Save").click();
        h.run();
        assert!(
            st.message.lock().starts_with("saved"),
            "{}",
            st.message.lock()
        );
        h.get_by_label("extrinsics external");
        h.get_by_label("extrinsics image");
        rt.shutdown();
    }
}

#[cfg(feature = "calibrador")]
mod calibrador {
    use super::*;
    use jderobot::{
        progeo::{HPoint3D, PinholeCamera},
        schemas::calibrador::{Calibrador, CalibrationError, calibrate},
    };

    /// Two faces of a box (x = 0 and y = 0 planes) and its floor: 7x7 points each,
    /// 60 mm apart, 3D points not in one plane.
    fn pattern() -> Vec<[f64; 3]> {
        let mut v = Vec::new();
        for i in 1..=7 {
            for j in 1..=7 {
                let (a, b) = (i as f64 * 60.0, j as f64 * 60.0);
                v.push([0.0, a, b]);
                v.push([a, 0.0, b]);
                v.push([a, b, 0.0]);
            }
        }
        v
    }

    /// A known 640x480 progeo camera looking at the pattern.
    fn truth() -> PinholeCamera {
        let mut c = PinholeCamera::new(
            HPoint3D::point(1400.0, 1100.0, 900.0),
            HPoint3D::point(150.0, 150.0, 150.0),
            620.0,
            640,
            480,
        );
        c.fdisty = 600.0;
        c.u0 = 250.0;
        c.v0 = 330.0;
        c.roll = 0.12;
        c.update_camera_matrix();
        c
    }

    /// The pattern's graphic pixels through `cam`, with Gaussian noise of `sigma` px.
    fn render(cam: &PinholeCamera, pts: &[[f64; 3]], sigma: f64) -> Vec<(f64, f64)> {
        let mut seed = 7u64;
        let mut uniform = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let mut gauss = || {
            let (a, b) = (uniform(), uniform());
            (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        };
        pts.iter()
            .map(|p| {
                let q = cam
                    .project_visible(HPoint3D::point(p[0], p[1], p[2]))
                    .expect("visible");
                let (c, r) = cam.optical_to_graphic(q);
                (c + sigma * gauss(), r + sigma * gauss())
            })
            .collect()
    }

    #[test]
    fn synthetic_views_give_k_and_position_within_one_percent() {
        let cam = truth();
        let pts = pattern();
        for sigma in [0.0, 0.5] {
            let img = render(&cam, &pts, sigma);
            let c = calibrate(&pts, &img).unwrap();
            // OpenCV's fx goes with columns (progeo's fdisty), fy with rows (fdistx);
            // cx = v0, cy = rows - 1 - u0.
            let rel = |a: f64, b: f64| (a - b).abs() / b;
            assert!(
                rel(c.fx, 600.0) < 0.01 && rel(c.fy, 620.0) < 0.01,
                "{sigma}: {c:?}"
            );
            assert!(
                rel(c.cx, 330.0) < 0.01 && rel(c.cy, 479.0 - 250.0) < 0.01,
                "{sigma}: {c:?}"
            );
            let p = c.position();
            let want = nalgebra::Vector3::new(1400.0, 1100.0, 900.0);
            let dist = (want - nalgebra::Vector3::new(150.0, 150.0, 150.0)).norm();
            assert!((p - want).norm() < 0.01 * dist, "{sigma}: {p:?}");
            assert!(c.rms < 0.05 + 1.5 * sigma, "{sigma}: rms {}", c.rms);
            // The progeo camera reprojects the pattern as the calibration does.
            let back = c.to_progeo(640, 480);
            assert!((back.roll - 0.12).abs() < 0.01, "roll {}", back.roll);
            for (w, i) in pts.iter().zip(&render(&back, &pts, 0.0)) {
                let q = c.project(*w).unwrap();
                assert!((q.0 - i.0).abs() < 1e-6 && (q.1 - i.1).abs() < 1e-6);
            }
        }
        // Too few or coplanar points are errors, not panics.
        assert_eq!(
            calibrate(&pts[..5], &render(&cam, &pts[..5], 0.0)),
            Err(CalibrationError::TooFew(5))
        );
        let flat: Vec<[f64; 3]> = pts.iter().copied().filter(|p| p[2] == 0.0).collect();
        assert!(calibrate(&flat, &render(&cam, &flat, 0.0)).is_err());
    }

    #[test]
    fn conf_points_calibrate_headless_and_save_a_progeo_file() {
        let dir = tempfile::tempdir().unwrap();
        let cam = truth();
        let pts = pattern();
        let img = render(&cam, &pts, 0.0);
        let mut body = String::new();
        for (p, i) in pts.iter().zip(&img) {
            body += &format!("point {} {} {} {} {}\n", p[0], p[1], p[2], i.0, i.1);
        }
        let out = dir.path().join("cam");
        body += &format!("camera_out {}\n", out.display());
        let rt = start("calibrador", &body);
        let st = rt
            .names
            .import::<Calibrador>("calibrador", "state")
            .unwrap();
        let c = st.result.lock().clone().expect("calibrated at load");
        assert!(c.rms < 0.01, "{c:?}");
        // The schema sets `size` from its image (320x240) every 100 ms: a save whose
        // size it replaced between these two lines is tried again.
        let mut saved = None;
        eventually("a camera file saved at 640x480", || {
            *st.size.lock() = (640, 480);
            st.save();
            let s = PinholeCamera::load(&out).unwrap();
            let done = (s.columns, s.rows) == (640, 480);
            saved = Some(s);
            done
        });
        let saved = saved.unwrap();
        assert!(
            (saved.u0 - 250.0).abs() < 0.01 && (saved.v0 - 330.0).abs() < 0.01,
            "{saved:?}"
        );
        assert!((saved.position.x - 1400.0).abs() < 1.0, "{saved:?}");
        rt.shutdown();
    }

    #[test]
    fn panel_clicks_give_points_in_order() {
        let rt = start("calibrador", "point 0 0 0\npoint 100 0 0\npoint 0 100 0\n");
        let st = rt
            .names
            .import::<Calibrador>("calibrador", "state")
            .unwrap();
        let colora = rt
            .interfaces
            .get::<jderobot::interfaces::Image>("colorA")
            .unwrap();
        eventually("colorA published", || colora.clock() > 0);
        let mut h = panel_harness(&rt, "calibrador", vec2(600.0, 500.0));
        h.run();
        h.get_by_label("click point 1 of 3: (0, 0, 0) mm");
        click_at(&mut h, "calibrador image", (0.25, 0.25));
        click_at(&mut h, "calibrador image", (0.75, 0.25));
        let p = st.points.lock().clone();
        let (u, v) = p[0].image.unwrap();
        assert!((u - 80.5).abs() < 2.0 && (v - 60.5).abs() < 2.0, "{u} {v}");
        assert!(p[1].image.is_some() && p[2].image.is_none());
        h.get_by_label("Undo").click();
        h.run();
        assert!(st.points.lock()[1].image.is_none());
        h.get_by_label("Calibrate").click();
        h.run();
        assert!(
            st.message.lock().contains("6 or more"),
            "{}",
            st.message.lock()
        );
        rt.shutdown();
    }
}

/// `jderobot check` reads the vision schemas' lines from their declarations, without
/// building anything: each bad line is an error at its own line naming the range or
/// the usage (for each vision schema compiled in).
#[test]
fn check_names_the_line_and_the_range_of_every_vision_schema() {
    for (schema, line, want) in [
        ("hsvtuner", "hmin 30", "between 0 and 6.28"),
        ("colortuner", "rgb 0 255 0 255 0 256", "between 0 and 255"),
        ("colortuner", "space lab", "one of hsv, rgb, yuv"),
        (
            "opencvdemo",
            "houghp 50 30",
            "usage: houghp VOTES MIN_LENGTH MAX_GAP",
        ),
        ("opencvdemo", "row 16 1 2", "between 1 and 15"),
        ("imagerectifier", "points 1 2 3", "usage: points X1 Y1"),
        ("extrinsics", "cycle 0", "between 1 and 10000 ms"),
        ("calibrador", "point 1 2", "usage: point X Y Z [U V]"),
        ("image_viewer", "save_dir", "usage: save_dir DIRECTORY"),
    ] {
        if jderobot::registry::find(schema).is_none() {
            continue;
        }
        let e = common::line_problems("schema", schema, line);
        assert!(
            e.iter()
                .any(|e| e.starts_with("t.conf:2: ") && e.contains(want)),
            "{schema} `{line}`: {e:?}"
        );
    }
}
