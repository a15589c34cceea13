//! Simulator input over TCP: an external simulator streams frames of a garment to a running
//! werkstatt. The protocol is documented in docs/livelink.md; the encoders here are what
//! `examples/livelink_send.rs` and the tests use.
//!
//! A listener thread (started on the node's first run, stopped when the node is dropped or
//! its address changes) accepts one sender at a time, validates every message, builds the
//! surface (normals, tangents) off the render thread and publishes it as the latest frame.
//! The node never blocks: its run takes the latest frame from a mutex. It re-runs only when
//! the listener bumps its [`ChangeSignal`] (a new frame, an error, the listener starting), not
//! every frame.

use std::io::{ErrorKind, Read};
use std::net::{SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use glam::{Vec2, Vec3};

use crate::core::node::ChangeSignal;
use crate::core::node::prelude::*;
use crate::mesh::Mesh;

pub static LIVE_LINK: NodeSpec = NodeSpec {
    kind: "LiveLink",
    category: Category::Simulation,
    doc: "Receives a garment streamed by an external simulator over TCP (protocol in docs/livelink.md): a topology (indices, UVs, pieces) once per connection, then positions per frame. Shows the latest complete frame without ever blocking, keeps the last good frame across disconnects, rejects malformed messages with a warning. Re-runs only when a frame arrives.",
    inputs: &[],
    outputs: &[
        PortSpec::output("surface", PortType::Surface, "The latest frame received; UVs are the pattern coordinates."),
        PortSpec::output("frame", PortType::Scalar, "The simulator's frame number of that frame."),
    ],
    params: &[
        ParamSpec::new(
            "address",
            ParamKind::Text { default: "127.0.0.1:7878" },
            "Where to listen, host:port. The default accepts only this machine (loopback); port 0 lets the system choose (the node's status shows the port). There is no authentication: listen on other interfaces only in a trusted network.",
        ),
        ParamSpec::new(
            "record",
            ParamKind::Text { default: "" },
            "A folder (relative to the graph's) to record the session into: every frame received is written as frame_NNNN.obj (the simulator's frame number; pattern pieces as OBJ objects, UVs kept), the sequence MeshSequence plays, so a streamed session becomes a batch render or CI case. Empty: no recording.",
        ),
    ],
    capabilities: Capabilities::external_source(RECORD_HELP),
    create: || Box::<LiveLinkNode>::default(),
};

/// What a batch render (or `check`) tells the user of a graph whose LiveLink has no sender.
pub const RECORD_HELP: &str = "a batch render has no simulator to wait for: record a session instead (set the LiveLink's `record` parameter to a folder, e.g. in `werkstatt edit`, while the simulator streams: each frame is written as frame_NNNN.obj), then render with a MeshSequence whose `path` is that folder in place of the LiveLink";

/// The first bytes of every message.
pub const MAGIC: [u8; 4] = *b"WKLL";
/// The protocol version this build speaks.
pub const VERSION: u16 = 1;
/// Bytes of the fixed header before every payload.
pub const HEADER_BYTES: usize = 32;
/// Message type: indices, UVs and optional piece ids; first on every connection.
pub const MSG_TOPOLOGY: u16 = 1;
/// Message type: positions (and optional normals) of one frame.
pub const MSG_FRAME: u16 = 2;
/// Topology flag: a piece id (u32) per vertex follows the UVs.
pub const FLAG_PIECE_IDS: u32 = 1;
/// Frame flag: a normal (3 x f32) per vertex follows the positions.
pub const FLAG_NORMALS: u32 = 1;
/// Limits: larger counts are rejected before anything is allocated.
pub const MAX_VERTICES: u32 = 1 << 22;
pub const MAX_INDICES: u32 = 3 << 23;
/// A sender that stops in the middle of a message for this long is dropped.
pub const STALL_TIMEOUT: Duration = Duration::from_secs(5);
/// How long the listener waits in one read before it looks at its stop flag and for newer senders.
const POLL: Duration = Duration::from_millis(20);
/// Errors kept for the node's warnings.
const MAX_ERRORS: usize = 8;

/// A message header (32 bytes, little-endian).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    pub version: u16,
    pub kind: u16,
    pub flags: u32,
    pub vertex_count: u32,
    pub index_count: u32,
    pub payload_bytes: u32,
    pub frame: u64,
}

