//! Real OpenGL 3D views in a panel: line and triangle meshes drawn with depth
//! testing through egui's glow backend (an [`egui::PaintCallback`] with an
//! [`egui_glow::CallbackFn`]), seen through a [`progeo`](crate::progeo) camera.
//!
//! - A [`Mesh`] is immutable vertex data (positions in mm, RGB colours) with an id;
//!   it is uploaded to the GPU the first frame it is drawn and stays there while
//!   frames keep drawing it (static scenery costs no upload per frame). A mesh a
//!   frame no longer draws is freed at the next frame.
//! - A [`Frame3D`] is one picture: a progeo camera (its
//!   [`gl_view`](crate::progeo::PinholeCamera::gl_view) and
//!   [`gl_projection`](crate::progeo::PinholeCamera::gl_projection) matrices, so
//!   OpenGL puts every point on the pixel progeo projects it to), a background
//!   colour and meshes with model matrices (a robot at its pose).
//! - [`Gl3dView::paint`] draws it in a rectangle of the panel. The callback clears
//!   only its rectangle (colour and depth, scissored), enables depth testing, and
//!   restores what it changed (depth test off, blending on, scissor back to egui's
//!   clip, no vertex array bound); egui's painter resets the rest after it.
//! - Each view keeps its last picture offscreen (a framebuffer with colour and a
//!   24-bit depth buffer): a frame whose camera, meshes and model matrices are
//!   those of the last one (a heartbeat repaint while nothing moves) only copies
//!   it to the window (`glBlitFramebuffer`) instead of drawing the scene again.
//!   Without framebuffer objects it draws every frame directly.
//! - Without that offscreen framebuffer the view draws into the window, which then
//!   needs a depth buffer: the GUI host asks for 24 bits
//!   ([`crate::gui::run_window`]).
//!
//! Colours are written as given (no lighting in the shader, no blending), so a
//! wall of colour (200, 60, 40) is exactly that colour on screen; meshes that want
//! shading bake it into their vertex colours ([`shade`]).
//!
//! Shaders are GLSL 1.20/1.40 or ES 1.00/3.00, whichever the context speaks
//! (egui_glow's [`ShaderVersion`](egui_glow::ShaderVersion)).

use std::{
    collections::HashMap,
    sync::{
        Arc,
        atomic::{AtomicU64, Ordering},
    },
    time::{Duration, Instant},
};

use eframe::{
    egui_glow,
    glow::{self, HasContext},
};
use egui::{Rect, Ui};
use nalgebra::{Matrix4, Vector3};
use parking_lot::Mutex;

use crate::progeo::PinholeCamera;

/// What a mesh's vertices make.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Primitive {
    /// Pairs of vertices: segments.
    Lines,
    /// Triples of vertices: triangles.
    Triangles,
}

/// One vertex: position (mm) and colour (RGB, 0..1).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Vertex {
    pub pos: [f32; 3],
    pub color: [f32; 3],
}

static NEXT_MESH: AtomicU64 = AtomicU64::new(1);

/// Immutable vertex data with an id (the GPU copy is keyed by it).
#[derive(Debug)]
pub struct Mesh {
    id: u64,
    pub primitive: Primitive,
    pub vertices: Vec<Vertex>,
}

impl Mesh {
    pub fn new(primitive: Primitive, vertices: Vec<Vertex>) -> Arc<Mesh> {
        Arc::new(Mesh {
            id: NEXT_MESH.fetch_add(1, Ordering::Relaxed),
            primitive,
            vertices,
        })
    }
    pub fn id(&self) -> u64 {
        self.id
    }
}

/// An RGB colour from bytes.
pub fn rgb(c: [u8; 3]) -> [f32; 3] {
    [
        c[0] as f32 / 255.0,
        c[1] as f32 / 255.0,
        c[2] as f32 / 255.0,
    ]
}

/// `c` lit by a light from above and to the side along `normal` (flat shading baked
/// into a colour): 0.65 .. 1.0 of the colour.
pub fn shade(c: [f32; 3], normal: Vector3<f32>) -> [f32; 3] {
    let light = Vector3::new(0.4f32, 0.3, 0.866).normalize();
    let n = normal.try_normalize(1e-9).unwrap_or(Vector3::z());
    let k = 0.65 + 0.35 * n.dot(&light).abs();
    [c[0] * k, c[1] * k, c[2] * k]
}

/// Collects segments and triangles, then makes meshes of them.
#[derive(Default, Clone)]
pub struct MeshBuilder {
    pub lines: Vec<Vertex>,
    pub triangles: Vec<Vertex>,
}

