//! LiveLink: a sender on loopback streams frames into a running evaluator. Every loop here is
//! bounded by a deadline, so a broken listener fails the test instead of hanging it.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};

use glam::{Vec2, Vec3};
use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime, NodeStatus};
use werkstatt::core::graph::Graph;
use werkstatt::core::port::Value;
use werkstatt::core::resources::Resources;
use werkstatt::mesh::Mesh;
use werkstatt::nodes::mesh::live_link::{
    HEADER_BYTES, Header, MAX_VERTICES, MSG_FRAME, MSG_TOPOLOGY, VERSION, encode_frame, encode_topology,
};

const WAIT: Duration = Duration::from_secs(10);

/// An evaluator with a LiveLink on an OS-chosen loopback port, its frame number watched.
struct Rig {
    ev: Evaluator,
    res: Resources,
    frame: i64,
    addr: SocketAddr,
}

impl Rig {
    fn start() -> Rig {
        Rig::with_graph(
            r#"(version: 1, nodes: {
            "link": (kind: "LiveLink", params: {"address": "127.0.0.1:0"}),
            "watch": (kind: "Watch"),
        }, links: [("link.frame", "watch.value")])"#,
        )
    }

    /// A rig on a graph whose LiveLink "link" listens on 127.0.0.1:0.
    fn with_graph(text: &str) -> Rig {
        let g = Graph::load_str(text, "test.ron".as_ref()).unwrap_or_else(|e| panic!("{e}"));
        let mut rig = Rig {
            ev: Evaluator::new(&g, &["link".to_string()]).unwrap(),
            res: Resources::new(false),
            frame: 0,
            addr: "127.0.0.1:0".parse().unwrap(),
        };
        // The status names the bound address once the listener runs.
        rig.wait_until("the listener to bind", |r| match r.status() {
            NodeStatus::Pending(p) => {
                let text = p.display().to_string();
                let addr = text.rsplit("tcp://").next().unwrap().parse::<SocketAddr>().unwrap();
                r.addr = addr;
                addr.port() != 0
            }
            _ => false,
        });
        rig
    }

    /// One frame of the interactive loop.
    fn tick(&mut self) {
        self.frame += 1;
        self.ev.evaluate(FrameTime { frame: self.frame, fps: 60.0 }, None, &self.res, &FrameSettings::default());
    }

    fn wait_until(&mut self, what: &str, mut done: impl FnMut(&mut Rig) -> bool) {
        let deadline = Instant::now() + WAIT;
        loop {
            self.tick();
            if done(self) {
                return;
            }
            assert!(Instant::now() < deadline, "timed out waiting for {what}; status {:?}", self.status());
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    fn status(&self) -> NodeStatus {
        self.ev.report("link").unwrap().status.clone()
    }

    fn warnings(&self) -> Vec<String> {
        self.ev.report("link").unwrap().warnings.to_vec()
    }

    fn runs(&self, id: &str) -> u64 {
        self.ev.report(id).unwrap().runs
    }

    /// The frame number shown, if any.
    fn shown(&self) -> Option<u64> {
        match self.ev.output("link", "frame") {
            Some(Value::Scalar(f)) => Some(*f as u64),
            _ => None,
        }
    }

    fn surface(&self) -> Arc<Mesh> {
        match self.ev.output("link", "surface") {
            Some(Value::Surface(m)) => m.clone(),
            _ => panic!("no surface; status {:?}", self.status()),
        }
    }

    fn wait_for_frame(&mut self, frame: u64) {
        self.wait_until(&format!("frame {frame}"), |r| r.shown() == Some(frame));
    }

    fn wait_for_warning(&mut self, needle: &str) {
        self.wait_until(&format!("a warning containing \"{needle}\""), |r| {
            r.warnings().last().is_some_and(|w| w.contains(needle))
        });
    }

    fn connect(&self) -> TcpStream {
        let s = TcpStream::connect_timeout(&self.addr, WAIT).unwrap();
        // A listener that stops reading fails the write instead of hanging the test.
        s.set_read_timeout(Some(WAIT)).unwrap();
        s.set_write_timeout(Some(WAIT)).unwrap();
        s
    }
}

/// An n x n grid of the simulator's cloth: its topology (left half piece 0, right half 1).
struct Cloth {
    indices: Vec<u32>,
    uvs: Vec<Vec2>,
    pieces: Vec<u32>,
}

impl Cloth {
    fn new(n: usize) -> Cloth {
        let mut c = Cloth { indices: Vec::new(), uvs: Vec::new(), pieces: Vec::new() };
        for j in 0..n {
            for i in 0..n {
                c.uvs.push(Vec2::new(i as f32, j as f32) / (n - 1) as f32);
                c.pieces.push(u32::from(i >= n / 2));
            }
        }
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let a = (j * n + i) as u32;
                let (b, c2, d) = (a + 1, a + n as u32, a + n as u32 + 1);
                c.indices.extend_from_slice(&[a, c2, b, b, c2, d]);
            }
        }
        c
    }

    fn topology(&self) -> Vec<u8> {
        encode_topology(&self.indices, &self.uvs, Some(&self.pieces))
    }

    /// Frame `f`: the grid at height f, waving a little.
    fn positions(&self, f: u64) -> Vec<Vec3> {
        self.uvs.iter().map(|uv| Vec3::new(uv.x, f as f32 + 0.1 * (uv.x * 6.0 + f as f32).sin(), uv.y)).collect()
    }

    fn frame(&self, f: u64) -> Vec<u8> {
        encode_frame(f, self.indices.len() as u32, &self.positions(f), None)
    }
}