impl Header {
    pub fn encode(&self) -> [u8; HEADER_BYTES] {
        let mut b = [0u8; HEADER_BYTES];
        b[0..4].copy_from_slice(&MAGIC);
        b[4..6].copy_from_slice(&self.version.to_le_bytes());
        b[6..8].copy_from_slice(&self.kind.to_le_bytes());
        b[8..12].copy_from_slice(&self.flags.to_le_bytes());
        b[12..16].copy_from_slice(&self.vertex_count.to_le_bytes());
        b[16..20].copy_from_slice(&self.index_count.to_le_bytes());
        b[20..24].copy_from_slice(&self.payload_bytes.to_le_bytes());
        b[24..32].copy_from_slice(&self.frame.to_le_bytes());
        b
    }

    /// Parses and checks a header on its own (magic, version, type, flags, limits, payload size).
    pub fn decode(b: &[u8; HEADER_BYTES]) -> Result<Header, String> {
        if b[0..4] != MAGIC {
            return Err(format!(
                "bad magic {:02x?} (expected \"WKLL\"): not a LiveLink sender, or out of step",
                &b[0..4]
            ));
        }
        let u16_at = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
        let u32_at = |i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        let h = Header {
            version: u16_at(4),
            kind: u16_at(6),
            flags: u32_at(8),
            vertex_count: u32_at(12),
            index_count: u32_at(16),
            payload_bytes: u32_at(20),
            frame: u64::from_le_bytes(b[24..32].try_into().expect("8 bytes")),
        };
        if h.version != VERSION {
            return Err(format!("protocol version {}; this werkstatt speaks version {VERSION}", h.version));
        }
        if h.kind != MSG_TOPOLOGY && h.kind != MSG_FRAME {
            return Err(format!("unknown message type {}", h.kind));
        }
        let known = if h.kind == MSG_TOPOLOGY { FLAG_PIECE_IDS } else { FLAG_NORMALS };
        if h.flags & !known != 0 {
            return Err(format!("unknown flags {:#x} in a {} message", h.flags, h.kind_name()));
        }
        if h.vertex_count == 0 || h.vertex_count > MAX_VERTICES {
            return Err(format!("vertex count {} is outside 1..={MAX_VERTICES}", h.vertex_count));
        }
        if h.index_count == 0 || h.index_count > MAX_INDICES || !h.index_count.is_multiple_of(3) {
            return Err(format!("index count {} is not a multiple of 3 in 3..={MAX_INDICES}", h.index_count));
        }
        let expected = h.expected_payload();
        if h.payload_bytes as u64 != expected {
            return Err(format!(
                "{} message declares {} payload bytes, but its counts and flags need {expected}",
                h.kind_name(),
                h.payload_bytes
            ));
        }
        Ok(h)
    }

    fn kind_name(&self) -> &'static str {
        if self.kind == MSG_TOPOLOGY { "topology" } else { "frame" }
    }

    /// The payload size the counts and flags call for.
    pub fn expected_payload(&self) -> u64 {
        let (v, i) = (self.vertex_count as u64, self.index_count as u64);
        if self.kind == MSG_TOPOLOGY {
            i * 4 + v * 8 + if self.flags & FLAG_PIECE_IDS != 0 { v * 4 } else { 0 }
        } else {
            v * 12 * if self.flags & FLAG_NORMALS != 0 { 2 } else { 1 }
        }
    }
}

/// A topology message: triangle indices, a UV per vertex (pattern coordinates, v down as in
/// werkstatt's textures) and optionally a pattern piece id per vertex.
pub fn encode_topology(indices: &[u32], uvs: &[Vec2], piece_ids: Option<&[u32]>) -> Vec<u8> {
    let header = Header {
        version: VERSION,
        kind: MSG_TOPOLOGY,
        flags: if piece_ids.is_some() { FLAG_PIECE_IDS } else { 0 },
        vertex_count: uvs.len() as u32,
        index_count: indices.len() as u32,
        payload_bytes: 0,
        frame: 0,
    };
    let mut payload = Vec::new();
    indices.iter().for_each(|i| payload.extend_from_slice(&i.to_le_bytes()));
    uvs.iter().flat_map(|uv| uv.to_array()).for_each(|f| payload.extend_from_slice(&f.to_le_bytes()));
    piece_ids.unwrap_or_default().iter().for_each(|i| payload.extend_from_slice(&i.to_le_bytes()));
    with_header(header, payload)
}