impl MeshBuilder {
    pub fn line(&mut self, a: [f32; 3], b: [f32; 3], color: [f32; 3]) {
        self.lines.push(Vertex { pos: a, color });
        self.lines.push(Vertex { pos: b, color });
    }
    pub fn triangle(&mut self, a: [f32; 3], b: [f32; 3], c: [f32; 3], color: [f32; 3]) {
        for pos in [a, b, c] {
            self.triangles.push(Vertex { pos, color });
        }
    }
    /// The quadrilateral a-b-c-d (two triangles).
    pub fn quad(&mut self, a: [f32; 3], b: [f32; 3], c: [f32; 3], d: [f32; 3], color: [f32; 3]) {
        self.triangle(a, b, c, color);
        self.triangle(a, c, d, color);
    }
    /// An axis-aligned box from `min` to `max`, faces shaded, edges in `edge`.
    pub fn cuboid(
        &mut self,
        min: [f32; 3],
        max: [f32; 3],
        color: [f32; 3],
        edge: Option<[f32; 3]>,
    ) {
        let p = |i: usize| {
            [
                if i & 1 == 0 { min[0] } else { max[0] },
                if i & 2 == 0 { min[1] } else { max[1] },
                if i & 4 == 0 { min[2] } else { max[2] },
            ]
        };
        let faces: [([usize; 4], [f32; 3]); 6] = [
            ([0, 1, 3, 2], [0.0, 0.0, -1.0]),
            ([4, 5, 7, 6], [0.0, 0.0, 1.0]),
            ([0, 1, 5, 4], [0.0, -1.0, 0.0]),
            ([2, 3, 7, 6], [0.0, 1.0, 0.0]),
            ([0, 2, 6, 4], [-1.0, 0.0, 0.0]),
            ([1, 3, 7, 5], [1.0, 0.0, 0.0]),
        ];
        for (f, n) in faces {
            let c = shade(color, Vector3::from(n));
            self.quad(p(f[0]), p(f[1]), p(f[2]), p(f[3]), c);
        }
        if let Some(e) = edge {
            for (a, b) in [
                (0, 1),
                (1, 3),
                (3, 2),
                (2, 0),
                (4, 5),
                (5, 7),
                (7, 6),
                (6, 4),
                (0, 4),
                (1, 5),
                (2, 6),
                (3, 7),
            ] {
                self.line(p(a), p(b), e);
            }
        }
    }
    /// The meshes built (lines, triangles), each `None` when empty.
    pub fn build(self) -> (Option<Arc<Mesh>>, Option<Arc<Mesh>>) {
        let l = (!self.lines.is_empty()).then(|| Mesh::new(Primitive::Lines, self.lines));
        let t =
            (!self.triangles.is_empty()).then(|| Mesh::new(Primitive::Triangles, self.triangles));
        (l, t)
    }
    /// Both meshes, drawn with `model`.
    pub fn draws(self, model: Matrix4<f32>) -> Vec<Draw> {
        let (l, t) = self.build();
        [t, l]
            .into_iter()
            .flatten()
            .map(|mesh| Draw { mesh, model })
            .collect()
    }
}

/// A mesh drawn with a model matrix (mesh coordinates to world mm).
#[derive(Clone, Debug)]
pub struct Draw {
    pub mesh: Arc<Mesh>,
    pub model: Matrix4<f32>,
}

impl Draw {
    pub fn at_origin(mesh: Arc<Mesh>) -> Draw {
        Draw {
            mesh,
            model: Matrix4::identity(),
        }
    }
}

/// The model matrix of a robot at (x, y) mm heading `theta` radians (z up).
pub fn pose_matrix(x: f32, y: f32, theta: f32) -> Matrix4<f32> {
    Matrix4::new_translation(&Vector3::new(x, y, 0.0))
        * Matrix4::from_axis_angle(&Vector3::z_axis(), theta)
}

/// One picture: camera, background and what to draw.
#[derive(Clone, Debug)]
pub struct Frame3D {
    /// The camera; its `columns` x `rows` should be the viewport's pixels.
    pub camera: PinholeCamera,
    /// Clipping distances, mm.
    pub near: f64,
    pub far: f64,
    /// Background (RGB 0..1).
    pub clear: [f32; 3],
    pub draws: Vec<Draw>,
}

/// Timing of the GL work, for benchmarks: the last callback's duration.
#[derive(Clone, Debug, Default)]
pub struct GlStats {
    /// CPU time spent in the paint callback (uploads and draw calls), last frame.
    pub callback: Duration,
    /// Meshes and vertices drawn last frame.
    pub meshes: usize,
    pub vertices: usize,
    /// Set when the GL setup failed (shader or vertex array): the reason.
    pub error: Option<String>,
}

struct GpuMesh {
    vao: glow::VertexArray,
    vbo: glow::Buffer,
    count: i32,
    mode: u32,
}

struct Gpu {
    program: glow::Program,
    u_mvp: Option<glow::UniformLocation>,
    meshes: HashMap<u64, GpuMesh>,
    /// The last picture, offscreen (see [`Gpu::draw`]).
    cache: Option<Cache>,
    cache_failed: bool,
}

