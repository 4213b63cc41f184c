//! The vision schemas (image_viewer, hsvtuner, ...) on real image drivers
//! (imagefile with the images in `assets/`): headless results in the name space,
//! and their panels through egui_kittest (headless: no display, no GPU).
#![cfg(all(feature = "imagefile", feature = "gui"))]

mod common;

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