/// Waits until the peer closes the connection (EOF or reset), failing after the deadline.
fn assert_dropped(mut s: TcpStream) {
    let mut buf = [0u8; 64];
    match s.read(&mut buf) {
        Ok(0) => {}
        Err(e) if e.kind() != std::io::ErrorKind::WouldBlock && e.kind() != std::io::ErrorKind::TimedOut => {}
        other => panic!("the node did not drop the connection: {other:?}"),
    }
}

fn header(kind: u16, flags: u32, vertices: u32, indices: u32, payload: u32, frame: u64) -> [u8; HEADER_BYTES] {
    Header {
        version: VERSION,
        kind,
        flags,
        vertex_count: vertices,
        index_count: indices,
        payload_bytes: payload,
        frame,
    }
    .encode()
}

#[test]
fn frames_arrive_and_only_new_frames_rerun_the_node() {
    let mut rig = Rig::start();
    let cloth = Cloth::new(5);
    let mut s = rig.connect();
    s.write_all(&cloth.topology()).unwrap();
    for f in 1..=5 {
        s.write_all(&cloth.frame(f)).unwrap();
    }
    rig.wait_for_frame(5);
    assert_eq!(rig.status(), NodeStatus::Ok);
    let m = rig.surface();
    assert_eq!(m.positions, cloth.positions(5));
    assert_eq!((&m.uvs, &m.indices, &m.piece_ids), (&cloth.uvs, &cloth.indices, &cloth.pieces));
    assert!(m.normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-4 && n.y > 0.5));
    assert!(rig.warnings().is_empty(), "{:?}", rig.warnings());

    // No new frame: neither the node nor what it feeds re-runs, although the time moves on.
    let (link, watch) = (rig.runs("link"), rig.runs("watch"));
    for _ in 0..30 {
        rig.tick();
    }
    assert_eq!((rig.runs("link"), rig.runs("watch")), (link, watch), "re-ran without a new frame");

    // Frames with normals from the sender are used as sent (normalized).
    let normals = vec![Vec3::new(0.0, 0.0, 2.0); cloth.uvs.len()];
    s.write_all(&encode_frame(6, cloth.indices.len() as u32, &cloth.positions(6), Some(&normals))).unwrap();
    rig.wait_for_frame(6);
    assert!(rig.runs("link") > link && rig.runs("watch") > watch);
    assert!(rig.surface().normals.iter().all(|n| *n == Vec3::Z));
}

