//! The windows of a live run: `tessera view`'s one window, and `render --present`'s one per
//! display of a wall (or one for the frame). They run their event loop on a thread of their
//! own (X11 allows any thread), so that the rank's MPI calls stay where they are; a frame is
//! handed to them as an image, and what a person does in the steering window becomes the
//! commands of the control port (`render::control`), sent to whoever applies them.
//!
//! | input (the steering window) | command |
//! |---|---|
//! | left drag | orbit about the target (yaw and pitch) |
//! | right drag, or shift and left drag | pan (eye and target together) |
//! | wheel | zoom toward the target |
//! | W, S, A, D, R/F or the arrows, Page Up and Down | fly forward, back, left, right, up, down |
//! | Home or 0 | reset to the flags' camera |
//! | P | screenshot: `--out`, numbered (`frame-0001.png`...), equal to `render`'s PNG for that camera |
//! | G | overlay of the tile grid, each tile tinted by its cost (decode and render ms) |
//! | H | the heads-up line on and off |
//! | Q, Escape (in any window), closing any window | quit |
//!
//! A frame is shown as the rank holds it, pixel for pixel (`softbuffer`: no GPU upload), on
//! black where nothing was drawn. Nothing is drawn but when a frame comes or the X server
//! asks (an expose): the event loop sleeps between events.

use std::num::NonZeroU32;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Sender, SyncSender};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use serde_json::Value;
use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop, EventLoopProxy};
use winit::keyboard::{Key, NamedKey};
use winit::monitor::MonitorHandle;
use winit::platform::x11::EventLoopBuilderExtX11;
use winit::window::{Fullscreen, Window, WindowId};

use crate::composite::Image;
use crate::render::control::Command;
use crate::render::{frame_path, Plan, Present};
use crate::wall::{Display, Monitor, WindowPlace};

/// Degrees of orbit per pixel dragged.
const DEGREES_PER_PIXEL: f32 = 0.3;
/// A step of flying or panning by keys, in units of the eye's distance to the target.
const FLY_STEP: f32 = 0.05;

/// Where the windows' commands go: rank 0's control channel, or a display rank's messages
/// to rank 0.
pub type Input = Box<dyn Fn(Command) + Send>;

/// One window: its title, the size of its picture, where it opens, and which part of a
/// whole frame it shows (`None`: all of it).
pub struct WindowSpec {
    pub title: String,
    pub size: (u32, u32),
    pub place: WindowPlace,
    pub crop: Option<[u32; 4]>,
}

impl WindowSpec {
    /// One window for `plan`'s whole frame, where the window manager puts it.
    pub fn frame(plan: &Plan) -> WindowSpec {
        WindowSpec {
            title: title(plan),
            size: (plan.grid.width, plan.grid.height),
            place: WindowPlace::default(),
            crop: None,
        }
    }

    /// The window of a wall's display `d`, where the wall file places it, showing its
    /// picture; with `of_frame`, its part of the whole frames it is handed (rank 0's windows),
    /// else pictures of its own (a display rank's).
    pub fn display(plan: &Plan, d: &Display, of_frame: bool) -> WindowSpec {
        let [x0, y0, x1, y1] = d.rect;
        WindowSpec {
            title: format!("{}, display {}", title(plan), d.name),
            size: (x1 - x0, y1 - y0),
            place: d.window.clone(),
            crop: of_frame.then_some(d.rect),
        }
    }
}

/// "Tessera: " and the model's file name.
fn title(plan: &Plan) -> String {
    format!("Tessera: {}", plan.model.file_name().map_or_else(String::new, |n| n.to_string_lossy().into_owned()))
}

/// How the windows behave: which of them steers, whether a resize re-plans the frame, the
/// heads-up line at the start, where screenshots go.
pub struct Behaviour {
    /// The first window takes the mouse and keys (`view`, rank 0's windows, the display
    /// rank with the wall's first display); every window's close quits.
    pub steer: bool,
    /// A resized window asks for the frame at its new size (`view`, a frame without a wall).
    pub resize: bool,
    pub hud: bool,
    /// `--out`: screenshots are numbered beside it.
    pub out: PathBuf,
    /// The tile grid's columns and rows, for the cost overlay.
    pub tiles: (u32, u32),
}

