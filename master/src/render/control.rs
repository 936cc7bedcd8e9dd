//! The control port of a live run (`render --control HOST:PORT`): programs steer rank 0 with
//! newline-delimited JSON, one command a line, each answered with one JSON line.
//!
//! | command | what it does | answer |
//! |---|---|---|
//! | `{"cmd":"camera","eye":[x,y,z],"target":[..],"up":[..],"fovy":deg}` | sets what it names of the camera; the next frame is sorted from it | `{"ok":"camera","frame":k}` |
//! | `{"cmd":"orbit","degrees":d}` | turns the eye about the target's vertical axis | `{"ok":"orbit","frame":k}` |
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
use serde::Deserialize;
use serde_json::{json, Value};

use crate::camera::CameraSpec;
use codec::view::Camera;

/// The longest command line a client may send; a longer one ends its connection (a client
/// cannot make rank 0 hold an unbounded line).
const MAX_LINE: u64 = 64 * 1024;

/// A command of the control port (the module's table).
#[derive(Debug, Deserialize, PartialEq)]
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
pub(super) enum Command {
    Camera { eye: Option<[f32; 3]>, target: Option<[f32; 3]>, up: Option<[f32; 3]>, fovy: Option<f32> },
    Orbit { degrees: f32 },
    Snapshot { path: PathBuf },
    // Braces, so that a field they do not take is refused as for the others.
    Subscribe {},
    Status {},
    Quit {},
}

/// One client's connection, for answers and stats lines. Writes are whole lines under the
/// lock, so that two writers never interleave within a line.
#[derive(Clone)]
pub(super) struct Client {
    id: usize,
    stream: Arc<Mutex<TcpStream>>,
}

impl Client {
    /// Sends one JSON line; a client that went away is only logged (the run goes on).
    pub(super) fn send(&self, value: &Value) {
        let mut line = value.to_string();
        line.push('\n');
        let Ok(mut s) = self.stream.lock() else { return };
        if let Err(e) = s.write_all(line.as_bytes()) {
            eprintln!("tessera: control client {}: {e}", self.id);
        }
    }

    pub(super) fn error(&self, message: impl std::fmt::Display) {
        self.send(&json!({ "error": message.to_string() }));
    }
}

/// A command from a client, with the client to answer.
pub(super) struct Request {
    pub client: Client,
    pub command: Command,
}

/// The serving side: requests come in on a channel from the connections' threads, and the
/// clients that subscribed get every frame's stats line.
pub(super) struct Control {
    pub requests: Receiver<Request>,
    subscribers: Arc<Mutex<Vec<Client>>>,
}

impl Control {
    /// Binds `addr` and serves it on threads of its own. A non-loopback address needs a
    /// `token`.
    pub(super) fn bind(addr: SocketAddr, token: Option<String>) -> Result<Control> {
        if !addr.ip().is_loopback() && token.is_none() {
            bail!(
                "--control {addr} is not a loopback address: give --control-token-file, whose token every client must present"
            );
        }
        let listener = TcpListener::bind(addr).with_context(|| format!("--control {addr}"))?;
        let addr = listener.local_addr()?;
        let (tx, requests) = channel();
        let token = token.map(Arc::new);
        std::thread::spawn(move || {
            for (id, stream) in listener.incoming().enumerate() {
                let Ok(stream) = stream else { continue };
                let (tx, token) = (tx.clone(), token.clone());
                std::thread::spawn(move || serve(id, stream, tx, token));
            }
        });
        eprintln!("tessera: control port on {addr}");
        Ok(Control { requests, subscribers: Arc::new(Mutex::new(Vec::new())) })
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
    let client = Client { id, stream: Arc::new(Mutex::new(stream)) };
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
            "a command is a JSON object with a \"cmd\" (camera, orbit, snapshot, subscribe, status, quit)".into()
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
        Command::Orbit { degrees } if !degrees.is_finite() => return Err("orbit: degrees must be finite".into()),
        _ => {}
    }
    Ok(command)
}

/// The camera flags after `command` (a camera or orbit command; `None` for the others),
/// from `spec`, the flags so far, and `cam`, the camera they gave. The result is what
/// `render` would take as flags for that view (an orbit sets the eye and the target), so that
/// the frame is the one `render` draws with them.
pub(super) fn steer(spec: &CameraSpec, cam: &Camera, command: &Command) -> Option<CameraSpec> {
    let mut s = spec.clone();
    match command {
        Command::Camera { eye, target, up, fovy } => {
            s.eye = eye.map(Vec3::from).or(s.eye);
            s.target = target.map(Vec3::from).or(s.target);
            s.up = up.map(Vec3::from).or(s.up);
            s.fovy = fovy.or(s.fovy);
        }
        Command::Orbit { degrees } => {
            let q = glam::Quat::from_axis_angle(cam.up.normalize_or(Vec3::Y), degrees.to_radians());
            s.eye = Some(cam.target + q * (cam.eye - cam.target));
            s.target = Some(cam.target);
        }
        _ => return None,
    }
    Some(s)
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
        assert_eq!(parse(r#"{"cmd":"orbit","degrees":10}"#), Ok(Command::Orbit { degrees: 10.0 }));
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
        let s = steer(&spec, &cam, &Command::Orbit { degrees: 90.0 }).unwrap();
        let c = s.camera([-1.0; 3], [1.0; 3], 1.0).unwrap();
        assert_eq!(c.target, cam.target);
        assert!(((c.eye - c.target).length() - (cam.eye - cam.target).length()).abs() < 1e-4);
        assert!((c.eye - c.target).dot(cam.eye - cam.target).abs() < 1e-3);
    }

    #[test]
    fn a_public_address_needs_a_token() {
        let e = Control::bind("0.0.0.0:0".parse().unwrap(), None).err().unwrap().to_string();
        assert!(e.contains("token"), "{e}");
    }
}
