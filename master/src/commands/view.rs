//! `tessera view MODEL`: one process, one window. Rank 0's frame loop and one worker thread
//! run as `render` runs alone, sort-first through the same tiles; the window shows each
//! composited frame and turns its mouse and keys into the commands of the control port
//! (`render::control`), which rank 0 applies to the next frame it sorts. Nothing changes,
//! nothing is drawn: the event loop sleeps until an event, and rank 0 until a command.
//!
//! | input | command |
//! |---|---|
//! | left drag | orbit about the target (yaw and pitch) |
//! | right drag, or shift and left drag | pan (eye and target together) |
//! | wheel | zoom toward the target |
//! | W, S, A, D, R/F or the arrows, Page Up and Down | fly forward, back, left, right, up, down |
//! | Home or 0 | reset to the flags' camera |
//! | P | screenshot: `--out`, numbered (`frame-0001.png`...), equal to `render`'s PNG for that camera |
//! | G | overlay of the tile grid, each tile tinted by its cost (decode and render ms) |
//! | H | the heads-up line on and off |
//! | Q, Escape, closing the window | quit |
//!
//! The frame is shown as rank 0 holds it, pixel for pixel (`softbuffer`: no GPU upload), on
//! black where nothing was drawn; a window larger than the frame is re-planned at its size
//! (same tile grid) and the frame sorted again.

use std::num::NonZeroU32;
use std::path::PathBuf;
use std::sync::mpsc::Sender;
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use serde_json::Value;
use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop, EventLoopProxy};
use winit::keyboard::{Key, NamedKey};
use winit::window::{Window, WindowId};

use crate::cli::RenderArgs;
use crate::composite::Image;
use crate::render::control::{Client, Command, Control, Request};
use crate::render::{frame_path, Present};

/// Degrees of orbit per pixel dragged.
const DEGREES_PER_PIXEL: f32 = 0.3;
/// A step of flying or panning by keys, in units of the eye's distance to the target.
const FLY_STEP: f32 = 0.05;

/// What the frame loop's thread tells the window.
enum Shown {
    Frame {
        image: Arc<Image>,
        hud: String,
        costs: Vec<f64>,
    },
    /// The run ended (quit, or an error the thread returns).
    Ended,
}

/// `tessera view`: the window on this thread (X11 wants the main one), the frame loop and
/// its worker on others.
pub fn run(args: &RenderArgs) -> Result<()> {
    let plan = crate::render::plan_view(args)?;
    if std::env::var_os("DISPLAY").is_none_or(|d| d.is_empty()) {
        bail!("tessera view needs an X display, and DISPLAY is not set (run it on one, or under Xvfb)");
    }
    let control = Control::default();
    if let Some((addr, token)) = &plan.control {
        control.listen(*addr, token.clone())?;
    }
    let event_loop = EventLoop::<Shown>::with_user_event().build().context("cannot open the X display")?;
    event_loop.set_control_flow(ControlFlow::Wait);
    let proxy = event_loop.create_proxy();
    let sender = control.sender();
    let present = presenter(proxy.clone());
    let size = (plan.grid.width, plan.grid.height);
    let title = format!("Tessera: {}", plan.model.file_name().map_or_else(String::new, |n| n.to_string_lossy().into()));
    let out = plan.out.clone();
    let cols_rows = (plan.grid.cols, plan.grid.rows);
    let frames = std::thread::spawn(move || {
        let result = crate::render::run_alone_live(&plan, Some(crate::render::Window { control, present }));
        let _ = proxy.send_event(Shown::Ended);
        result
    });
    let mut app = App::new(sender, title, size, out, cols_rows);
    let ran = event_loop.run_app(&mut app);
    // The window is gone: the frame loop ends at its next command (quit was sent on close).
    let _ = app.sender.send(Request { client: Client::local(), command: Command::Quit {} });
    let result = frames.join().map_err(|_| anyhow::anyhow!("the frame loop panicked"))?;
    if let Some(e) = app.error.take() {
        return Err(e);
    }
    ran.context("the window's event loop failed")?;
    result
}

/// What the writer thread calls with each frame: the image, and the heads-up line and tile
/// costs made from its stats lines, sent to the window's event loop.
fn presenter(proxy: EventLoopProxy<Shown>) -> Present {
    Box::new(move |image: &Arc<Image>, master: &Value, workers: &[Value]| {
        let (hud, costs) = heads_up(master, workers);
        let _ = proxy.send_event(Shown::Frame { image: image.clone(), hud, costs });
    })
}

