//! The control port of a live run (`render --control HOST:PORT`): programs steer rank 0 with
//! newline-delimited JSON, one command a line, each answered with one JSON line.
//!
//! | command | what it does | answer |
//! |---|---|---|
//! | `{"cmd":"camera","eye":[x,y,z],"target":[..],"up":[..],"fovy":deg}` | sets what it names of the camera; the next frame is sorted from it | `{"ok":"camera","frame":k}` |
//! | `{"cmd":"orbit","degrees":d,"pitch":p}` | turns the eye about the target: `degrees` about the up axis, `pitch` (optional) about the view's right axis | `{"ok":"orbit","frame":k}` |
//! | `{"cmd":"zoom","factor":f}` | moves the eye toward the target to `f` times its distance | `{"ok":"zoom","frame":k}` |
//! | `{"cmd":"move","right":r,"up":u,"forward":f}` | moves eye and target together (fly, pan), each in units of their distance (all optional) | `{"ok":"move","frame":k}` |
//! | `{"cmd":"reset"}` | back to the flags' camera | `{"ok":"reset","frame":k}` |
//! | `{"cmd":"animate","seconds":s,"degrees":d,"pitch":p}` or `{"cmd":"animate","seconds":s,"eye":[..],"target":[..]}` | a timed move: orbits `d` degrees (and pitches `p`), or flies eye and target in a straight line to those given, over `s` seconds; frames follow the clock (each shows where the move is when it is sorted, so a slow frame skips ahead), and any other steering command ends it | `{"ok":"animate","frame":k}` |
//! | `{"cmd":"tiles","cols":c,"rows":r}` | re-plans the frame in a `c` x `r` tile grid | `{"ok":"tiles","frame":k}` |
//! | `{"cmd":"error_px","value":e}` | the screen error `.dpm`, `.nsp` and level-of-detail `.bft` models adapt to | `{"ok":"error_px","frame":k}` |
//! | `{"cmd":"balance","on":b}` | tiles go to workers by their last costs, or round robin | `{"ok":"balance","frame":k}` |
//! | `{"cmd":"eye","position":[x,y,z]}` | head tracking: the eye of a wall placed in the world (`--wall` with a plane); without one, the camera's eye | `{"ok":"eye","frame":k}` |
//! | `{"cmd":"load","path":"model"}` | another model, any kind, in place of this one (the workers free the old one); the flags' camera frames it | `{"ok":"load","frame":k}` |
//! | `{"cmd":"snapshot","path":"x.png"}` | writes the last frame shown, whole, as a PNG (atomically) | `{"ok":"snapshot","path":..}` |
//! | `{"cmd":"subscribe"}` | streams every frame's rank 0 stats line to this client | `{"ok":"subscribe"}`, then a line a frame |
//! | `{"cmd":"status"}` | the frame count and the camera | `{"ok":"status","frames":n,"eye":..}` |
//! | `{"cmd":"quit"}` | ends the run once the frames in flight are done | `{"ok":"quit"}` |
//!
//! A line that is not JSON, or names no command this table has, gets `{"error":"..."}` and the
//! run goes on; several clients may be connected at once. The port binds to loopback unless
//! a token is given (`--control-token-file`): then every client's first line must be
//! `{"token":"..."}`, and a client that does not present it is answered with an error and
//! disconnected. A still camera costs nothing: rank 0 sorts a frame only when a command
//! changed the view, and otherwise waits for the next command.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::PathBuf;
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::{Arc, Mutex};

use anyhow::{bail, Context, Result};
use glam::Vec3;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::camera::CameraSpec;
use crate::cli::EyeStream;
use codec::view::Camera;

/// The longest command line a client may send; a longer one ends its connection (a client
/// cannot make rank 0 hold an unbounded line).
const MAX_LINE: u64 = 64 * 1024;