/// An offscreen picture and the [`frame_key`] it was drawn for.
struct Cache {
    fbo: glow::Framebuffer,
    color: glow::Renderbuffer,
    depth: glow::Renderbuffer,
    size: (i32, i32),
    key: Option<u64>,
}

/// GPU state shared with the paint callback (created on the first paint, where
/// the GL context is).
#[derive(Default)]
struct Shared {
    gpu: Option<Result<Gpu, String>>,
    stats: GlStats,
}

/// GPU state of views that were dropped (a schema unloaded): there is no GL
/// context at drop time, so the next paint of any view frees it (the window has
/// one context).
static ORPHANS: Mutex<Vec<Gpu>> = Mutex::new(Vec::new());

impl Drop for Shared {
    fn drop(&mut self) {
        if let Some(Ok(gpu)) = self.gpu.take() {
            ORPHANS.lock().push(gpu);
        }
    }
}

/// A real OpenGL 3D view (see the module doc). Cheap to keep per panel.
#[derive(Default, Clone)]
pub struct Gl3dView {
    shared: Arc<Mutex<Shared>>,
}

impl Gl3dView {
    pub fn new() -> Self {
        Gl3dView::default()
    }

    /// Statistics of the last drawn frame.
    pub fn stats(&self) -> GlStats {
        self.shared.lock().stats.clone()
    }

    /// Draws `frame` in `rect` (egui points) of `ui`'s painter.
    pub fn paint(&self, ui: &Ui, rect: Rect, frame: Frame3D) {
        let shared = self.shared.clone();
        let frame = Arc::new(frame);
        let cb = egui_glow::CallbackFn::new(move |info, painter| {
            let t = Instant::now();
            let gl = painter.gl();
            for gpu in ORPHANS.lock().drain(..) {
                // SAFETY: on the GL thread, with the context these were made in.
                unsafe { gpu.free(gl) };
            }
            let mut s = shared.lock();
            if s.gpu.is_none() {
                // SAFETY: called on the GL thread with the painter's current context.
                s.gpu = Some(unsafe { Gpu::new(gl) });
            }
            let (meshes, vertices) = match s.gpu.as_mut() {
                Some(Ok(gpu)) => {
                    // SAFETY: as above; the state this changes is restored in draw.
                    unsafe { gpu.draw(gl, &info, &frame) }
                }
                Some(Err(e)) => {
                    let e = e.clone();
                    s.stats.error = Some(e);
                    return;
                }
                None => (0, 0),
            };
            s.stats = GlStats {
                callback: t.elapsed(),
                meshes,
                vertices,
                error: None,
            };
        });
        ui.painter().add(egui::PaintCallback {
            rect,
            callback: Arc::new(cb),
        });
    }
}

fn shader_sources(v: egui_glow::ShaderVersion) -> (String, String) {
    let header = v.version_declaration();
    let es = matches!(
        v,
        egui_glow::ShaderVersion::Es100 | egui_glow::ShaderVersion::Es300
    );
    let precision = if es { "precision mediump float;\n" } else { "" };
    let (att, var_out, var_in, frag_decl, frag_out) = if v.is_new_shader_interface() {
        ("in", "out", "in", "out vec4 out_color;\n", "out_color")
    } else {
        ("attribute", "varying", "varying", "", "gl_FragColor")
    };
    let vs = format!(
        "{header}{precision}uniform mat4 u_mvp;\n{att} vec3 a_pos;\n{att} vec3 a_color;\n\
         {var_out} vec3 v_color;\nvoid main() {{\n  v_color = a_color;\n  \
         gl_Position = u_mvp * vec4(a_pos, 1.0);\n}}\n"
    );
    let fs = format!(
        "{header}{precision}{var_in} vec3 v_color;\n{frag_decl}void main() {{\n  \
         {frag_out} = vec4(v_color, 1.0);\n}}\n"
    );
    (vs, fs)
}