/// A frame message: the positions of frame `frame` (and optionally normals); `index_count`
/// repeats the topology's, as a check.
pub fn encode_frame(frame: u64, index_count: u32, positions: &[Vec3], normals: Option<&[Vec3]>) -> Vec<u8> {
    let header = Header {
        version: VERSION,
        kind: MSG_FRAME,
        flags: if normals.is_some() { FLAG_NORMALS } else { 0 },
        vertex_count: positions.len() as u32,
        index_count,
        payload_bytes: 0,
        frame,
    };
    let mut payload = Vec::with_capacity(positions.len() * 24);
    for v in positions.iter().chain(normals.unwrap_or_default()) {
        v.to_array().iter().for_each(|f| payload.extend_from_slice(&f.to_le_bytes()));
    }
    with_header(header, payload)
}

fn with_header(mut header: Header, payload: Vec<u8>) -> Vec<u8> {
    header.payload_bytes = payload.len() as u32;
    let mut out = header.encode().to_vec();
    out.extend_from_slice(&payload);
    out
}

/// What the listener publishes for the node.
#[derive(Default)]
struct Latest {
    mesh: Option<Arc<Mesh>>,
    frame: u64,
    /// The address listened on, once bound.
    bound: Option<SocketAddr>,
    /// Why binding fails, while it does.
    listen_error: Option<String>,
    /// Rejected messages and dropped connections since the last good topology.
    errors: Vec<String>,
}

struct Shared {
    address: String,
    /// The folder frames are recorded into (the `record` parameter), if any.
    record: Mutex<Option<PathBuf>>,
    latest: Mutex<Latest>,
    signal: ChangeSignal,
    stop: AtomicBool,
}

impl Shared {
    fn publish(&self, f: impl FnOnce(&mut Latest)) {
        f(&mut self.latest.lock().unwrap_or_else(|e| e.into_inner()));
        self.signal.bump();
    }

    fn error(&self, message: String) {
        eprintln!("warning: LiveLink {}: {message}", self.address);
        self.publish(|l| {
            if l.errors.len() == MAX_ERRORS {
                l.errors.remove(0);
            }
            l.errors.push(message);
        });
    }

    fn stopped(&self) -> bool {
        self.stop.load(Ordering::Acquire)
    }
}

/// A running listener; dropping it stops the thread (within a poll interval).
struct Link {
    shared: Arc<Shared>,
}

impl Drop for Link {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
    }
}

#[derive(Default)]
struct LiveLinkNode {
    link: Option<Link>,
}

impl Node for LiveLinkNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let address = cx.str("address").trim().to_string();
        let record = (!cx.str("record").trim().is_empty()).then(|| cx.path("record"));
        if self.link.as_ref().is_none_or(|l| l.shared.address != address) {
            self.link = None;
            let addr = resolve(&address).map_err(NodeError::Failed)?;
            let shared = Arc::new(Shared {
                address: address.clone(),
                record: Mutex::new(record.clone()),
                latest: Mutex::new(Latest::default()),
                signal: ChangeSignal::new(),
                stop: AtomicBool::new(false),
            });
            let thread_shared = shared.clone();
            std::thread::Builder::new()
                .name(format!("werkstatt-livelink-{address}"))
                .spawn(move || listen(thread_shared, addr))
                .map_err(|e| NodeError::msg(format!("cannot start the listener thread: {e}")))?;
            self.link = Some(Link { shared });
        }
        let shared = self.link.as_ref().expect("started above").shared.clone();
        *shared.record.lock().unwrap_or_else(|e| e.into_inner()) = record;
        // Watch before reading: a frame that lands in between makes the next frame re-run.
        cx.watch(&shared.signal);
        let latest = shared.latest.lock().unwrap_or_else(|e| e.into_inner());
        for e in &latest.errors {
            cx.warn(e.clone());
        }
        let (mesh, frame) = (latest.mesh.clone(), latest.frame);
        match (mesh, &latest.listen_error) {
            (Some(mesh), listen_error) => {
                if let Some(e) = listen_error {
                    cx.warn(e.clone());
                }
                cx.set("surface", mesh);
                cx.set("frame", frame as f64);
                Ok(())
            }
            (None, Some(e)) => Err(NodeError::msg(e.clone())),
            (None, None) => {
                let at = latest.bound.map_or(address, |a| a.to_string());
                Err(NodeError::Pending(PathBuf::from(format!("a simulator on tcp://{at}"))))
            }
        }
    }
}