/// A command of the control port (the module's table).
#[derive(Debug, Deserialize, Serialize, PartialEq)]
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
pub enum Command {
    Camera {
        eye: Option<[f32; 3]>,
        target: Option<[f32; 3]>,
        up: Option<[f32; 3]>,
        fovy: Option<f32>,
    },
    Orbit {
        degrees: f32,
        pitch: Option<f32>,
    },
    Zoom {
        factor: f32,
    },
    Move {
        right: Option<f32>,
        up: Option<f32>,
        forward: Option<f32>,
    },
    Reset {},
    /// A timed camera move: `degrees` (and `pitch`) of orbit, or to `eye` and `target`, over
    /// `seconds`; each frame shows where the move is when it is sorted.
    Animate {
        seconds: f32,
        degrees: Option<f32>,
        pitch: Option<f32>,
        eye: Option<[f32; 3]>,
        target: Option<[f32; 3]>,
    },
    /// The window's new size (`tessera view`): the frame is re-planned at it, with the same
    /// tile grid.
    Resize {
        width: u32,
        height: u32,
    },
    /// A new tile grid, at the frame's size.
    Tiles {
        cols: u32,
        rows: u32,
    },
    /// The screen error `.dpm` and `.nsp` models adapt to.
    ErrorPx {
        value: f32,
    },
    Balance {
        on: bool,
    },
    Snapshot {
        path: PathBuf,
    },
    Load {
        path: PathBuf,
    },
    Eye {
        position: [f32; 3],
    },
    // Braces, so that a field they do not take is refused as for the others.
    Subscribe {},
    Status {},
    Quit {},
}

/// One client's connection, for answers and stats lines. Writes are whole lines under the
/// lock, so that two writers never interleave within a line.
#[derive(Clone)]
pub struct Client {
    id: usize,
    /// `None`: the window of `tessera view`, whose errors are printed instead.
    stream: Option<Arc<Mutex<TcpStream>>>,
}

impl Client {
    /// The window's own requests: answers are dropped, errors printed.
    pub fn local() -> Client {
        Client { id: usize::MAX, stream: None }
    }

    /// Sends one JSON line; a client that went away is only logged (the run goes on).
    pub(super) fn send(&self, value: &Value) {
        let Some(stream) = &self.stream else {
            if let Some(e) = value.get("error") {
                eprintln!("tessera: {}", e.as_str().unwrap_or_default());
            }
            return;
        };
        let mut line = value.to_string();
        line.push('\n');
        let Ok(mut s) = stream.lock() else { return };
        if let Err(e) = s.write_all(line.as_bytes()) {
            eprintln!("tessera: control client {}: {e}", self.id);
        }
    }

    pub(super) fn error(&self, message: impl std::fmt::Display) {
        self.send(&json!({ "error": message.to_string() }));
    }
}

/// A command from a client, with the client to answer.
pub struct Request {
    pub client: Client,
    pub command: Command,
}

/// The serving side: requests come in on a channel from the connections' threads (and from
/// a window), and the clients that subscribed get every frame's stats line.
pub struct Control {
    pub(super) requests: Receiver<Request>,
    sender: Sender<Request>,
    subscribers: Arc<Mutex<Vec<Client>>>,
}

impl Default for Control {
    fn default() -> Self {
        let (sender, requests) = channel();
        Control { requests, sender, subscribers: Arc::new(Mutex::new(Vec::new())) }
    }
}

impl Control {
    /// Where a window sends its requests.
    pub fn sender(&self) -> Sender<Request> {
        self.sender.clone()
    }

    /// A command a display rank's window sent (JSON), as the window's own request; one that
    /// does not parse is printed and dropped (the run goes on).
    pub(super) fn relay(&self, json: &str) {
        match serde_json::from_str::<Command>(json) {
            Ok(command) => {
                let _ = self.sender.send(Request { client: Client::local(), command });
            }
            Err(e) => eprintln!("tessera: a display window's input is not a command: {e}"),
        }
    }

    /// Serves `addr` on threads of its own, beside whatever else sends requests. A
    /// non-loopback address needs a `token`.
    pub fn listen(&self, addr: SocketAddr, token: Option<String>) -> Result<()> {
        if !addr.ip().is_loopback() && token.is_none() {
            bail!(
                "--control {addr} is not a loopback address: give --control-token-file, whose token every client must present"
            );
        }
        let listener = TcpListener::bind(addr).with_context(|| format!("--control {addr}"))?;
        let addr = listener.local_addr()?;
        let tx = self.sender.clone();
        let token = token.map(Arc::new);
        std::thread::spawn(move || {
            for (id, stream) in listener.incoming().enumerate() {
                let Ok(stream) = stream else { continue };
                let (tx, token) = (tx.clone(), token.clone());
                std::thread::spawn(move || serve(id, stream, tx, token));
            }
        });
        eprintln!("tessera: control port on {addr}");
        Ok(())
    }

