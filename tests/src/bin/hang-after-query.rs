//! `hang-after-query`: a client that sends one slow query and then hangs, for the
//! test to kill while its reply listener is registered (`tests/tests/it/hostile.rs`).
//!
//! ```text
//! hang-after-query PREFIX DOMAIN MAP SCENARIO
//! ```
//!
//! Connects, sends a `brute` query of `MAP` for `SCENARIO`'s rover from a second
//! thread, prints `sent` once the query has had time to leave, and sleeps.

use dyfos_client::prelude::*;
use std::time::Duration;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [prefix, domain, map, scenario] = args.as_slice() else {
        eprintln!("usage: hang-after-query PREFIX DOMAIN MAP SCENARIO");
        std::process::exit(2);
    };
    let s = Scenario::from_json(&std::fs::read_to_string(scenario).expect("scenario file")).expect("scenario");
    let config = ClientConfig { prefix: prefix.clone(), domain: Some(domain.clone()), ..ClientConfig::default() };
    let mut client = Client::connect(&config).expect("connect");
    let request = RendezvousRequest {
        algorithm: Algorithm::Brute,
        params: s.params,
        ..RendezvousRequest::new(map.parse().expect("map id"), s.belief)
    };
    std::thread::spawn(move || {
        let _ = client.rendezvous(&request, Duration::from_secs(60));
    });
    std::thread::sleep(Duration::from_millis(20));
    println!("sent");
    std::thread::sleep(Duration::from_secs(60));
}