impl Gpu {
    unsafe fn new(gl: &glow::Context) -> Result<Gpu, String> {
        unsafe {
            let version = egui_glow::ShaderVersion::get(gl);
            let (vs, fs) = shader_sources(version);
            let program = gl.create_program()?;
            let mut shaders = Vec::new();
            for (kind, src) in [(glow::VERTEX_SHADER, vs), (glow::FRAGMENT_SHADER, fs)] {
                let sh = gl.create_shader(kind)?;
                gl.shader_source(sh, &src);
                gl.compile_shader(sh);
                if !gl.get_shader_compile_status(sh) {
                    let log = gl.get_shader_info_log(sh);
                    gl.delete_shader(sh);
                    gl.delete_program(program);
                    return Err(format!(
                        "gl3d: shader does not compile ({version:?}): {log}"
                    ));
                }
                gl.attach_shader(program, sh);
                shaders.push(sh);
            }
            gl.bind_attrib_location(program, 0, "a_pos");
            gl.bind_attrib_location(program, 1, "a_color");
            gl.link_program(program);
            for sh in shaders {
                gl.detach_shader(program, sh);
                gl.delete_shader(sh);
            }
            if !gl.get_program_link_status(program) {
                let log = gl.get_program_info_log(program);
                gl.delete_program(program);
                return Err(format!("gl3d: shaders do not link: {log}"));
            }
            let u_mvp = gl.get_uniform_location(program, "u_mvp");
            Ok(Gpu {
                program,
                u_mvp,
                meshes: HashMap::new(),
                cache: None,
                cache_failed: false,
            })
        }
    }

    /// Deletes every GL object this holds.
    unsafe fn free(self, gl: &glow::Context) {
        unsafe {
            for m in self.meshes.values() {
                gl.delete_vertex_array(m.vao);
                gl.delete_buffer(m.vbo);
            }
            if let Some(c) = &self.cache {
                gl.delete_framebuffer(c.fbo);
                gl.delete_renderbuffer(c.color);
                gl.delete_renderbuffer(c.depth);
            }
            gl.delete_program(self.program);
        }
    }

    unsafe fn upload(gl: &glow::Context, mesh: &Mesh) -> Result<GpuMesh, String> {
        unsafe {
            let vao = gl.create_vertex_array()?;
            let vbo = gl.create_buffer()?;
            gl.bind_vertex_array(Some(vao));
            gl.bind_buffer(glow::ARRAY_BUFFER, Some(vbo));
            let floats: Vec<f32> = mesh
                .vertices
                .iter()
                .flat_map(|v| v.pos.into_iter().chain(v.color))
                .collect();
            let bytes: Vec<u8> = floats.iter().flat_map(|f| f.to_ne_bytes()).collect();
            gl.buffer_data_u8_slice(glow::ARRAY_BUFFER, &bytes, glow::STATIC_DRAW);
            gl.enable_vertex_attrib_array(0);
            gl.vertex_attrib_pointer_f32(0, 3, glow::FLOAT, false, 24, 0);
            gl.enable_vertex_attrib_array(1);
            gl.vertex_attrib_pointer_f32(1, 3, glow::FLOAT, false, 24, 12);
            gl.bind_vertex_array(None);
            gl.bind_buffer(glow::ARRAY_BUFFER, None);
            Ok(GpuMesh {
                vao,
                vbo,
                count: mesh.vertices.len() as i32,
                mode: match mesh.primitive {
                    Primitive::Lines => glow::LINES,
                    Primitive::Triangles => glow::TRIANGLES,
                },
            })
        }
    }