#[test]
fn malformed_messages_are_rejected_and_the_last_good_frame_stays() {
    let mut rig = Rig::start();
    let cloth = Cloth::new(4);
    let (v, i) = (cloth.uvs.len() as u32, cloth.indices.len() as u32);
    let mut good = rig.connect();
    good.write_all(&cloth.topology()).unwrap();
    good.write_all(&cloth.frame(7)).unwrap();
    rig.wait_for_frame(7);
    let shown = rig.surface();

    // A frame with a NaN keeps the connection (its framing is fine) but is skipped.
    let mut nan = cloth.positions(8);
    nan[3].x = f32::NAN;
    good.write_all(&encode_frame(8, i, &nan, None)).unwrap();
    rig.wait_for_warning("skipped frame 8");
    assert!(Arc::ptr_eq(&rig.surface(), &shown));
    drop(good);

    let truncated = {
        let mut m = cloth.frame(9);
        m.truncate(HEADER_BYTES + 20);
        m
    };
    let mut too_many = cloth.frame(9);
    too_many[12..16].copy_from_slice(&(v + 1).to_le_bytes());
    too_many[20..24].copy_from_slice(&((v + 1) * 12).to_le_bytes());
    too_many.extend_from_slice(&[0u8; 12]);
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("bad magic", [b"XXXX".as_slice(), &cloth.frame(9)[4..]].concat(), "bad magic"),
        ("oversized vertex count", header(MSG_FRAME, 0, u32::MAX, i, 0, 9).to_vec(), "vertex count 4294967295"),
        ("oversized topology", header(MSG_TOPOLOGY, 0, MAX_VERTICES + 1, 3, 0, 0).to_vec(), "vertex count 4194305"),
        ("payload size disagreeing with the counts", header(MSG_FRAME, 0, v, i, 5, 9).to_vec(), "declares 5 payload"),
        ("unknown flags", header(MSG_FRAME, 8, v, i, v * 12, 9).to_vec(), "unknown flags"),
        ("other protocol version", [&cloth.frame(9)[..4], &[9, 0], &cloth.frame(9)[6..]].concat(), "version 9"),
        ("truncated frame", [cloth.topology(), truncated].concat(), "truncated message"),
        ("counts disagreeing with the topology", [cloth.topology(), too_many].concat(), "has 17 vertices"),
        ("frame before the topology", cloth.frame(9), "before the topology"),
        ("index out of range", encode_topology(&[0, 1, 99], &cloth.uvs, None), "index 99 is out of range"),
    ];
    for (what, bytes, needle) in cases {
        let mut s = rig.connect();
        s.write_all(&bytes).unwrap();
        if what == "truncated frame" {
            s.shutdown(std::net::Shutdown::Write).unwrap();
        }
        rig.wait_for_warning(needle);
        assert_eq!(rig.status(), NodeStatus::Ok, "{what}");
        assert!(Arc::ptr_eq(&rig.surface(), &shown), "{what}: the last good frame must stay");
        assert_eq!(rig.shown(), Some(7));
        assert_dropped(s);
    }
    // The warnings stay until a healthy sender comes; that one streams on.
    let mut s = rig.connect();
    s.write_all(&cloth.topology()).unwrap();
    s.write_all(&encode_frame(10, i, &cloth.positions(10), Some(&vec![Vec3::Y; v as usize]))).unwrap();
    rig.wait_for_frame(10);
    assert!(rig.warnings().is_empty(), "{:?}", rig.warnings());
}

#[test]
fn streaming_continues_after_disconnect_and_reconnect() {
    let mut rig = Rig::start();
    let cloth = Cloth::new(3);
    let mut first = rig.connect();
    first.write_all(&cloth.topology()).unwrap();
    for f in 1..=3 {
        first.write_all(&cloth.frame(f)).unwrap();
    }
    rig.wait_for_frame(3);
    drop(first);
    // Disconnected: the last frame stays, without an error. The listener serves one sender
    // at a time, so once a probe's message is answered the close has been handled: a probe
    // that sends a frame without a topology gets exactly one warning, its own.
    let mut probe = rig.connect();
    probe.write_all(&cloth.frame(4)).unwrap();
    rig.wait_for_warning("frame 4 arrived before the topology");
    assert_eq!((rig.status(), rig.shown()), (NodeStatus::Ok, Some(3)));
    assert_eq!(rig.warnings().len(), 1, "a clean disconnect must not warn: {:?}", rig.warnings());
    assert_dropped(probe);

    // A restarted simulator (a new topology: another cloth size) streams on.
    let bigger = Cloth::new(6);
    let mut second = rig.connect();
    second.write_all(&bigger.topology()).unwrap();
    second.write_all(&bigger.frame(10)).unwrap();
    rig.wait_for_frame(10);
    assert_eq!(rig.surface().positions.len(), 36);

    // A new sender replaces one that went quiet without closing (a crashed simulator).
    let mut third = rig.connect();
    third.write_all(&cloth.topology()).unwrap();
    third.write_all(&cloth.frame(20)).unwrap();
    rig.wait_for_frame(20);
    assert_eq!(rig.surface().positions.len(), 9);
    assert!(rig.warnings().iter().all(|w| !w.contains("dropped")), "{:?}", rig.warnings());
    assert_dropped(second);
    third.write_all(&cloth.frame(21)).unwrap();
    rig.wait_for_frame(21);
}

