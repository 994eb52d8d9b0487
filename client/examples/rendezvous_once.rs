//! Asks a running `dyfosd` once where the viewer's camera should be.
//!
//! ```sh
//! dyfosd &                                   # in another terminal
//! cargo run -p dyfos-client --example rendezvous_once [PREFIX [DOMAIN]]
//! ```
//!
//! Creates map 1 (a 20 m square with one pole) if it is missing, then sends one
//! rendezvous request and prints the answer.

use dyfos_client::prelude::*;
use std::time::Duration;

mod common;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mut client = Client::connect(&common::config(args.next(), args.next()))?;
    let timeout = Duration::from_secs(5);

    if common::create_map(&mut client, 1, timeout)? {
        let pole = Obstacle::Cylinder(dyfos_shared::world::VerticalCylinder {
            center: na::Point2::new(2.0, 1.0),
            radius: 0.5,
            height: 10.0,
        });
        client.apply(1, Some(0), &[MapDelta::UpsertObstacle { id: 1, obstacle: pole }], timeout)?;
    }

    let belief = Belief::new([0.0, 0.0, 0.3], [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]])?;
    let request =
        RendezvousRequest { seed: 7, deadline: Some(Duration::from_secs(2)), ..RendezvousRequest::new(1, belief) };
    let answer = client.rendezvous(&request, timeout)?;
    println!(
        "viewer at ({:.3}, {:.3}, {:.3}) yaw {:.3} rad; E = {:.4}; map version {}; {} candidates in {} µs",
        answer.viewer_position.x,
        answer.viewer_position.y,
        answer.viewer_position.z,
        answer.viewer_yaw,
        answer.cost,
        answer.map_version,
        answer.evaluations.total,
        answer.micros
    );
    Ok(())
}