    /// Draws `frame`; returns (meshes, vertices) drawn.
    unsafe fn draw(
        &mut self,
        gl: &glow::Context,
        info: &egui::PaintCallbackInfo,
        frame: &Frame3D,
    ) -> (usize, usize) {
        unsafe {
            // Free the meshes this frame does not draw; upload the new ones.
            let wanted: std::collections::HashSet<u64> =
                frame.draws.iter().map(|d| d.mesh.id).collect();
            self.meshes.retain(|id, m| {
                let keep = wanted.contains(id);
                if !keep {
                    gl.delete_vertex_array(m.vao);
                    gl.delete_buffer(m.vbo);
                }
                keep
            });
            for d in &frame.draws {
                if !self.meshes.contains_key(&d.mesh.id) && !d.mesh.vertices.is_empty() {
                    match Gpu::upload(gl, &d.mesh) {
                        Ok(m) => {
                            self.meshes.insert(d.mesh.id, m);
                        }
                        Err(e) => tracing::warn!("gl3d: cannot upload a mesh: {e}"),
                    }
                }
            }
            // Only this view's rectangle: the viewport is set by egui_glow; the
            // scissor is the visible part of it.
            let vp = info.viewport_in_pixels();
            let clip = info.clip_rect_in_pixels();
            let x0 = vp.left_px.max(clip.left_px);
            let y0 = vp.from_bottom_px.max(clip.from_bottom_px);
            let x1 = (vp.left_px + vp.width_px).min(clip.left_px + clip.width_px);
            let y1 = (vp.from_bottom_px + vp.height_px).min(clip.from_bottom_px + clip.height_px);
            if x1 <= x0 || y1 <= y0 {
                return (0, 0);
            }
            let size = (vp.width_px, vp.height_px);
            let key = frame_key(frame, size);
            let target = gl.get_parameter_framebuffer(glow::DRAW_FRAMEBUFFER_BINDING);
            let mut drawn = (0, 0);
            // Draw into the cached picture when the frame changed, then copy it to
            // the window: an unchanged scene (a heartbeat frame) costs one copy.
            if self.ensure_cache(gl, size) {
                let cache = self.cache.as_ref().expect("cache");
                let (fbo, fresh) = (cache.fbo, cache.key != Some(key));
                if fresh {
                    gl.bind_framebuffer(glow::FRAMEBUFFER, Some(fbo));
                    gl.viewport(0, 0, size.0, size.1);
                    gl.disable(glow::SCISSOR_TEST);
                    drawn = self.render(gl, frame);
                    if let Some(c) = self.cache.as_mut() {
                        c.key = Some(key);
                    }
                }
                gl.bind_framebuffer(glow::READ_FRAMEBUFFER, Some(fbo));
                gl.bind_framebuffer(glow::DRAW_FRAMEBUFFER, target);
                gl.enable(glow::SCISSOR_TEST);
                gl.scissor(x0, y0, x1 - x0, y1 - y0);
                gl.blit_framebuffer(
                    0,
                    0,
                    size.0,
                    size.1,
                    vp.left_px,
                    vp.from_bottom_px,
                    vp.left_px + size.0,
                    vp.from_bottom_px + size.1,
                    glow::COLOR_BUFFER_BIT,
                    glow::NEAREST,
                );
                gl.bind_framebuffer(glow::FRAMEBUFFER, target);
                gl.viewport(vp.left_px, vp.from_bottom_px, size.0, size.1);
            } else {
                gl.enable(glow::SCISSOR_TEST);
                gl.scissor(x0, y0, x1 - x0, y1 - y0);
                drawn = self.render(gl, frame);
            }
            // Restore what egui expects (its painter resets program, viewport and
            // blending function after the callback).
            gl.bind_vertex_array(None);
            gl.use_program(None);
            gl.disable(glow::DEPTH_TEST);
            gl.enable(glow::BLEND);
            gl.enable(glow::SCISSOR_TEST);
            gl.scissor(
                clip.left_px,
                clip.from_bottom_px,
                clip.width_px,
                clip.height_px,
            );
            drawn
        }
    }

    /// Clears the bound framebuffer's viewport (and scissor) and draws `frame`
    /// with depth testing; (meshes, vertices) drawn.
    unsafe fn render(&self, gl: &glow::Context, frame: &Frame3D) -> (usize, usize) {
        unsafe {
            let [r, g, b] = frame.clear;
            gl.clear_color(r, g, b, 1.0);
            gl.depth_mask(true);
            gl.clear_depth_f32(1.0);
            gl.clear(glow::COLOR_BUFFER_BIT | glow::DEPTH_BUFFER_BIT);
            gl.enable(glow::DEPTH_TEST);
            gl.depth_func(glow::LEQUAL);
            gl.disable(glow::BLEND);
            gl.disable(glow::CULL_FACE);
            gl.use_program(Some(self.program));
            let vp_m = (frame.camera.gl_projection(frame.near, frame.far) * frame.camera.gl_view())
                .cast::<f32>();
            let (mut meshes, mut vertices) = (0, 0);
            for d in &frame.draws {
                let Some(m) = self.meshes.get(&d.mesh.id) else {
                    continue;
                };
                let mvp = vp_m * d.model;
                gl.uniform_matrix_4_f32_slice(self.u_mvp.as_ref(), false, mvp.as_slice());
                gl.bind_vertex_array(Some(m.vao));
                gl.draw_arrays(m.mode, 0, m.count);
                meshes += 1;
                vertices += m.count as usize;
            }
            gl.bind_vertex_array(None);
            (meshes, vertices)
        }
    }