    /// Adds `client` to those that get every frame's stats line.
    pub(super) fn subscribe(&self, client: Client) {
        if let Ok(mut s) = self.subscribers.lock() {
            s.push(client);
        }
    }

    /// What sends the stats lines to the subscribers (for the writer thread).
    pub(super) fn publisher(&self) -> Publisher {
        Publisher { subscribers: self.subscribers.clone() }
    }
}

/// Sends every frame's stats line to the clients that subscribed.
#[derive(Clone)]
pub(super) struct Publisher {
    subscribers: Arc<Mutex<Vec<Client>>>,
}

impl Publisher {
    pub(super) fn publish(&self, line: &Value) {
        if let Ok(subscribers) = self.subscribers.lock() {
            for c in subscribers.iter() {
                c.send(line);
            }
        }
    }
}

/// One connection: its lines parsed into requests until it closes (or, with a token, until
/// it fails to present it).
fn serve(id: usize, stream: TcpStream, tx: Sender<Request>, token: Option<Arc<String>>) {
    let Ok(reader) = stream.try_clone() else { return };
    let client = Client { id, stream: Some(Arc::new(Mutex::new(stream))) };
    let mut lines = BufReader::new(reader).take(MAX_LINE);
    let mut authorised = token.is_none();
    let mut line = String::new();
    loop {
        line.clear();
        lines.set_limit(MAX_LINE);
        match lines.read_line(&mut line) {
            Ok(0) | Err(_) => return,
            Ok(_) if !line.ends_with('\n') => {
                client.error(format!("a command line is longer than {MAX_LINE} bytes; closing"));
                return;
            }
            Ok(_) => {}
        }
        let text = line.trim();
        if text.is_empty() {
            continue;
        }
        if !authorised {
            let presented =
                serde_json::from_str::<Value>(text).ok().and_then(|v| v.get("token")?.as_str().map(String::from));
            if presented.as_deref() == token.as_deref().map(|t| t.as_str()) {
                authorised = true;
                client.send(&json!({ "ok": "token" }));
                continue;
            }
            client.error("this control port needs a token: the first line must be {\"token\":\"...\"}; closing");
            return;
        }
        match parse(text) {
            Ok(command) => {
                if tx.send(Request { client: client.clone(), command }).is_err() {
                    return;
                }
            }
            Err(e) => client.error(e),
        }
    }
}

/// A command line, or what is wrong with it in one line.
pub(super) fn parse(text: &str) -> Result<Command, String> {
    let value: Value = serde_json::from_str(text).map_err(|e| format!("not JSON: {e}"))?;
    let Some(cmd) = value.get("cmd").and_then(Value::as_str).map(String::from) else {
        return Err(
            "a command is a JSON object with a \"cmd\" (camera, orbit, zoom, move, reset, animate, eye, tiles, error_px, balance, load, snapshot, subscribe, status, quit)".into()
        );
    };
    let command: Command = serde_json::from_value(value).map_err(|e| format!("{cmd}: {e}"))?;
    let finite = |v: &Option<[f32; 3]>| v.is_none_or(|v| v.iter().all(|x| x.is_finite()));
    match &command {
        Command::Camera { eye, target, up, fovy } => {
            if !(finite(eye) && finite(target) && finite(up)) {
                return Err("camera: every coordinate must be a finite number".into());
            }
            if fovy.is_some_and(|f| !(f > 0.0 && f < 180.0)) {
                return Err("camera: fovy must be above 0 and below 180 degrees".into());
            }
        }
        Command::Orbit { degrees, pitch } if !degrees.is_finite() || pitch.is_some_and(|p| !p.is_finite()) => {
            return Err("orbit: degrees and pitch must be finite".into())
        }
        Command::Animate { seconds, degrees, pitch, eye, target } => {
            if !(seconds.is_finite() && *seconds > 0.0 && *seconds <= 86_400.0) {
                return Err("animate: seconds must be above 0 and at most a day".into());
            }
            let orbit = degrees.is_some() || pitch.is_some();
            if orbit == (eye.is_some() || target.is_some()) {
                return Err("animate: give degrees (and pitch) to orbit, or eye and target to fly to".into());
            }
            if [degrees, pitch].iter().any(|v| v.is_some_and(|v| !v.is_finite())) || !(finite(eye) && finite(target)) {
                return Err("animate: every number must be finite".into());
            }
        }
        Command::Zoom { factor } if !(factor.is_finite() && *factor > 0.0) => {
            return Err("zoom: factor must be a positive number".into())
        }
        Command::Move { right, up, forward }
            if [right, up, forward].iter().any(|v| v.is_some_and(|v| !v.is_finite())) =>
        {
            return Err("move: right, up and forward must be finite".into())
        }
        Command::Resize { width, height } => {
            crate::cli::check_frame_size(*width as u64, *height as u64).map_err(|e| format!("resize: {e}"))?
        }
        Command::Eye { position } if !position.iter().all(|v| v.is_finite()) => {
            return Err("eye: every coordinate must be a finite number".into())
        }
        Command::ErrorPx { value } if !(value.is_finite() && *value > 0.0) => {
            return Err("error_px: value must be a positive number".into())
        }
        _ => {}
    }
    Ok(command)
}

