//! A stand-in simulator for the LiveLink node: streams a waving flag (a grid of quads with
//! UVs) to a running werkstatt over TCP, using the protocol of docs/livelink.md.
//!
//! ```sh
//! cargo run --example livelink_send -- [ADDRESS] [--size N] [--fps F] [--frames N]
//! ```
//!
//! ADDRESS defaults to 127.0.0.1:7878 (LiveLink's default). The sender reconnects when the
//! connection drops (sending the topology again) and keeps counting frames; `--frames N`
//! stops after N frames, otherwise it runs until interrupted.

use std::io::Write;
use std::net::TcpStream;
use std::time::{Duration, Instant};

use glam::{Vec2, Vec3};
use werkstatt::nodes::mesh::live_link::{encode_frame, encode_topology};

struct Options {
    address: String,
    size: usize,
    fps: f64,
    frames: Option<u64>,
}

fn parse_args() -> Result<Options, String> {
    let mut o = Options { address: "127.0.0.1:7878".into(), size: 32, fps: 30.0, frames: None };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |name: &str| args.next().ok_or(format!("{name} needs a value"));
        match a.as_str() {
            "--size" => o.size = value("--size")?.parse().map_err(|_| "--size: expected a number of quads")?,
            "--fps" => o.fps = value("--fps")?.parse().map_err(|_| "--fps: expected a number")?,
            "--frames" => o.frames = Some(value("--frames")?.parse().map_err(|_| "--frames: expected a count")?),
            "-h" | "--help" => {
                return Err("usage: livelink_send [ADDRESS] [--size N] [--fps F] [--frames N]".into());
            }
            _ if !a.starts_with('-') => o.address = a,
            _ => return Err(format!("unknown option {a}")),
        }
    }
    if !((2..=2048).contains(&o.size) && o.fps > 0.0 && o.fps <= 1000.0) {
        return Err("--size must be in 2..=2048 and --fps in (0, 1000]".into());
    }
    Ok(o)
}

/// The flag: (size+1)^2 vertices in [0,1]^2 UV space, two triangles per quad.
fn topology(size: usize) -> (Vec<u32>, Vec<Vec2>) {
    let n = size + 1;
    let uvs = (0..n * n).map(|k| Vec2::new((k % n) as f32, (k / n) as f32) / size as f32).collect();
    let mut indices = Vec::with_capacity(size * size * 6);
    for j in 0..size {
        for i in 0..size {
            let a = (j * n + i) as u32;
            let (b, c, d) = (a + 1, a + n as u32, a + n as u32 + 1);
            indices.extend_from_slice(&[a, c, b, b, c, d]);
        }
    }
    (indices, uvs)
}

/// A 1.6 x 1 flag on a pole at u = 0, facing +Z, waving more towards its free edge.
fn positions(uvs: &[Vec2], t: f32) -> Vec<Vec3> {
    uvs.iter()
        .map(|uv| {
            let phase = std::f32::consts::TAU * (1.2 * uv.x - 0.8 * t) + 0.7 * uv.y;
            let z = 0.18 * uv.x * phase.sin();
            Vec3::new(1.6 * uv.x - 0.8 - 0.05 * uv.x * (1.0 - phase.cos()), 0.5 - uv.y, z)
        })
        .collect()
}

fn main() {
    let o = match parse_args() {
        Ok(o) => o,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let (indices, uvs) = topology(o.size);
    let topology_message = encode_topology(&indices, &uvs, None);
    let period = Duration::from_secs_f64(1.0 / o.fps);
    let mut frame: u64 = 0;
    let start = Instant::now();
    'connect: loop {
        let mut stream = match TcpStream::connect(&o.address) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("cannot connect to {} ({e}); retrying", o.address);
                std::thread::sleep(Duration::from_millis(500));
                continue;
            }
        };
        let _ = stream.set_nodelay(true);
        if let Err(e) = stream.write_all(&topology_message) {
            eprintln!("connection lost ({e}); reconnecting");
            std::thread::sleep(Duration::from_millis(500));
            continue;
        }
        eprintln!("streaming a {0}x{0} flag to {1} at {2} fps", o.size, o.address, o.fps);
        loop {
            if o.frames.is_some_and(|n| frame >= n) {
                break 'connect;
            }
            let t = frame as f32 / o.fps as f32;
            let message = encode_frame(frame, indices.len() as u32, &positions(&uvs, t), None);
            if let Err(e) = stream.write_all(&message) {
                eprintln!("connection lost ({e}); reconnecting");
                std::thread::sleep(Duration::from_millis(500));
                continue 'connect;
            }
            frame += 1;
            // Pace by the wall clock, so a slow frame does not slow the animation down.
            let due = start + period.mul_f64(frame as f64);
            std::thread::sleep(due.saturating_duration_since(Instant::now()));
        }
    }
    eprintln!("sent {frame} frames");
}
