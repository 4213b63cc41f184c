//! What a python schema and its worker process say to each other over their
//! socket: one frame per message, `[json length u32 LE][payload length u32 LE]
//! [json][payload]`; the payload carries an image's bytes, so they are never
//! written as JSON. Frames are rare (a load, a pass, a print, a changed
//! command); the sensors go through the [`board`](super::board).

use std::io::{self, Read, Write};

use serde::{Deserialize, Serialize};

/// jderobot → worker.
#[derive(Serialize, Deserialize, Debug)]
pub enum ToWorker {
    /// Compile the program (and add the venv's packages); answered by
    /// [`FromWorker::Loaded`] or [`FromWorker::Refused`]. `per_command`: the
    /// run's clock advances per motors command, so the command goes out once per
    /// pass, at its end (see `Robot::per_command`).
    Load {
        path: String,
        source: String,
        venv: Option<String>,
        per_command: bool,
        /// (the `uses` line's key, the interface or `none`, whether it is there).
        lines: Vec<(String, String, bool)>,
        /// The world's targets (`GUI.map`), x and y in m, in order.
        targets: Vec<(f64, f64)>,
    },
    /// Run the init code (0), one pass of the loop (1) or the code after it (2);
    /// answered by [`FromWorker::Outcome`]. In the Academy 5 shape 0 is the
    /// whole program.
    Pass(u8),
}

/// worker → jderobot.
#[derive(Serialize, Deserialize, Debug)]
pub enum FromWorker {
    Loaded {
        academy5: bool,
        has_loop: bool,
    },
    Refused(Failure),
    /// What the program printed.
    Print(String),
    /// The program's command (v mm/s, w deg/s): `HAL.setV`/`setW` changed it, or
    /// (`end_of_pass`) a pass on a per-command clock ended.
    Command {
        v: f32,
        w: f32,
        end_of_pass: bool,
    },
    /// `GUI.showImage`: the BGR bytes are the payload.
    Image {
        width: u32,
        height: u32,
    },
    /// `GUI.showForces` (or a 4.x pass's `GUI.map.carx`...): car, obstacle and
    /// average, [x, y] in the robot's frame.
    Forces([[f64; 2]; 3]),
    /// `GUI.showLocalTarget`: [x, y] m in the robot's frame.
    LocalTarget([f64; 2]),
    Outcome(Outcome),
}

/// A program's failure: the line (0: unknown), a one-line `FILE:LINE: what`, and
/// the full text (a traceback) to print.
#[derive(Serialize, Deserialize, Debug, Clone)]
pub struct Failure {
    pub line: usize,
    pub summary: String,
    pub text: String,
}

/// How running a piece of the program went.
#[derive(Serialize, Deserialize, Debug)]
pub enum Outcome {
    Done,
    /// `break` out of the main loop.
    Broke,
    /// `sys.exit(...)` / `exit()`: the program ended itself (its argument).
    Exited(String),
    Failed(Failure),
}

/// The largest frame either side takes (a 4K BGR image and its header).
const MAX_FRAME: usize = 64 << 20;

/// Writes one message (and its payload) as one frame.
pub fn send<T: Serialize>(w: &mut impl Write, msg: &T, payload: &[u8]) -> io::Result<()> {
    let json = serde_json::to_vec(msg).map_err(io::Error::other)?;
    let mut head = [0u8; 8];
    head[..4].copy_from_slice(&(json.len() as u32).to_le_bytes());
    head[4..].copy_from_slice(&(payload.len() as u32).to_le_bytes());
    let mut frame = Vec::with_capacity(8 + json.len() + SMALL);
    frame.extend_from_slice(&head);
    frame.extend_from_slice(&json);
    // A small payload goes in the same write; a large one (an image) is not
    // copied into the frame.
    if payload.len() <= SMALL {
        frame.extend_from_slice(payload);
        return w.write_all(&frame);
    }
    w.write_all(&frame)?;
    w.write_all(payload)
}

/// The largest payload [`send`] copies into its frame.
const SMALL: usize = 4096;

/// Reads one message and its payload; Ok(None) when the other side closed.
pub fn receive<T: for<'de> Deserialize<'de>>(
    r: &mut impl Read,
) -> io::Result<Option<(T, Vec<u8>)>> {
    let mut head = [0u8; 8];
    match r.read_exact(&mut head) {
        Ok(()) => {}
        Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => return Ok(None),
        Err(e) => return Err(e),
    }
    let json_len = u32::from_le_bytes(head[..4].try_into().expect("4 bytes")) as usize;
    let payload_len = u32::from_le_bytes(head[4..].try_into().expect("4 bytes")) as usize;
    if json_len + payload_len > MAX_FRAME {
        return Err(io::Error::other(format!(
            "a frame of {} bytes (at most {MAX_FRAME})",
            json_len + payload_len
        )));
    }
    let mut json = vec![0u8; json_len];
    r.read_exact(&mut json)?;
    let mut payload = vec![0u8; payload_len];
    r.read_exact(&mut payload)?;
    let msg = serde_json::from_slice(&json).map_err(io::Error::other)?;
    Ok(Some((msg, payload)))
}