/// The camera flags after `command` (one that moves the camera; `None` for the others),
/// from `spec`, the flags so far, `cam`, the camera they gave, and `initial`, the flags the
/// run started with. The result is what `render` would take as flags for that view (a move
/// sets the eye and the target), so that the frame is the one `render` draws with them.
pub(super) fn steer(spec: &CameraSpec, cam: &Camera, initial: &CameraSpec, command: &Command) -> Option<CameraSpec> {
    let mut s = spec.clone();
    let (eye, target) = (cam.eye, cam.target);
    let back = eye - target;
    let up = cam.up.normalize_or(Vec3::Y);
    let right = back.cross(up).normalize_or(Vec3::X) * -1.0;
    match command {
        Command::Camera { eye, target, up, fovy } => {
            s.eye = eye.map(Vec3::from).or(s.eye);
            s.target = target.map(Vec3::from).or(s.target);
            s.up = up.map(Vec3::from).or(s.up);
            s.fovy = fovy.or(s.fovy);
        }
        Command::Orbit { degrees, pitch } => {
            let yaw = glam::Quat::from_axis_angle(up, degrees.to_radians());
            let turned = yaw * back;
            // Pitch about the view's right axis, stopped short of the poles (the up vector).
            let right = yaw * right;
            let pitched = glam::Quat::from_axis_angle(right, -pitch.unwrap_or(0.0).to_radians()) * turned;
            let keep = pitched.normalize_or_zero().dot(up).abs() < 0.995;
            s.eye = Some(target + if keep { pitched } else { turned });
            s.target = Some(target);
        }
        Command::Zoom { factor } => {
            s.eye = Some(target + back * *factor);
            s.target = Some(target);
        }
        Command::Move { right: r, up: u, forward: f } => {
            let d = back.length();
            let forward = -back.normalize_or(Vec3::NEG_Z);
            let by = (right * r.unwrap_or(0.0) + up * u.unwrap_or(0.0) + forward * f.unwrap_or(0.0)) * d;
            s.eye = Some(eye + by);
            s.target = Some(target + by);
        }
        Command::Reset {} => s = initial.clone(),
        _ => return None,
    }
    Some(s)
}

/// An eye position of the stream: `x y z` or `x,y,z`, after the token where one is needed.
fn eye_line(line: &str, token: Option<&str>) -> Result<[f32; 3], String> {
    let line = line.trim_start();
    let point = match token {
        Some(token) => match line.strip_prefix(token) {
            Some(rest) if rest.starts_with(|c: char| c == ',' || c.is_whitespace()) => rest,
            _ => return Err("no token: a datagram from beyond loopback starts with the control token".into()),
        },
        None => line,
    };
    Ok(crate::cli::parse_point(point)?.to_array())
}

