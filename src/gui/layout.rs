//! Where schema panels open: tiled in the area beside the docked mastergui, or
//! where the user left them last time (a small text file, one panel a line:
//! `NAME X Y`, in points from the window's top-left).

use std::{collections::BTreeMap, path::PathBuf};

use egui::{Pos2, Rect, Vec2, pos2};

/// Panel positions: remembered from the last run and seen this run.
#[derive(Default)]
pub struct Layout {
    file: Option<PathBuf>,
    remembered: BTreeMap<String, Pos2>,
    current: BTreeMap<String, Rect>,
    /// The area beside the docked panels in the last frame.
    pub free: Option<Rect>,
}

impl Layout {
    /// Reads `file` (a missing or unreadable file, or a bad line, is skipped: the
    /// panels then open tiled).
    pub fn load(file: Option<PathBuf>) -> Layout {
        let mut remembered = BTreeMap::new();
        if let Some(text) = file.as_ref().and_then(|f| std::fs::read_to_string(f).ok()) {
            for line in text.lines() {
                let w: Vec<&str> = line.split_whitespace().collect();
                if let [name, x, y] = w[..]
                    && let (Ok(x), Ok(y)) = (x.parse::<f32>(), y.parse::<f32>())
                    && x.is_finite()
                    && y.is_finite()
                {
                    remembered.insert(name.to_string(), pos2(x, y));
                }
            }
        }
        Layout {
            file,
            remembered,
            ..Default::default()
        }
    }

    /// Where panel `name` (the `index`-th shown) opens: where it was left, or the
    /// `index`-th tile of `free`, left to right then top to bottom.
    pub fn place(&self, name: &str, index: usize, free: Rect, size: Vec2) -> Pos2 {
        if let Some(p) = self.remembered.get(name) {
            return *p;
        }
        let gap = 8.0;
        let cols = ((free.width() + gap) / (size.x + gap)).floor().max(1.0) as usize;
        let rows = ((free.height() + gap) / (size.y + gap)).floor().max(1.0) as usize;
        let (col, row) = (index % cols, (index / cols) % rows);
        // Tiles beyond the area's capacity cascade a little so none hides another.
        let cascade = (index / (cols * rows)) as f32 * 24.0;
        pos2(
            free.min.x + col as f32 * (size.x + gap) + cascade,
            free.min.y + row as f32 * (size.y + gap) + cascade,
        )
    }

    /// Records where panel `name` is this frame.
    pub fn seen(&mut self, name: &str, rect: Rect) {
        self.current.insert(name.to_string(), rect);
    }

    /// Each panel's rectangle in the last frame.
    pub fn current(&self) -> Vec<(String, Rect)> {
        self.current.iter().map(|(n, r)| (n.clone(), *r)).collect()
    }

    /// Writes where the panels are (and were, for those not shown this run).
    pub fn save(&self) {
        let Some(file) = &self.file else { return };
        let mut all = self.remembered.clone();
        for (n, r) in &self.current {
            all.insert(n.clone(), r.min);
        }
        let text: String = all
            .iter()
            .map(|(n, p)| format!("{n} {:.0} {:.0}\n", p.x, p.y))
            .collect();
        if let Some(dir) = file.parent() {
            let _ = std::fs::create_dir_all(dir);
        }
        if let Err(e) = std::fs::write(file, text) {
            tracing::warn!(
                "gui: cannot save panel positions to {}: {e}",
                file.display()
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_fill_the_free_area_then_cascade() {
        let free = Rect::from_min_size(pos2(400.0, 30.0), egui::vec2(1000.0, 700.0));
        let l = Layout::default();
        let size = egui::vec2(480.0, 520.0);
        assert_eq!(l.place("a", 0, free, size), pos2(400.0, 30.0));
        assert_eq!(l.place("b", 1, free, size), pos2(888.0, 30.0));
        assert_eq!(l.place("c", 2, free, size), pos2(424.0, 54.0));
    }

    #[test]
    fn positions_survive_a_save_and_a_bad_file() {
        let dir = std::env::temp_dir().join(format!("jde-layout-{}", std::process::id()));
        let file = dir.join("panels");
        let mut l = Layout::load(Some(file.clone()));
        l.seen(
            "introrob",
            Rect::from_min_size(pos2(500.0, 90.0), egui::vec2(10.0, 10.0)),
        );
        l.save();
        let back = Layout::load(Some(file.clone()));
        let free = Rect::from_min_size(pos2(0.0, 0.0), egui::vec2(100.0, 100.0));
        assert_eq!(
            back.place("introrob", 3, free, egui::vec2(1.0, 1.0)),
            pos2(500.0, 90.0)
        );
        std::fs::write(&file, "garbage\nintrorob x y\nnan 1 2 3\n").unwrap();
        let bad = Layout::load(Some(file));
        assert_eq!(
            bad.place("introrob", 0, free, egui::vec2(1.0, 1.0)),
            pos2(0.0, 0.0)
        );
        let _ = std::fs::remove_dir_all(dir);
    }
}