/// The heads-up line of a frame (frames a second from the frame's period, sort ms, the
/// workers' decode and render ms, bytes sent, triangles drawn) and each tile's cost (decode
/// and render ms).
fn heads_up(master: &Value, workers: &[Value]) -> (String, Vec<f64>) {
    let f = |v: &Value, k: &str| v.get(k).and_then(Value::as_f64).unwrap_or(0.0);
    let tiles = master.get("tiles").and_then(Value::as_array).cloned().unwrap_or_default();
    let bytes: f64 = tiles.iter().map(|t| f(t, "bytes")).sum();
    let triangles: f64 = tiles.iter().map(|t| f(t, "triangles")).sum();
    let decode: f64 = workers.iter().map(|w| f(w, "decode_ms") + f(w, "adapt_ms")).fold(0.0, f64::max);
    let render: f64 = workers.iter().map(|w| f(w, "render_ms")).fold(0.0, f64::max);
    let mut costs = Vec::new();
    for w in workers {
        for t in w.get("tiles").and_then(Value::as_array).into_iter().flatten() {
            let i = f(t, "index") as usize;
            if costs.len() <= i {
                costs.resize(i + 1, 0.0);
            }
            costs[i] += f(t, "decode_ms") + f(t, "adapt_ms") + f(t, "render_ms");
        }
    }
    let period = f(master, "sort_ms") + f(master, "send_ms") + f(master, "wait_ms") + f(master, "composite_ms");
    let hud = format!(
        "frame {} | {:.1} frames/s | sort {:.1} ms, decode {decode:.1} ms, render {render:.1} ms | {:.1} kB | {} triangles",
        f(master, "frame") as u64 + 1,
        1000.0 / period.max(1e-3),
        f(master, "sort_ms"),
        bytes / 1e3,
        triangles as u64
    );
    (hud, costs)
}

/// A drag in progress: its button and the last position.
struct Drag {
    pan: bool,
    at: PhysicalPosition<f64>,
}

struct App {
    sender: Sender<Request>,
    title: String,
    size: (u32, u32),
    out: PathBuf,
    cols_rows: (u32, u32),
    window: Option<Arc<Window>>,
    surface: Option<softbuffer::Surface<Arc<Window>, Arc<Window>>>,
    frame: Option<(Arc<Image>, String, Vec<f64>)>,
    cursor: PhysicalPosition<f64>,
    drag: Option<Drag>,
    shift: bool,
    grid: bool,
    hud: bool,
    screenshots: u32,
    /// Why the window failed, for `run` to return.
    error: Option<anyhow::Error>,
}

impl App {
    fn new(sender: Sender<Request>, title: String, size: (u32, u32), out: PathBuf, cols_rows: (u32, u32)) -> App {
        App {
            sender,
            title,
            size,
            out,
            cols_rows,
            window: None,
            surface: None,
            frame: None,
            cursor: PhysicalPosition::new(0.0, 0.0),
            drag: None,
            shift: false,
            grid: false,
            hud: true,
            screenshots: 0,
            error: None,
        }
    }

    fn send(&self, command: Command) {
        let _ = self.sender.send(Request { client: Client::local(), command });
    }

    fn fly(&self, right: f32, up: f32, forward: f32) {
        self.send(Command::Move { right: Some(right), up: Some(up), forward: Some(forward) });
    }

