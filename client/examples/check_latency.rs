//! Measures the round trip of check-mode rendezvous requests: the daemon validates
//! the request (map, version, belief, parameters) and answers without searching,
//! so this is the IPC floor a real query pays on top of its search.
//!
//! ```sh
//! cargo run --release -p dyfos-client --example check_latency -- [PREFIX [DOMAIN [COUNT [SPIN_US [GAP_US]]]]]
//! ```
//!
//! `SPIN_US` is the client's busy-poll window before it sleeps on the reply event
//! (default 200); `GAP_US` a pause between requests (default 0, back to back).
//! Prints one JSON line: percentiles of the round trip in µs.

use dyfos_client::prelude::*;
use std::time::{Duration, Instant};

mod common;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize| args.get(i).filter(|a| !a.is_empty());
    let count: usize = arg(2).map_or(Ok(2000), |a| a.parse())?;
    let poll_us: u64 = arg(3).map_or(Ok(200), |a| a.parse())?;
    let gap_us: u64 = arg(4).map_or(Ok(0), |a| a.parse())?;
    let config =
        ClientConfig { poll: Duration::from_micros(poll_us), ..common::config(arg(0).cloned(), arg(1).cloned()) };
    let mut client = Client::connect(&config)?;
    let timeout = Duration::from_secs(5);
    let map: MapId = 0xC0FFEE;
    common::create_map(&mut client, map, timeout)?;
    let belief = Belief::new([0.0, 0.0, 0.3], [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]])?;
    let request = RendezvousRequest::new(map, belief);
    for _ in 0..100 {
        client.check(&request, timeout)?; // warm up
    }
    let mut micros = Vec::with_capacity(count);
    for _ in 0..count {
        if gap_us > 0 {
            std::thread::sleep(Duration::from_micros(gap_us));
        }
        let start = Instant::now();
        client.check(&request, timeout)?;
        micros.push(start.elapsed().as_secs_f64() * 1e6);
    }
    micros.sort_by(f64::total_cmp);
    let at = |q: f64| micros[((micros.len() - 1) as f64 * q).round() as usize];
    println!(
        "{{\"count\": {count}, \"client_poll_us\": {poll_us}, \"gap_us\": {gap_us}, \"p50_us\": {:.1}, \"p90_us\": {:.1}, \"p99_us\": {:.1}, \"max_us\": {:.1}}}",
        at(0.5),
        at(0.9),
        at(0.99),
        micros[micros.len() - 1]
    );
    Ok(())
}