    /// An offscreen framebuffer (colour and 24-bit depth) of `size` pixels;
    /// false if the context cannot make one (then frames are drawn directly).
    unsafe fn ensure_cache(&mut self, gl: &glow::Context, size: (i32, i32)) -> bool {
        unsafe {
            if self.cache_failed {
                return false;
            }
            if self.cache.as_ref().is_some_and(|c| c.size == size) {
                return true;
            }
            if let Some(c) = self.cache.take() {
                gl.delete_framebuffer(c.fbo);
                gl.delete_renderbuffer(c.color);
                gl.delete_renderbuffer(c.depth);
            }
            let made = (|| -> Result<Cache, String> {
                let fbo = gl.create_framebuffer()?;
                let color = gl.create_renderbuffer()?;
                let depth = gl.create_renderbuffer()?;
                gl.bind_renderbuffer(glow::RENDERBUFFER, Some(color));
                gl.renderbuffer_storage(glow::RENDERBUFFER, glow::RGBA8, size.0, size.1);
                gl.bind_renderbuffer(glow::RENDERBUFFER, Some(depth));
                gl.renderbuffer_storage(
                    glow::RENDERBUFFER,
                    glow::DEPTH_COMPONENT24,
                    size.0,
                    size.1,
                );
                gl.bind_renderbuffer(glow::RENDERBUFFER, None);
                let previous = gl.get_parameter_framebuffer(glow::FRAMEBUFFER_BINDING);
                gl.bind_framebuffer(glow::FRAMEBUFFER, Some(fbo));
                gl.framebuffer_renderbuffer(
                    glow::FRAMEBUFFER,
                    glow::COLOR_ATTACHMENT0,
                    glow::RENDERBUFFER,
                    Some(color),
                );
                gl.framebuffer_renderbuffer(
                    glow::FRAMEBUFFER,
                    glow::DEPTH_ATTACHMENT,
                    glow::RENDERBUFFER,
                    Some(depth),
                );
                let status = gl.check_framebuffer_status(glow::FRAMEBUFFER);
                gl.bind_framebuffer(glow::FRAMEBUFFER, previous);
                if status != glow::FRAMEBUFFER_COMPLETE {
                    gl.delete_framebuffer(fbo);
                    gl.delete_renderbuffer(color);
                    gl.delete_renderbuffer(depth);
                    return Err(format!("framebuffer incomplete (0x{status:x})"));
                }
                Ok(Cache {
                    fbo,
                    color,
                    depth,
                    size,
                    key: None,
                })
            })();
            match made {
                Ok(c) => {
                    self.cache = Some(c);
                    true
                }
                Err(e) => {
                    tracing::warn!("gl3d: no offscreen framebuffer ({e}); drawing every frame");
                    self.cache_failed = true;
                    false
                }
            }
        }
    }
}

/// A hash of everything a frame's picture depends on (camera, clipping,
/// background, meshes and their model matrices, viewport size).
fn frame_key(frame: &Frame3D, size: (i32, i32)) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    size.hash(&mut h);
    let m = frame.camera.gl_projection(frame.near, frame.far) * frame.camera.gl_view();
    for v in m.iter() {
        v.to_bits().hash(&mut h);
    }
    for c in frame.clear {
        c.to_bits().hash(&mut h);
    }
    for d in &frame.draws {
        d.mesh.id.hash(&mut h);
        for v in d.model.iter() {
            v.to_bits().hash(&mut h);
        }
    }
    h.finish()
}

/// A camera placed by its position and focus of attention (4.3's xcam, ycam, zcam
/// and foax, foay, foaz, in mm) with a vertical aperture; drag orbits the position
/// about the focus, scroll moves it closer or further.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LookAtCamera {
    pub position: [f64; 3],
    pub foa: [f64; 3],
    /// Vertical aperture (gluPerspective's fovy), degrees.
    pub fovy_deg: f64,
}

/// The distance limits of [`LookAtCamera::zoomed`], mm.
pub const LOOK_DISTANCE_RANGE: (f64, f64) = (200.0, 2.0e5);

impl LookAtCamera {
    /// Distance, azimuth (rad, from +x) and elevation (rad) of the position seen
    /// from the focus.
    pub fn spherical(&self) -> (f64, f64, f64) {
        let d = [
            self.position[0] - self.foa[0],
            self.position[1] - self.foa[1],
            self.position[2] - self.foa[2],
        ];
        let r = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let az = d[1].atan2(d[0]);
        let el = if r > 0.0 {
            (d[2] / r).clamp(-1.0, 1.0).asin()
        } else {
            0.0
        };
        (r, az, el)
    }

    /// The same focus with the position at distance `r`, azimuth `az` and
    /// elevation `el` (radians; the elevation kept within ±89°).
    pub fn with_spherical(&self, r: f64, az: f64, el: f64) -> LookAtCamera {
        let el = el.clamp(-89f64.to_radians(), 89f64.to_radians());
        let r = r.max(1.0);
        let mut c = *self;
        c.position = [
            self.foa[0] + r * el.cos() * az.cos(),
            self.foa[1] + r * el.cos() * az.sin(),
            self.foa[2] + r * el.sin(),
        ];
        c
    }

    /// Turned about the focus's vertical axis by `deg` degrees (counter-clockwise
    /// seen from above): the rotate toggle's orbit.
    pub fn orbited(&self, deg: f64) -> LookAtCamera {
        let (r, az, el) = self.spherical();
        self.with_spherical(r, az + deg.to_radians(), el)
    }

    /// After a drag of `delta` points: right turns the camera clockwise about the
    /// focus, down raises it (0.5° per point).
    pub fn dragged(&self, delta: egui::Vec2) -> LookAtCamera {
        let (r, az, el) = self.spherical();
        self.with_spherical(
            r,
            az - (delta.x as f64 * 0.5).to_radians(),
            el + (delta.y as f64 * 0.5).to_radians(),
        )
    }