    fn key(&mut self, event_loop: &ActiveEventLoop, key: &Key) {
        let s = FLY_STEP;
        match key {
            Key::Named(NamedKey::Escape) => self.quit(event_loop),
            Key::Named(NamedKey::ArrowUp) => self.fly(0.0, 0.0, s),
            Key::Named(NamedKey::ArrowDown) => self.fly(0.0, 0.0, -s),
            Key::Named(NamedKey::ArrowLeft) => self.fly(-s, 0.0, 0.0),
            Key::Named(NamedKey::ArrowRight) => self.fly(s, 0.0, 0.0),
            Key::Named(NamedKey::PageUp) => self.fly(0.0, s, 0.0),
            Key::Named(NamedKey::PageDown) => self.fly(0.0, -s, 0.0),
            Key::Named(NamedKey::Home) => self.send(Command::Reset {}),
            Key::Character(c) => match c.to_lowercase().as_str() {
                "q" => self.quit(event_loop),
                "w" => self.fly(0.0, 0.0, s),
                "s" => self.fly(0.0, 0.0, -s),
                "a" => self.fly(-s, 0.0, 0.0),
                "d" => self.fly(s, 0.0, 0.0),
                "r" => self.fly(0.0, s, 0.0),
                "f" => self.fly(0.0, -s, 0.0),
                "0" => self.send(Command::Reset {}),
                "p" => {
                    self.screenshots += 1;
                    let path = frame_path(&self.out, self.screenshots - 1, u32::MAX);
                    eprintln!("tessera: screenshot {}", path.display());
                    self.send(Command::Snapshot { path });
                }
                "g" => {
                    self.grid = !self.grid;
                    self.redraw();
                }
                "h" => {
                    self.hud = !self.hud;
                    self.redraw();
                }
                _ => {}
            },
            _ => {}
        }
    }

    fn quit(&mut self, event_loop: &ActiveEventLoop) {
        self.send(Command::Quit {});
        event_loop.exit();
    }

    fn redraw(&self) {
        if let Some(w) = &self.window {
            w.request_redraw();
        }
    }

    /// Draws the frame (and the overlay, and the heads-up line) into the window's buffer.
    fn draw(&mut self) -> Result<()> {
        let (Some(window), Some(surface)) = (&self.window, self.surface.as_mut()) else { return Ok(()) };
        let size = window.inner_size();
        let (Some(w), Some(h)) = (NonZeroU32::new(size.width), NonZeroU32::new(size.height)) else { return Ok(()) };
        surface.resize(w, h).map_err(|e| anyhow::anyhow!("the window's buffer: {e}"))?;
        let mut buffer = surface.buffer_mut().map_err(|e| anyhow::anyhow!("the window's buffer: {e}"))?;
        buffer.fill(0);
        if let Some((image, hud, costs)) = &self.frame {
            let (fw, fh) = (image.width.min(size.width), image.height.min(size.height));
            for y in 0..fh {
                let src = &image.rgba[(y * image.width * 4) as usize..][..(fw * 4) as usize];
                let dst = &mut buffer[(y * size.width) as usize..][..fw as usize];
                for (d, p) in dst.iter_mut().zip(src.chunks_exact(4)) {
                    *d = (p[0] as u32) << 16 | (p[1] as u32) << 8 | p[2] as u32;
                }
            }
            if self.grid {
                overlay(&mut buffer, size.width, image, self.cols_rows, costs);
            }
            if self.hud {
                heads_up_line(&mut buffer, size.width, size.height, hud);
            }
            window.set_title(&format!("{} | {hud}", self.title));
        }
        buffer.present().map_err(|e| anyhow::anyhow!("the window's buffer: {e}"))?;
        Ok(())
    }
}

/// Tints each tile of the frame by its cost (green for the cheapest, red for the dearest)
/// and outlines it.
fn overlay(buffer: &mut [u32], stride: u32, image: &Image, (cols, rows): (u32, u32), costs: &[f64]) {
    let Ok(grid) = codec::view::TileGrid::new(image.width, image.height, cols, rows) else { return };
    let most = costs.iter().copied().fold(0.0, f64::max).max(1e-9);
    for i in 0..grid.tiles() {
        let [x0, y0, x1, y1] = grid.tile_rect(i);
        let c = costs.get(i).copied().unwrap_or(0.0) / most;
        let tint = [(255.0 * c) as u32, (255.0 * (1.0 - c)) as u32, 0];
        for y in y0..y1.min(image.height) {
            for x in x0..x1.min(image.width) {
                let at = (y * stride + x) as usize;
                let Some(p) = buffer.get_mut(at) else { continue };
                let edge = x == x0 || y == y0 || x + 1 == x1 || y + 1 == y1;
                let rgb = [(*p >> 16) & 255, (*p >> 8) & 255, *p & 255];
                let mix = |k: usize| if edge { tint[k] } else { (rgb[k] * 3 + tint[k]) / 4 };
                *p = mix(0) << 16 | mix(1) << 8 | mix(2);
            }
        }
    }
}

