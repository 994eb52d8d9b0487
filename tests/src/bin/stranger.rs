//! `stranger`: a host without the mission's credentials, for the link tests
//! (`tests/tests/it/hosts.rs`), run in a network namespace of its own.
//!
//! ```text
//! stranger silent ADDR N          hold N TCP connections to ADDR open, saying nothing;
//!                                 one the other side closes is opened again
//! stranger garbage ADDR SECONDS   for SECONDS, connect again and again and send random
//!                                 frames (Zenoh's TCP framing: a 2-byte length, then bytes)
//! ```
//!
//! `silent` prints `holding N` once N connections are open and runs until killed;
//! `garbage` prints `sent F frames in C connections` at the end.

use rand::{RngExt, SeedableRng};
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

fn connect(addr: &SocketAddr) -> Option<TcpStream> {
    let stream = TcpStream::connect_timeout(addr, Duration::from_secs(1)).ok()?;
    stream.set_nonblocking(true).ok()?;
    Some(stream)
}

/// Whether the other side closed `stream` (or it failed).
fn closed(stream: &mut TcpStream) -> bool {
    let mut buf = [0u8; 256];
    match stream.read(&mut buf) {
        Ok(0) => true,
        Ok(_) => false,
        Err(e) => e.kind() != std::io::ErrorKind::WouldBlock,
    }
}

fn silent(addr: SocketAddr, n: usize) {
    let mut held: Vec<Option<TcpStream>> = (0..n).map(|_| None).collect();
    let mut announced = false;
    loop {
        for slot in &mut held {
            if slot.as_mut().is_none_or(closed) {
                *slot = connect(&addr);
            }
        }
        let open = held.iter().filter(|s| s.is_some()).count();
        if open == n && !announced {
            println!("holding {n}");
            let _ = std::io::stdout().flush();
            announced = true;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn garbage(addr: SocketAddr, seconds: f64) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(u64::from(std::process::id()));
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let (mut frames, mut connections) = (0u64, 0u64);
    while Instant::now() < end {
        let Ok(mut stream) = TcpStream::connect_timeout(&addr, Duration::from_secs(1)) else {
            std::thread::sleep(Duration::from_millis(10));
            continue;
        };
        connections += 1;
        let _ = stream.set_read_timeout(Some(Duration::from_millis(100)));
        for _ in 0..4 {
            let len: usize = rng.random_range(8..256);
            let mut frame = (len as u16).to_le_bytes().to_vec();
            frame.extend((0..len).map(|_| rng.random::<u8>()));
            if stream.write_all(&frame).is_err() {
                break;
            }
            frames += 1;
        }
        // Until the other side gives up on it.
        let mut buf = [0u8; 1024];
        while Instant::now() < end && matches!(stream.read(&mut buf), Ok(n) if n > 0) {}
    }
    println!("sent {frames} frames in {connections} connections");
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = || -> ! {
        eprintln!("usage: stranger silent ADDR N | stranger garbage ADDR SECONDS");
        std::process::exit(2)
    };
    let [mode, addr, amount] = args.as_slice() else { usage() };
    let Ok(addr) = addr.parse::<SocketAddr>() else { usage() };
    match mode.as_str() {
        "silent" => silent(addr, amount.parse().unwrap_or_else(|_| usage())),
        "garbage" => garbage(addr, amount.parse().unwrap_or_else(|_| usage())),
        _ => usage(),
    }
}