    /// After scrolling `scroll` points (positive: closer).
    pub fn zoomed(&self, scroll: f32) -> LookAtCamera {
        let (r, az, el) = self.spherical();
        let r = (r * (-(scroll as f64) / 200.0).exp())
            .clamp(LOOK_DISTANCE_RANGE.0, LOOK_DISTANCE_RANGE.1);
        self.with_spherical(r, az, el)
    }

    /// The OpenGL camera for a viewport of this aspect (width / height).
    pub fn gl(&self, aspect: f64) -> crate::progeo::GlCamera {
        crate::progeo::GlCamera {
            position: self.position,
            foa: self.foa,
            roll: 0.0,
            fovy: self.fovy_deg.clamp(1.0, 170.0).to_radians(),
            aspect,
            near: 50.0,
            far: 2.0e5,
        }
    }

    /// The progeo camera for a `columns` x `rows` viewport (the manual's OpenGL →
    /// progeo mapping: [`GlCamera::to_progeo`](crate::progeo::GlCamera::to_progeo)).
    pub fn progeo(&self, columns: u32, rows: u32) -> PinholeCamera {
        let (c, r) = (columns.max(1), rows.max(1));
        self.gl(c as f64 / r as f64).to_progeo(c, r)
    }

    /// Applies a drag and a scroll on `response`; whether the camera changed.
    pub fn interact(&mut self, ui: &Ui, response: &egui::Response) -> bool {
        let before = *self;
        if response.dragged() {
            *self = self.dragged(response.drag_delta());
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                *self = self.zoomed(scroll);
            }
        }
        *self != before
    }
}

/// The size in pixels of `rect` (egui points) on `ui`'s screen.
pub fn pixels(ui: &Ui, rect: Rect) -> (u32, u32) {
    let ppp = ui.ctx().pixels_per_point();
    (
        (rect.width() * ppp).round().max(1.0) as u32,
        (rect.height() * ppp).round().max(1.0) as u32,
    )
}

/// The world's static scenery: the floor (a quad of its floor colour under the
/// walls' bounds plus a margin), wall faces in their colours (flat, so a wall's
/// pixels are its colour), darker wall edges, boxes (sides and tops) and the balls
/// where they start (octahedra). Meshes are built once per world.
pub fn world_draws(world: &crate::world::World) -> Vec<Draw> {
    let mut b = MeshBuilder::default();
    let (lo, hi) = world
        .bounds()
        .unwrap_or(([-5000.0, -5000.0], [5000.0, 5000.0]));
    let m = 1000.0;
    let (x0, y0, x1, y1) = (
        (lo[0] - m) as f32,
        (lo[1] - m) as f32,
        (hi[0] + m) as f32,
        (hi[1] + m) as f32,
    );
    let floor = rgb(world.floor_color);
    b.quad(
        [x0, y0, -2.0],
        [x1, y0, -2.0],
        [x1, y1, -2.0],
        [x0, y1, -2.0],
        floor,
    );
    for s in &world.segments {
        let (a, c) = (s.a, s.b);
        let h = s.height as f32;
        let col = rgb(s.color);
        let (ax, ay, bx, by) = (a[0] as f32, a[1] as f32, c[0] as f32, c[1] as f32);
        b.quad([ax, ay, 0.0], [bx, by, 0.0], [bx, by, h], [ax, ay, h], col);
        let e = [col[0] * 0.45, col[1] * 0.45, col[2] * 0.45];
        b.line([ax, ay, h], [bx, by, h], e);
        b.line([ax, ay, 0.0], [ax, ay, h], e);
        b.line([bx, by, 0.0], [bx, by, h], e);
    }
    for bx in &world.boxes {
        let c = bx.corners();
        let h = bx.height as f32;
        let top = shade(rgb(bx.color), Vector3::z());
        let p = |k: usize| [c[k][0] as f32, c[k][1] as f32, h];
        b.quad(p(0), p(1), p(2), p(3), top);
    }
    for ball in &world.balls {
        ball_into(&mut b, ball.pos, ball.radius, ball.color);
    }
    b.draws(Matrix4::identity())
}

/// A ball (an octahedron, shaded) resting on the floor at `pos`.
pub fn ball_into(b: &mut MeshBuilder, pos: [f64; 2], radius: f64, color: [u8; 3]) {
    let (x, y, r) = (pos[0] as f32, pos[1] as f32, radius as f32);
    let c = [x, y, r];
    let v = [[x + r, y, r], [x, y + r, r], [x - r, y, r], [x, y - r, r]];
    let col = rgb(color);
    for k in 0..4 {
        let (p, q) = (v[k], v[(k + 1) % 4]);
        for top in [[x, y, 2.0 * r], [x, y, 0.0]] {
            let n = Vector3::new(
                (p[0] + q[0]) / 2.0 - c[0],
                (p[1] + q[1]) / 2.0 - c[1],
                top[2] - c[2],
            );
            b.triangle(p, q, top, shade(col, n));
        }
    }
}