#[test]
fn the_render_loop_never_blocks_on_a_stalled_sender() {
    let mut rig = Rig::start();
    // A large frame, sent in part: the listener sits in the middle of the message.
    let cloth = Cloth::new(200);
    let mut s = rig.connect();
    s.write_all(&cloth.topology()).unwrap();
    s.write_all(&cloth.frame(1)).unwrap();
    rig.wait_for_frame(1);
    let next = cloth.frame(2);
    let half = next.len() / 2;
    s.write_all(&next[..half]).unwrap();
    // The rest of the frame is sent only after the render loop has run frames of its own: a
    // loop that waited for the sender would never get there. So that such a loop fails
    // instead of hanging, a helper sends the rest after a deadline and reports that it had to.
    let (go, gone) = mpsc::channel::<()>();
    let mut writer = s.try_clone().unwrap();
    let rest = next[half..].to_vec();
    let helper = std::thread::spawn(move || {
        let forced = gone.recv_timeout(WAIT).is_err();
        writer.write_all(&rest).unwrap();
        forced
    });
    let runs = (rig.runs("link"), rig.runs("watch"));
    for _ in 0..20 {
        rig.tick();
        assert_eq!(rig.shown(), Some(1), "a partial frame must not be shown");
        std::thread::sleep(Duration::from_millis(2));
    }
    assert_eq!((rig.runs("link"), rig.runs("watch")), runs, "a partial frame must not re-run the node");
    go.send(()).unwrap();
    assert!(!helper.join().unwrap(), "the render loop waited for the stalled sender");
    // The stall ends before the stall timeout: the frame completes and shows.
    rig.wait_for_frame(2);
    assert_eq!(rig.surface().positions, cloth.positions(2));
    assert!(rig.warnings().is_empty(), "{:?}", rig.warnings());
}

