//! A BGR image scaled to fit, with pixel picking.

use egui::{
    Color32, ColorImage, Pos2, Rect, Response, Sense, Stroke, TextureHandle, TextureOptions, Ui,
    Vec2, pos2, vec2,
};

use super::*;
use crate::interfaces::{Image, Sample};

/// The largest size with the image's aspect ratio that fits in `avail` (never
/// larger than `max_scale` times the image). A zero-sized image gives zero.
pub fn fit_size(width: u32, height: u32, avail: Vec2, max_scale: f32) -> Vec2 {
    let positive = |v: f32| v > 0.0; // false for NaN
    if width == 0 || height == 0 || !positive(avail.x) || !positive(avail.y) {
        return Vec2::ZERO;
    }
    let (w, h) = (width as f32, height as f32);
    let scale = (avail.x / w)
        .min(avail.y / h)
        .min(max_scale.max(f32::MIN_POSITIVE));
    vec2(w * scale, h * scale)
}

/// The pixel (column, row) of a `width`×`height` image drawn in `rect` under screen
/// point `pos`, or `None` outside the image.
pub fn pick_pixel(rect: Rect, width: u32, height: u32, pos: Pos2) -> Option<(u32, u32)> {
    if width == 0 || height == 0 || rect.width() <= 0.0 || rect.height() <= 0.0 {
        return None;
    }
    let u = (pos.x - rect.min.x) / rect.width();
    let v = (pos.y - rect.min.y) / rect.height();
    if !(0.0..1.0).contains(&u) || !(0.0..1.0).contains(&v) {
        return None;
    }
    let x = ((u * width as f32) as u32).min(width - 1);
    let y = ((v * height as f32) as u32).min(height - 1);
    Some((x, y))
}

/// The screen rectangle of pixel (x, y) of a `width`×`height` image drawn in `rect`.
pub fn pixel_rect(rect: Rect, width: u32, height: u32, x: u32, y: u32) -> Rect {
    let sx = rect.width() / width.max(1) as f32;
    let sy = rect.height() / height.max(1) as f32;
    Rect::from_min_size(
        pos2(rect.min.x + x as f32 * sx, rect.min.y + y as f32 * sy),
        vec2(sx, sy),
    )
}

/// Converts a BGR image to an egui image (opaque). Short or malformed data gives
/// black pixels rather than a panic.
pub fn bgr_to_color_image(image: &Image) -> ColorImage {
    let (w, h) = (image.width as usize, image.height as usize);
    let mut pixels = Vec::with_capacity(w * h);
    for i in 0..w * h {
        let p = image.data.get(i * 3..i * 3 + 3);
        pixels.push(match p {
            Some(&[b, g, r]) => Color32::from_rgb(r, g, b),
            _ => Color32::BLACK,
        });
    }
    ColorImage::new([w, h], pixels)
}

/// A clicked pixel: column `x`, row `y` (from the top-left) and its colour.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelPick {
    pub x: u32,
    pub y: u32,
    /// Blue, green, red, as stored in the image.
    pub bgr: [u8; 3],
}

/// Shows BGR images scaled to fit; keeps one texture and uploads a new image only
/// when its clock changes.
pub struct ImageView {
    label: String,
    texture: Option<TextureHandle>,
    clock: Option<u64>,
    size: (u32, u32),
    /// The largest zoom factor (default 4).
    pub max_scale: f32,
    /// The last clicked pixel, drawn as a marker.
    pub last_pick: Option<PixelPick>,
    uploads: u64,
}

/// What [`ImageView::show`] gives back.
pub struct ImageResponse {
    pub response: Response,
    /// The pixel clicked this frame.
    pub pick: Option<PixelPick>,
    /// Where the image was drawn.
    pub rect: Rect,
}

impl ImageView {
    /// `label` names the view (its texture and accessibility label).
    pub fn new(label: impl Into<String>) -> Self {
        ImageView {
            label: label.into(),
            texture: None,
            clock: None,
            size: (0, 0),
            max_scale: 4.0,
            last_pick: None,
            uploads: 0,
        }
    }

    /// How many times an image was uploaded to the GPU (one per new clock).
    pub fn uploads(&self) -> u64 {
        self.uploads
    }

    /// Shows an interface sample (uploads only when its clock changed).
    pub fn show_sample(&mut self, ui: &mut Ui, sample: &Sample<Image>) -> ImageResponse {
        self.show(ui, &sample.value, sample.clock)
    }

    /// Shows `image`, whose version is `clock`: the texture is updated only when the
    /// clock or the size changes. Fits the available width (and height, if bounded).
    pub fn show(&mut self, ui: &mut Ui, image: &Image, clock: u64) -> ImageResponse {
        let size = (image.width, image.height);
        if self.clock != Some(clock) || self.size != size || self.texture.is_none() {
            let ci = bgr_to_color_image(image);
            match &mut self.texture {
                Some(t) => t.set(ci, TextureOptions::NEAREST),
                None => {
                    self.texture = Some(ui.ctx().load_texture(
                        format!("imageview:{}", self.label),
                        ci,
                        TextureOptions::NEAREST,
                    ))
                }
            }
            self.clock = Some(clock);
            self.size = size;
            self.uploads += 1;
        }
        let mut avail = ui.available_size();
        if !avail.y.is_finite() || avail.y <= 1.0 {
            avail.y = avail.x;
        }
        let mut want = fit_size(image.width, image.height, avail, self.max_scale);
        if want == Vec2::ZERO {
            want = vec2(avail.x.clamp(16.0, 320.0), 16.0);
        }
        let (rect, response) = ui.allocate_exact_size(want, Sense::click());
        label_response(&response, &self.label);
        let painter = ui.painter_at(rect);
        match &self.texture {
            Some(t) if image.width > 0 && image.height > 0 => {
                painter.image(
                    t.id(),
                    rect,
                    Rect::from_min_max(pos2(0.0, 0.0), pos2(1.0, 1.0)),
                    Color32::WHITE,
                );
            }
            _ => {
                painter.rect_filled(rect, 0.0, Color32::DARK_GRAY);
                painter.text(
                    rect.center(),
                    egui::Align2::CENTER_CENTER,
                    "no image",
                    egui::FontId::proportional(12.0),
                    Color32::LIGHT_GRAY,
                );
            }
        }
        let mut pick = None;
        if response.clicked()
            && let Some(pos) = response.interact_pointer_pos()
            && let Some((x, y)) = pick_pixel(rect, image.width, image.height, pos)
        {
            let i = (y as usize * image.width as usize + x as usize) * 3;
            let bgr = match image.data.get(i..i + 3) {
                Some(&[b, g, r]) => [b, g, r],
                _ => [0, 0, 0],
            };
            pick = Some(PixelPick { x, y, bgr });
            self.last_pick = pick;
        }
        if let Some(p) = self.last_pick
            && p.x < image.width
            && p.y < image.height
        {
            let r = pixel_rect(rect, image.width, image.height, p.x, p.y);
            let c = r.center();
            let s = Stroke::new(1.5, Color32::YELLOW);
            painter.line_segment([pos2(c.x - 6.0, c.y), pos2(c.x + 6.0, c.y)], s);
            painter.line_segment([pos2(c.x, c.y - 6.0), pos2(c.x, c.y + 6.0)], s);
        }
        ImageResponse {
            response,
            pick,
            rect,
        }
    }
}