/// The heads-up line, white on a dark strip along the window's top.
fn heads_up_line(buffer: &mut [u32], width: u32, height: u32, text: &str) {
    const STRIP: u32 = 22;
    let h = STRIP.min(height);
    let mut rgb = vec![0u8; (width * h * 3) as usize];
    for y in 0..h {
        for x in 0..width {
            let p = buffer[(y * width + x) as usize];
            let o = ((y * width + x) * 3) as usize;
            // Darkened to a third, so that the text reads over any frame.
            rgb[o..o + 3].copy_from_slice(&[(p >> 16) as u8 / 3, (p >> 8) as u8 / 3, p as u8 / 3]);
        }
    }
    {
        use plotters::prelude::*;
        if crate::commands::plot::register_font().is_ok() {
            let root = BitMapBackend::with_buffer(&mut rgb, (width, h)).into_drawing_area();
            let style = TextStyle::from(("sans-serif", 15).into_font()).color(&WHITE);
            let _ = root.draw_text(text, &style, (6, 3));
            let _ = root.present();
        }
    }
    for y in 0..h {
        for x in 0..width {
            let o = ((y * width + x) * 3) as usize;
            buffer[(y * width + x) as usize] = (rgb[o] as u32) << 16 | (rgb[o + 1] as u32) << 8 | rgb[o + 2] as u32;
        }
    }
}

impl ApplicationHandler<Shown> for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.window.is_some() {
            return;
        }
        let attributes = Window::default_attributes()
            .with_title(&self.title)
            .with_inner_size(PhysicalSize::new(self.size.0, self.size.1));
        let opened = event_loop
            .create_window(attributes)
            .map_err(|e| anyhow::anyhow!("cannot open a window: {e}"))
            .and_then(|window| {
                let window = Arc::new(window);
                let context = softbuffer::Context::new(window.clone())
                    .map_err(|e| anyhow::anyhow!("cannot draw in the window: {e}"))?;
                let surface = softbuffer::Surface::new(&context, window.clone())
                    .map_err(|e| anyhow::anyhow!("cannot draw in the window: {e}"))?;
                Ok((window, surface))
            });
        match opened {
            Ok((window, surface)) => {
                self.window = Some(window);
                self.surface = Some(surface);
            }
            Err(e) => {
                self.error = Some(e);
                self.quit(event_loop);
            }
        }
    }

    fn user_event(&mut self, event_loop: &ActiveEventLoop, event: Shown) {
        match event {
            Shown::Frame { image, hud, costs } => {
                self.frame = Some((image, hud, costs));
                self.redraw();
            }
            Shown::Ended => event_loop.exit(),
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => self.quit(event_loop),
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.draw() {
                    self.error = Some(e);
                    self.quit(event_loop);
                }
            }
            WindowEvent::Resized(size) => {
                if size.width > 0 && size.height > 0 && (size.width, size.height) != self.size {
                    self.size = (size.width, size.height);
                    self.send(Command::Resize { width: size.width, height: size.height });
                }
                self.redraw();
            }
            WindowEvent::ModifiersChanged(m) => self.shift = m.state().shift_key(),
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                self.key(event_loop, &event.logical_key)
            }
            WindowEvent::MouseInput { state, button, .. } => match (state, button) {
                (ElementState::Pressed, MouseButton::Left) => {
                    self.drag = Some(Drag { pan: self.shift, at: self.cursor })
                }
                (ElementState::Pressed, MouseButton::Right) => self.drag = Some(Drag { pan: true, at: self.cursor }),
                (ElementState::Released, _) => self.drag = None,
                _ => {}
            },
            WindowEvent::CursorMoved { position, .. } => {
                self.cursor = position;
                if let Some(drag) = &mut self.drag {
                    let (dx, dy) = ((position.x - drag.at.x) as f32, (position.y - drag.at.y) as f32);
                    drag.at = position;
                    let pan = drag.pan;
                    if pan {
                        // A pixel of pan moves the view by a pixel's share of the frame's height.
                        let k = 1.0 / self.size.1.max(1) as f32;
                        self.send(Command::Move { right: Some(-dx * k), up: Some(dy * k), forward: None });
                    } else {
                        self.send(Command::Orbit {
                            degrees: -dx * DEGREES_PER_PIXEL,
                            pitch: Some(dy * DEGREES_PER_PIXEL),
                        });
                    }
                }
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                };
                if lines != 0.0 {
                    self.send(Command::Zoom { factor: 0.9f32.powf(lines) });
                }
            }
            _ => {}
        }
    }
}