impl Behaviour {
    /// `plan`'s windows: the first steers, a resize changes nothing, no heads-up line.
    pub fn of(plan: &Plan) -> Behaviour {
        Behaviour {
            steer: true,
            resize: false,
            hud: false,
            out: plan.out.clone(),
            tiles: (plan.grid.cols, plan.grid.rows),
        }
    }
}

/// What the windows are told.
enum Shown {
    /// A whole frame, each window showing its part, with the heads-up line and tile costs.
    Whole { image: Arc<Image>, hud: String, costs: Vec<f64> },
    /// A picture for each window (a display rank's displays), drawn before `drawn` is
    /// answered: a swap.
    Each { images: Vec<Image>, drawn: SyncSender<()> },
    /// The run ended.
    Ended,
}

/// Open windows, served by their own thread.
pub struct Windows {
    proxy: EventLoopProxy<Shown>,
    thread: Option<std::thread::JoinHandle<Result<()>>>,
    /// A person closed them (Q, Escape, a closed window): the quit is on its way to rank 0,
    /// and frames that come meanwhile are not drawn.
    quit: Arc<AtomicBool>,
}

impl Windows {
    /// Opens `specs` on the X display of `DISPLAY` and returns once they are open, or with
    /// why they cannot be; `alive` is called every `beat` meanwhile (a display rank tells rank
    /// 0 that it is starting, so that a slow X server is not taken for a dead rank).
    pub fn open(
        specs: Vec<WindowSpec>,
        behaviour: Behaviour,
        input: Input,
        beat: Duration,
        alive: &mut dyn FnMut(),
    ) -> Result<Windows> {
        let display = match std::env::var("DISPLAY") {
            Ok(d) if !d.is_empty() => d,
            _ => bail!("the windows need an X display, and DISPLAY is not set (run on one, or under Xvfb)"),
        };
        let (opened, open) = std::sync::mpsc::channel::<Result<EventLoopProxy<Shown>>>();
        let quit = Arc::new(AtomicBool::new(false));
        let quit_set = quit.clone();
        let thread = std::thread::Builder::new()
            .name("windows".into())
            .spawn(move || -> Result<()> {
                let event_loop = EventLoop::<Shown>::with_user_event().with_any_thread(true).build();
                let event_loop = match event_loop {
                    Ok(l) => l,
                    Err(e) => {
                        let _ = opened.send(Err(anyhow::anyhow!("cannot open the X display {display}: {e}")));
                        return Ok(());
                    }
                };
                event_loop.set_control_flow(ControlFlow::Wait);
                let mut app = App::new(specs, behaviour, input, opened, event_loop.create_proxy(), quit_set);
                let ran = event_loop.run_app(&mut app);
                if let Some(e) = app.error.take() {
                    return Err(e);
                }
                ran.context("the windows' event loop failed")
            })
            .context("cannot start the windows' thread")?;
        loop {
            match open.recv_timeout(beat) {
                Ok(Ok(proxy)) => return Ok(Windows { proxy, thread: Some(thread), quit }),
                Ok(Err(e)) => {
                    let _ = thread.join();
                    return Err(e);
                }
                Err(std::sync::mpsc::RecvTimeoutError::Timeout) => alive(),
                Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                    return Err(match thread.join() {
                        Ok(Err(e)) => e,
                        _ => anyhow::anyhow!("the windows closed as they opened"),
                    });
                }
            }
        }
    }

    /// What the frame loop's writer calls with each frame: the image, with the heads-up line
    /// and the tile costs made from its stats lines.
    pub fn presenter(&self) -> Present {
        let proxy = self.proxy.clone();
        Box::new(move |image: &Arc<Image>, master: &Value, workers: &[Value]| {
            let (hud, costs) = heads_up(master, workers);
            let _ = proxy.send_event(Shown::Whole { image: image.clone(), hud, costs });
        })
    }

    /// Shows one picture in each window and returns once all are drawn (a swap); an error if
    /// the windows closed, or took longer than `timeout`.
    pub fn show_each(&self, images: Vec<Image>, timeout: Duration) -> Result<()> {
        let (drawn, done) = std::sync::mpsc::sync_channel(1);
        let closed = || match self.quit.load(Ordering::Relaxed) {
            // Quit by a person: the run ends once rank 0 has the quit.
            true => Ok(()),
            false => bail!("the windows are closed"),
        };
        if self.proxy.send_event(Shown::Each { images, drawn }).is_err() {
            return closed();
        }
        match done.recv_timeout(timeout) {
            Ok(()) => Ok(()),
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                bail!("the windows did not draw a frame within {:.0} s", timeout.as_secs_f64())
            }
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => closed(),
        }
    }

    /// Closes the windows; why they failed, if they did.
    pub fn close(mut self) -> Result<()> {
        let _ = self.proxy.send_event(Shown::Ended);
        match self.thread.take().map(|t| t.join()) {
            Some(Ok(r)) => r,
            Some(Err(_)) => bail!("the windows' thread panicked"),
            None => Ok(()),
        }
    }
}