fn resolve(address: &str) -> Result<SocketAddr, String> {
    address
        .to_socket_addrs()
        .ok()
        .and_then(|mut a| a.next())
        .ok_or_else(|| format!("parameter \"address\": \"{address}\" is not a host:port address like 127.0.0.1:7878"))
}

/// The listener thread: binds (retrying while the port is taken), then serves one sender at
/// a time until stopped; a newer sender replaces one that has gone quiet.
fn listen(shared: Arc<Shared>, addr: SocketAddr) {
    let listener = loop {
        if shared.stopped() {
            return;
        }
        match TcpListener::bind(addr).and_then(|l| l.set_nonblocking(true).map(|_| l)) {
            Ok(l) => break l,
            Err(e) => {
                let msg = format!("cannot listen on {addr}: {e} (retrying)");
                let changed =
                    shared.latest.lock().unwrap_or_else(|e| e.into_inner()).listen_error.as_ref() != Some(&msg);
                if changed {
                    eprintln!("warning: LiveLink: {msg}");
                    shared.publish(|l| l.listen_error = Some(msg));
                }
                std::thread::sleep(Duration::from_millis(250));
            }
        }
    };
    let bound = listener.local_addr().ok();
    shared.publish(|l| {
        l.bound = bound;
        l.listen_error = None;
    });
    let mut next: Option<(TcpStream, SocketAddr)> = None;
    while !shared.stopped() {
        let incoming = next.take().map(Ok).unwrap_or_else(|| listener.accept());
        match incoming {
            Ok((stream, peer)) => {
                let mut conn = Connection { stream, peer, topology: None };
                match conn.serve(&shared, &listener) {
                    Ok(End::Closed) | Ok(End::Stopped) => {}
                    Ok(End::Replaced(s, p)) => {
                        shared.error(format!("{peer} went quiet and was replaced by a new sender from {p}"));
                        next = Some((s, p));
                    }
                    Err(e) => shared.error(format!("dropped the connection from {peer}: {e}")),
                }
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => std::thread::sleep(POLL),
            Err(e) => {
                shared.error(format!("accept failed: {e}"));
                std::thread::sleep(Duration::from_millis(250));
            }
        }
    }
}

/// The triangles, UVs and pieces every frame of a connection shares.
struct Topology {
    indices: Vec<u32>,
    uvs: Vec<Vec2>,
    piece_ids: Vec<u32>,
}

enum End {
    /// The sender closed the connection between messages.
    Closed,
    Stopped,
    /// A new sender connected while this one was quiet.
    Replaced(TcpStream, SocketAddr),
}

enum Fill {
    Done,
    End(End),
}

struct Connection {
    stream: TcpStream,
    peer: SocketAddr,
    topology: Option<Topology>,
}

impl Connection {
    fn serve(&mut self, shared: &Shared, listener: &TcpListener) -> Result<End, String> {
        let setup = |s: &TcpStream| -> std::io::Result<()> {
            s.set_nonblocking(false)?;
            s.set_read_timeout(Some(POLL))?;
            s.set_nodelay(true)
        };
        setup(&self.stream).map_err(|e| format!("cannot set up the socket: {e}"))?;
        let mut head = Vec::with_capacity(HEADER_BYTES);
        let mut payload = Vec::new();
        loop {
            head.clear();
            if let Fill::End(end) = self.fill(&mut head, HEADER_BYTES, true, shared, listener)? {
                return Ok(end);
            }
            let header = Header::decode(head.as_slice().try_into().expect("32 bytes"))?;
            payload.clear();
            if let Fill::End(end) = self.fill(&mut payload, header.payload_bytes as usize, false, shared, listener)? {
                return Ok(end);
            }
            self.handle(header, &payload, shared)?;
        }
    }

    /// Reads until `out` holds `want` bytes. `boundary`: nothing of this message has arrived
    /// yet, so a close is a clean end and waiting is not a stall.
    fn fill(
        &mut self,
        out: &mut Vec<u8>,
        want: usize,
        boundary: bool,
        shared: &Shared,
        listener: &TcpListener,
    ) -> Result<Fill, String> {
        let mut chunk = [0u8; 64 * 1024];
        let mut progress = Instant::now();
        while out.len() < want {
            if shared.stopped() {
                return Ok(Fill::End(End::Stopped));
            }
            let n = (want - out.len()).min(chunk.len());
            match self.stream.read(&mut chunk[..n]) {
                Ok(0) if boundary && out.is_empty() => return Ok(Fill::End(End::Closed)),
                Ok(0) => {
                    return Err(format!(
                        "truncated message: the connection closed after {} of {want} {} bytes",
                        out.len(),
                        if boundary { "header" } else { "payload" }
                    ));
                }
                Ok(n) => {
                    out.extend_from_slice(&chunk[..n]);
                    progress = Instant::now();
                }
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted) => {
                    let idle = boundary && out.is_empty();
                    if !idle && progress.elapsed() > STALL_TIMEOUT {
                        return Err(format!(
                            "the sender stalled for {} s in the middle of a message",
                            STALL_TIMEOUT.as_secs()
                        ));
                    }
                    if let Ok((s, p)) = listener.accept() {
                        return Ok(Fill::End(End::Replaced(s, p)));
                    }
                }
                Err(e) => return Err(format!("read failed: {e}")),
            }
        }
        Ok(Fill::Done)
    }

    fn handle(&mut self, h: Header, payload: &[u8], shared: &Shared) -> Result<(), String> {
        let words = |bytes: &[u8]| -> Vec<u32> {
            bytes.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
        };
        let floats = |bytes: &[u8]| -> Vec<f32> {
            bytes.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
        };
        let (v, i) = (h.vertex_count as usize, h.index_count as usize);
        if h.kind == MSG_TOPOLOGY {
            let indices = words(&payload[..i * 4]);
            if let Some(bad) = indices.iter().find(|&&x| x as usize >= v) {
                return Err(format!("topology index {bad} is out of range ({v} vertices)"));
            }
            let uvs: Vec<Vec2> = floats(&payload[i * 4..i * 4 + v * 8]).chunks_exact(2).map(Vec2::from_slice).collect();
            if let Some(k) = uvs.iter().position(|uv| !uv.is_finite()) {
                return Err(format!("topology UV {k} is not finite"));
            }
            let piece_ids = if h.flags & FLAG_PIECE_IDS != 0 { words(&payload[i * 4 + v * 8..]) } else { Vec::new() };
            self.topology = Some(Topology { indices, uvs, piece_ids });
            // A healthy connection: earlier errors are history.
            shared.publish(|l| l.errors.clear());
            return Ok(());
        }
        let Some(t) = &self.topology else {
            return Err(format!("frame {} arrived before the topology message", h.frame));
        };
        if v != t.uvs.len() || i != t.indices.len() {
            return Err(format!(
                "frame {} has {v} vertices and {i} indices, but the topology has {} and {}",
                h.frame,
                t.uvs.len(),
                t.indices.len()
            ));
        }
        let vectors = floats(payload).chunks_exact(3).map(Vec3::from_slice).collect::<Vec<_>>();
        let (positions, normals) = if h.flags & FLAG_NORMALS != 0 {
            let (p, n) = vectors.split_at(v);
            (p.to_vec(), Some(n.to_vec()))
        } else {
            (vectors, None)
        };
        // The framing is intact, so a bad frame is skipped and the connection kept.
        match Mesh::from_parts(positions, normals, t.uvs.clone(), t.indices.clone(), t.piece_ids.clone()) {
            Ok(mesh) => {
                let record = shared.record.lock().unwrap_or_else(|e| e.into_inner()).clone();
                if let Some(dir) = record
                    && let Err(e) = record_frame(&dir, h.frame, &mesh)
                {
                    shared.error(format!("cannot record frame {}: {e:#}", h.frame));
                }
                shared.publish(|l| {
                    l.mesh = Some(Arc::new(mesh));
                    l.frame = h.frame;
                })
            }
            Err(e) => shared.error(format!("skipped frame {} from {}: {e:#}", h.frame, self.peer)),
        }
        Ok(())
    }
}

/// Writes one received frame as `<dir>/frame_NNNN.obj` (atomically), for MeshSequence.
fn record_frame(dir: &std::path::Path, frame: u64, mesh: &Mesh) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| anyhow::anyhow!("cannot create {}: {e}", dir.display()))?;
    crate::io::geometry::write_obj(&dir.join(format!("frame_{frame:04}.obj")), mesh, &[])
}