/// Reads `stream` on a thread of its own, each eye position an `eye` request on `requests`
/// (what cannot be read is said on standard error, and the stream goes on). UDP binds to
/// loopback unless a `token` is given, which each datagram must then start with.
pub fn start_eye_stream(stream: &EyeStream, token: Option<String>, requests: Sender<Request>) -> Result<()> {
    let send = move |line: &str, token: Option<&str>| match eye_line(line, token) {
        Ok(position) => requests.send(Request { client: Client::local(), command: Command::Eye { position } }).is_ok(),
        Err(e) => {
            eprintln!("tessera: --eye-stream: {e}");
            true
        }
    };
    match stream {
        EyeStream::Stdin => {
            std::thread::spawn(move || {
                for line in std::io::stdin().lock().lines() {
                    let Ok(line) = line else { return };
                    let line = line.split('#').next().unwrap_or("").trim().to_string();
                    if !line.is_empty() && !send(&line, None) {
                        return;
                    }
                }
            });
        }
        EyeStream::Udp(addr) => {
            if !addr.ip().is_loopback() && token.is_none() {
                bail!(
                    "--eye-stream udp:{addr} is not a loopback address: give --control-token-file, whose token each datagram must start with"
                );
            }
            let socket = std::net::UdpSocket::bind(addr).with_context(|| format!("--eye-stream udp:{addr}"))?;
            eprintln!("tessera: eye stream on udp:{}", socket.local_addr()?);
            std::thread::spawn(move || {
                let mut buf = [0u8; 512];
                while let Ok(n) = socket.recv(&mut buf) {
                    let text = String::from_utf8_lossy(&buf[..n]).trim().to_string();
                    if !send(&text, token.as_deref()) {
                        return;
                    }
                }
            });
        }
    }
    Ok(())
}

/// Reads the token of `--control-token-file`: its first line, trimmed, at least 16 bytes.
pub(super) fn read_token(path: &std::path::Path) -> Result<String> {
    let what = || format!("--control-token-file {}", path.display());
    let (file, _) = codec::input::open_regular(path).map_err(anyhow::Error::msg).with_context(what)?;
    let mut text = Vec::new();
    codec::input::read_capped(file, 4096, &mut text).map_err(anyhow::Error::msg).with_context(what)?;
    let token = String::from_utf8_lossy(&text).lines().next().unwrap_or("").trim().to_string();
    if token.len() < 16 {
        bail!("--control-token-file {}: the token must be at least 16 characters", path.display());
    }
    Ok(token)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_parse_and_bad_ones_say_why() {
        assert_eq!(parse(r#"{"cmd":"quit"}"#), Ok(Command::Quit {}));
        assert_eq!(parse(r#"{"cmd":"orbit","degrees":10}"#), Ok(Command::Orbit { degrees: 10.0, pitch: None }));
        assert_eq!(
            parse(r#"{"cmd":"camera","eye":[1,2,3]}"#),
            Ok(Command::Camera { eye: Some([1.0, 2.0, 3.0]), target: None, up: None, fovy: None })
        );
        for (line, says) in [
            ("{", "not JSON"),
            (r#"{"cmd":"fly"}"#, "unknown variant"),
            (r#"{"x":1}"#, "\"cmd\""),
            (r#"{"cmd":"orbit"}"#, "degrees"),
            (r#"{"cmd":"camera","fovy":500}"#, "fovy"),
            (r#"{"cmd":"camera","eye":[1,2]}"#, "camera"),
            (r#"{"cmd":"quit","now":true}"#, "unknown field"),
        ] {
            let e = parse(line).unwrap_err();
            assert!(e.contains(says), "{line}: {e}");
        }
    }

    #[test]
    fn orbit_turns_about_the_target() {
        let spec = CameraSpec::default();
        let cam = spec.camera([-1.0; 3], [1.0; 3], 1.0).unwrap();
        let s = steer(&spec, &cam, &spec, &Command::Orbit { degrees: 90.0, pitch: None }).unwrap();
        let c = s.camera([-1.0; 3], [1.0; 3], 1.0).unwrap();
        assert_eq!(c.target, cam.target);
        assert!(((c.eye - c.target).length() - (cam.eye - cam.target).length()).abs() < 1e-4);
        assert!((c.eye - c.target).dot(cam.eye - cam.target).abs() < 1e-3);
    }

    #[test]
    fn a_public_address_needs_a_token() {
        let e = Control::default().listen("0.0.0.0:0".parse().unwrap(), None).err().unwrap().to_string();
        assert!(e.contains("token"), "{e}");
    }
}