impl Drop for Windows {
    fn drop(&mut self) {
        let _ = self.proxy.send_event(Shown::Ended);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The heads-up line of a frame (frames a second from the frame's period, sort ms, the
/// workers' decode and render ms, bytes sent, triangles drawn) and each tile's cost (decode
/// and render ms).
pub fn heads_up(master: &Value, workers: &[Value]) -> (String, Vec<f64>) {
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

/// One open window and what it shows.
struct Open {
    window: Arc<Window>,
    surface: softbuffer::Surface<Arc<Window>, Arc<Window>>,
    spec: WindowSpec,
    /// Its own picture (a display rank's swap), else its part of the whole frame.
    image: Option<Image>,
}

struct App {
    specs: Vec<WindowSpec>,
    behaviour: Behaviour,
    input: Input,
    /// Told once the windows are open (or why not).
    opened: Option<Sender<Result<EventLoopProxy<Shown>>>>,
    proxy: EventLoopProxy<Shown>,
    open: Vec<Open>,
    /// The picture size the frame was planned at (a resize asks for another).
    size: (u32, u32),
    frame: Option<(Arc<Image>, String, Vec<f64>)>,
    cursor: PhysicalPosition<f64>,
    drag: Option<Drag>,
    shift: bool,
    grid: bool,
    screenshots: u32,
    /// Why the windows failed, for the thread to return.
    error: Option<anyhow::Error>,
    /// Set when a person quits.
    quit: Arc<AtomicBool>,
}

impl App {
    fn new(
        specs: Vec<WindowSpec>,
        behaviour: Behaviour,
        input: Input,
        opened: Sender<Result<EventLoopProxy<Shown>>>,
        proxy: EventLoopProxy<Shown>,
        quit: Arc<AtomicBool>,
    ) -> App {
        App {
            quit,
            size: specs.first().map_or((0, 0), |s| s.size),
            specs,
            behaviour,
            input,
            opened: Some(opened),
            proxy,
            open: Vec::new(),
            frame: None,
            cursor: PhysicalPosition::new(0.0, 0.0),
            drag: None,
            shift: false,
            grid: false,
            screenshots: 0,
            error: None,
        }
    }

    fn send(&self, command: Command) {
        (self.input)(command);
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
                    let path = frame_path(&self.behaviour.out, self.screenshots - 1, u32::MAX);
                    eprintln!("tessera: screenshot {}", path.display());
                    self.send(Command::Snapshot { path });
                }
                "g" => {
                    self.grid = !self.grid;
                    self.redraw();
                }
                "h" => {
                    self.behaviour.hud = !self.behaviour.hud;
                    self.redraw();
                }
                _ => {}
            },
            _ => {}
        }
    }

    fn quit(&mut self, event_loop: &ActiveEventLoop) {
        self.quit.store(true, Ordering::Relaxed);
        self.send(Command::Quit {});
        event_loop.exit();
    }

    fn redraw(&self) {
        self.open.iter().for_each(|o| o.window.request_redraw());
    }

    /// Draws window `i`'s picture (its part of the frame, the overlay and the heads-up line
    /// in the steering window) into its buffer and presents it.
    fn draw(&mut self, i: usize) -> Result<()> {
        let steering = i == 0 && self.behaviour.steer;
        let (grid, hud_on, tiles) = (self.grid && steering, self.behaviour.hud && steering, self.behaviour.tiles);
        let frame = self.frame.clone();
        let Some(o) = self.open.get_mut(i) else { return Ok(()) };
        let size = o.window.inner_size();
        let (Some(w), Some(h)) = (NonZeroU32::new(size.width), NonZeroU32::new(size.height)) else { return Ok(()) };
        o.surface.resize(w, h).map_err(|e| anyhow::anyhow!("the window's buffer: {e}"))?;
        let mut buffer = o.surface.buffer_mut().map_err(|e| anyhow::anyhow!("the window's buffer: {e}"))?;
        buffer.fill(0);
        // Its own picture, or its part of the whole frame: the source rectangle, shown at
        // the window's top-left pixel for pixel.
        let source = match (&o.image, &frame) {
            (Some(own), _) => Some((own, [0, 0, own.width, own.height])),
            (None, Some((whole, ..))) => {
                Some((whole.as_ref(), o.spec.crop.unwrap_or([0, 0, whole.width, whole.height])))
            }
            (None, None) => None,
        };
        if let Some((image, [x0, y0, x1, y1])) = source {
            let (x1, y1) = (x1.min(image.width), y1.min(image.height));
            let (fw, fh) = (x1.saturating_sub(x0).min(size.width), y1.saturating_sub(y0).min(size.height));
            for y in 0..fh {
                let src = &image.rgba[(((y0 + y) * image.width + x0) * 4) as usize..][..(fw * 4) as usize];
                let dst = &mut buffer[(y * size.width) as usize..][..fw as usize];
                for (d, p) in dst.iter_mut().zip(src.chunks_exact(4)) {
                    *d = (p[0] as u32) << 16 | (p[1] as u32) << 8 | p[2] as u32;
                }
            }
            if let (true, Some((whole, _, costs)), None) = (grid, &frame, o.spec.crop) {
                overlay(&mut buffer, size.width, whole, tiles, costs);
            }
        }
        if let Some((_, hud, _)) = &frame {
            if hud_on {
                heads_up_line(&mut buffer, size.width, size.height, hud);
            }
            if steering {
                o.window.set_title(&format!("{} | {hud}", o.spec.title));
            }
        }
        buffer.present().map_err(|e| anyhow::anyhow!("the window's buffer: {e}"))?;
        Ok(())
    }

    /// Opens every window, placed as its spec says.
    fn open_all(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let monitors: Vec<MonitorHandle> = event_loop.available_monitors().collect();
        for spec in std::mem::take(&mut self.specs) {
            let place = &spec.place;
            let monitor = match &place.monitor {
                None => None,
                Some(m) => Some(find_monitor(&monitors, m).with_context(|| format!("the window of {}", spec.title))?),
            };
            let mut attributes = Window::default_attributes()
                .with_title(&spec.title)
                .with_inner_size(PhysicalSize::new(spec.size.0, spec.size.1))
                .with_resizable(self.behaviour.resize);
            let origin = monitor.as_ref().map_or(PhysicalPosition::new(0, 0), MonitorHandle::position);
            if let (Some(x), Some(y)) = (place.x, place.y) {
                attributes = attributes.with_position(PhysicalPosition::new(origin.x + x, origin.y + y));
            } else if monitor.is_some() {
                attributes = attributes.with_position(origin);
            }
            if place.fullscreen == Some(true) {
                // Positioned on its monitor first: X11 fullscreen takes the monitor the
                // window is on (winit#1270).
                attributes = attributes.with_decorations(false).with_fullscreen(Some(Fullscreen::Borderless(monitor)));
            }
            let window = Arc::new(
                event_loop.create_window(attributes).map_err(|e| anyhow::anyhow!("cannot open a window: {e}"))?,
            );
            let context = softbuffer::Context::new(window.clone())
                .map_err(|e| anyhow::anyhow!("cannot draw in the window: {e}"))?;
            let surface = softbuffer::Surface::new(&context, window.clone())
                .map_err(|e| anyhow::anyhow!("cannot draw in the window: {e}"))?;
            self.open.push(Open { window, surface, spec, image: None });
        }
        Ok(())
    }

    /// The windows failed: why, for whoever opened them or for the thread to return; the run
    /// is told to quit (not as a person's quit: the failure is the run's error).
    fn fail(&mut self, event_loop: &ActiveEventLoop, e: anyhow::Error) {
        match self.opened.take() {
            Some(opened) => {
                let _ = opened.send(Err(e));
            }
            None => self.error = Some(e),
        }
        self.send(Command::Quit {});
        event_loop.exit();
    }
}

/// The monitor a wall file names, by name or index.
fn find_monitor(monitors: &[MonitorHandle], m: &Monitor) -> Result<MonitorHandle> {
    let found = match m {
        Monitor::Index(i) => monitors.get(*i as usize),
        Monitor::Name(name) => monitors.iter().find(|h| h.name().as_deref() == Some(name.as_str())),
    };
    found.cloned().with_context(|| {
        let names: Vec<String> = monitors.iter().map(|h| h.name().unwrap_or_else(|| "(unnamed)".into())).collect();
        let which = match m {
            Monitor::Index(i) => format!("monitor {i}"),
            Monitor::Name(n) => format!("monitor {n}"),
        };
        format!("no {which} on this X display (it has {})", names.join(", "))
    })
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
        if self.opened.is_none() {
            return;
        }
        match self.open_all(event_loop) {
            Ok(()) => {
                if let Some(opened) = self.opened.take() {
                    let _ = opened.send(Ok(self.proxy.clone()));
                }
            }
            Err(e) => self.fail(event_loop, e),
        }
    }