/// A grid on the floor every `step` mm over `half` mm around the origin, and the
/// x (red), y (green), z (blue) axes, `axes` mm long.
pub fn grid_and_axes(step: f32, half: f32, axes: f32, grid_color: [f32; 3]) -> Vec<Draw> {
    let mut b = MeshBuilder::default();
    let n = (half / step).floor() as i32;
    for i in -n..=n {
        let t = i as f32 * step;
        b.line([t, -half, 0.0], [t, half, 0.0], grid_color);
        b.line([-half, t, 0.0], [half, t, 0.0], grid_color);
    }
    b.line([0.0, 0.0, 1.0], [axes, 0.0, 1.0], [0.85, 0.1, 0.1]);
    b.line([0.0, 0.0, 1.0], [0.0, axes, 1.0], [0.1, 0.7, 0.1]);
    b.line([0.0, 0.0, 1.0], [0.0, 0.0, axes], [0.15, 0.3, 0.95]);
    b.draws(Matrix4::identity())
}

/// The size of a 3D view in a panel: the available width, 3/4 of it high (640 x
/// 480 at 640 points), but no taller than what is visible below the cursor (so a
/// scrolled panel window shows the whole view) and at least 160 x 120.
pub fn canvas_size(ui: &Ui) -> egui::Vec2 {
    let w = ui.available_width().max(160.0);
    let visible = ui.clip_rect().bottom() - ui.cursor().top() - 2.0;
    let h = (w * 0.75).min(visible).max(120.0);
    egui::vec2(w, h.round())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> LookAtCamera {
        LookAtCamera {
            position: [4000.0, 0.0, 3000.0],
            foa: [1000.0, 500.0, 0.0],
            fovy_deg: 45.0,
        }
    }

    #[test]
    fn orbiting_keeps_the_focus_distance_and_height() {
        let c = cam();
        let (r, az, el) = c.spherical();
        let o = c.orbited(90.0);
        let (r2, az2, el2) = o.spherical();
        assert!((r - r2).abs() < 1e-6 && (el - el2).abs() < 1e-9);
        assert!(((az2 - az).rem_euclid(std::f64::consts::TAU) - 90f64.to_radians()).abs() < 1e-9);
        assert_eq!(o.foa, c.foa);
        assert!((o.position[2] - 3000.0).abs() < 1e-6);
        // Four quarter turns come back.
        let back = o.orbited(90.0).orbited(90.0).orbited(90.0);
        for k in 0..3 {
            assert!((back.position[k] - c.position[k]).abs() < 1e-6);
        }
    }

    #[test]
    fn drag_and_zoom() {
        let c = cam();
        let (r, _, el) = c.spherical();
        let d = c.dragged(egui::vec2(0.0, 40.0));
        assert!(d.spherical().2 > el, "dragging down raises the camera");
        let z = c.zoomed(200.0);
        assert!((z.spherical().0 - r / std::f64::consts::E).abs() < 1e-6);
        let far = c.zoomed(-1.0e6);
        assert!((far.spherical().0 - LOOK_DISTANCE_RANGE.1).abs() < 1e-6);
        // Never past the pole.
        let top = c.dragged(egui::vec2(0.0, 10_000.0));
        assert!(top.spherical().2 <= 89f64.to_radians() + 1e-9);
    }

    #[test]
    fn the_progeo_camera_uses_the_opengl_mapping() {
        let p = cam().progeo(640, 480);
        assert_eq!((p.columns, p.rows, p.u0, p.v0), (640, 480, 240.0, 320.0));
        let f = crate::progeo::focal_from_fov(480.0, 45f64.to_radians());
        assert!((p.fdistx - f).abs() < 1e-9 && (p.fdisty - f).abs() < 1e-9);
        // The focus of attention projects to the optical centre.
        let q = p.project(crate::progeo::HPoint3D::point(1000.0, 500.0, 0.0));
        assert!((q.x - 240.0).abs() < 1e-6 && (q.y - 320.0).abs() < 1e-6);
    }

    #[test]
    fn meshes_keep_their_ids_and_builders_split_lines_from_triangles() {
        let mut b = MeshBuilder::default();
        b.cuboid([0.0; 3], [1.0; 3], [1.0, 0.0, 0.0], Some([0.0; 3]));
        let (l, t) = b.build();
        let (l, t) = (l.unwrap(), t.unwrap());
        assert_eq!(l.vertices.len(), 24);
        assert_eq!(t.vertices.len(), 36);
        assert_ne!(l.id(), t.id());
        // The top face is lit more than the sides: shading stays within 0.65..1.
        for v in &t.vertices {
            assert!(v.color[0] >= 0.65 - 1e-6 && v.color[0] <= 1.0 + 1e-6);
        }
    }
}