#[test]
fn dropping_the_node_or_changing_its_address_stops_the_listener() {
    let refused_soon = |addr: SocketAddr| {
        let deadline = Instant::now() + WAIT;
        while TcpStream::connect_timeout(&addr, Duration::from_millis(200)).is_ok() {
            assert!(Instant::now() < deadline, "{addr} still accepts connections");
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    let rig = Rig::start();
    let addr = rig.addr;
    drop(rig);
    refused_soon(addr);

    // An address change closes the old port and opens the new one.
    let mut rig = Rig::start();
    let old = rig.addr;
    let mut g = Graph::load_str(
        r#"(version: 1, nodes: {"link": (kind: "LiveLink", params: {"address": "127.0.0.1:0"}), "watch": (kind: "Watch")}, links: [("link.frame", "watch.value")])"#,
        "test.ron".as_ref(),
    )
    .unwrap();
    // A port the OS just handed out and took back: free, and not the old one.
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    g.set_from_cli(&format!("link.address=127.0.0.1:{port}")).unwrap();
    rig.ev.update(&g, &["link".to_string()]).unwrap();
    rig.tick();
    refused_soon(old);
    let new: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    rig.wait_until("the new listener", |r| match r.status() {
        NodeStatus::Pending(p) => p.display().to_string().ends_with(&format!("tcp://{new}")),
        _ => false,
    });
    rig.addr = new;
    let cloth = Cloth::new(3);
    let mut s = rig.connect();
    s.write_all(&cloth.topology()).unwrap();
    s.write_all(&cloth.frame(5)).unwrap();
    rig.wait_for_frame(5);
    // A bad address is an error on the node.
    g.set_from_cli("link.address=nowhere").unwrap();
    rig.ev.update(&g, &["link".to_string()]).unwrap();
    rig.tick();
    assert!(matches!(rig.status(), NodeStatus::Failed(m) if m.contains("not a host:port")), "{:?}", rig.status());
}

/// Two pattern pieces as separate 3 x 3 grids, vertices and triangles piece by piece: what a
/// simulator streams and what a recording must keep.
fn two_pieces() -> (Vec<u32>, Vec<Vec2>, Vec<u32>) {
    let (mut indices, mut uvs, mut pieces) = (Vec::new(), Vec::new(), Vec::new());
    for piece in 0..2u32 {
        let base = uvs.len() as u32;
        for j in 0..3 {
            for i in 0..3 {
                uvs.push(Vec2::new(0.05 + 0.5 * piece as f32 + 0.2 * i as f32, 0.1 + 0.4 * j as f32));
                pieces.push(piece);
            }
        }
        for j in 0..2 {
            for i in 0..2 {
                let a = base + j * 3 + i;
                indices.extend_from_slice(&[a, a + 3, a + 1, a + 1, a + 3, a + 4]);
            }
        }
    }
    (indices, uvs, pieces)
}

/// A session streamed into a LiveLink with `record` set replays through MeshSequence: the
/// same positions, UVs, triangles and pattern pieces.
#[test]
fn a_recorded_session_replays_through_mesh_sequence() {
    let dir = crate::common::out_dir("livelink-record");
    let record = dir.join("session");
    let text = format!(
        r#"(version: 1, nodes: {{"link": (kind: "LiveLink", params: {{"address": "127.0.0.1:0", "record": {:?}}})}}, links: [])"#,
        record.display().to_string()
    );
    let mut rig = Rig::with_graph(&text);
    let (indices, uvs, pieces) = two_pieces();
    let positions = |f: u64| -> Vec<Vec3> {
        uvs.iter().map(|uv| Vec3::new(uv.x, 0.3 * f as f32 + (uv.x * 5.0 + f as f32).sin() * 0.1, uv.y)).collect()
    };
    let mut s = rig.connect();
    s.write_all(&encode_topology(&indices, &uvs, Some(&pieces))).unwrap();
    for f in 1..=3 {
        s.write_all(&encode_frame(f, indices.len() as u32, &positions(f), None)).unwrap();
    }
    rig.wait_for_frame(3);
    let live = rig.surface();
    assert!(rig.warnings().is_empty(), "{:?}", rig.warnings());
    let files: Vec<String> = {
        let mut f: Vec<String> = std::fs::read_dir(&record)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        f.sort();
        f
    };
    assert_eq!(files, ["frame_0001.obj", "frame_0002.obj", "frame_0003.obj"]);

    // Replay frame 2 (hold) and frame 3 through MeshSequence.
    for (frame, start) in [(2u64, 2), (3, 3)] {
        let text = format!(
            r#"(version: 1, nodes: {{"seq": (kind: "MeshSequence", params: {{"path": {:?}, "mode": "hold", "start_frame": {start}}})}}, links: [])"#,
            record.display().to_string()
        );
        let g = Graph::load_str(&text, "test.ron".as_ref()).unwrap_or_else(|e| panic!("{e}"));
        let mut ev = Evaluator::new(&g, &["seq".to_string()]).unwrap();
        let res = Resources::new(false);
        let deadline = Instant::now() + WAIT;
        let replay = loop {
            ev.evaluate(FrameTime { frame: 0, fps: 30.0 }, None, &res, &FrameSettings::default());
            if let Some(Value::Surface(m)) = ev.output("seq", "surface") {
                break m.clone();
            }
            assert!(Instant::now() < deadline, "MeshSequence did not load: {:?}", ev.report("seq").unwrap().status);
            crate::common::wait_idle(&res);
        };
        // The same triangles corner by corner (MeshSequence numbers vertices in order of first
        // use, which need not be the sender's numbering).
        let corners = |m: &Mesh| -> Vec<(Vec3, Vec2, u32)> {
            m.indices.iter().map(|&i| (m.positions[i as usize], m.uvs[i as usize], m.piece_ids[i as usize])).collect()
        };
        let sent = Mesh::from_parts(positions(frame), None, uvs.clone(), indices.clone(), pieces.clone()).unwrap();
        let (got, want) = (corners(&replay), corners(&sent));
        assert_eq!(got.len(), want.len(), "frame {frame}: triangle count");
        for (k, (a, b)) in got.iter().zip(&want).enumerate() {
            assert_eq!((a.0, a.2), (b.0, b.2), "frame {frame}, corner {k}: position and piece");
            assert!((a.1 - b.1).abs().max_element() < 1e-6, "frame {frame}, corner {k}: UV {} against {}", a.1, b.1);
        }
        if frame == 3 {
            assert_eq!(
                got.iter().map(|c| c.0).collect::<Vec<_>>(),
                corners(&live).iter().map(|c| c.0).collect::<Vec<_>>()
            );
        }
    }
}

/// A batch render of a graph whose LiveLink has no sender stops at once and says which node
/// waits where, and how to record a session instead.
#[test]
fn a_batch_render_without_a_sender_names_the_node_and_how_to_record() {
    let out = crate::common::out_dir("livelink-no-sender");
    let err = crate::common::render_graph(
        &crate::common::root().join("graphs/livelink.ron"),
        &out,
        (0, 0),
        (32, 24),
        &["simulator.address=127.0.0.1:0"],
        &[],
    )
    .unwrap_err();
    let msg = format!("{err:#}");
    assert!(
        msg.contains("node \"simulator\" (LiveLink) is still waiting for a simulator on tcp://127.0.0.1:"),
        "{msg}"
    );
    // Not the 120 s limit of a frame that waits for loads: nothing will ever arrive.
    assert!(msg.contains("nothing will arrive in a batch render"), "{msg}");
    assert!(msg.contains("record") && msg.contains("MeshSequence"), "{msg}");
}