    fn user_event(&mut self, event_loop: &ActiveEventLoop, event: Shown) {
        match event {
            Shown::Whole { image, hud, costs } => {
                self.frame = Some((image, hud, costs));
                self.redraw();
            }
            Shown::Each { images, drawn } => {
                for (o, image) in self.open.iter_mut().zip(images) {
                    o.image = Some(image);
                }
                // Drawn now, not at the next redraw: the swap is answered once every
                // window shows the frame.
                for i in 0..self.open.len() {
                    if let Err(e) = self.draw(i) {
                        return self.fail(event_loop, e);
                    }
                }
                let _ = drawn.send(());
            }
            Shown::Ended => event_loop.exit(),
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, id: WindowId, event: WindowEvent) {
        let Some(i) = self.open.iter().position(|o| o.window.id() == id) else { return };
        let steering = i == 0 && self.behaviour.steer;
        match event {
            WindowEvent::CloseRequested => self.quit(event_loop),
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.draw(i) {
                    self.fail(event_loop, e);
                }
            }
            WindowEvent::Resized(size) => {
                if steering
                    && self.behaviour.resize
                    && size.width > 0
                    && size.height > 0
                    && (size.width, size.height) != self.size
                {
                    self.size = (size.width, size.height);
                    self.send(Command::Resize { width: size.width, height: size.height });
                }
                self.open[i].window.request_redraw();
            }
            // Any window quits; only the steering one steers.
            WindowEvent::KeyboardInput { event, .. }
                if !steering
                    && event.state == ElementState::Pressed
                    && (event.logical_key == Key::Named(NamedKey::Escape)
                        || matches!(&event.logical_key, Key::Character(c) if c.eq_ignore_ascii_case("q"))) =>
            {
                self.quit(event_loop)
            }
            _ if !steering => {}
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
