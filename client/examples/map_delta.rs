//! Changes a map in `dyfosd` with an atomic batch of deltas, and shows that a bad
//! batch changes nothing.
//!
//! ```sh
//! cargo run -p dyfos-client --example map_delta [PREFIX [DOMAIN]]
//! ```

use dyfos_client::prelude::*;
use dyfos_shared::world::{AxisBox, VerticalCylinder};
use std::time::Duration;

mod common;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mut client = Client::connect(&common::config(args.next(), args.next()))?;
    let timeout = Duration::from_secs(5);
    let map: MapId = 42;
    common::create_map(&mut client, map, timeout)?;
    let version = client.snapshot(map, timeout)?.version();

    // A newly seen pole and crate, and the sun moved: one batch, one version each.
    let pole = Obstacle::Cylinder(VerticalCylinder { center: na::Point2::new(3.0, -1.0), radius: 0.4, height: 6.0 });
    let crate_ = Obstacle::Box(AxisBox { min: na::Point3::new(-4.0, 2.0, 0.0), max: na::Point3::new(-3.0, 3.0, 1.0) });
    let batch = [
        MapDelta::UpsertObstacle { id: 10, obstacle: pole },
        MapDelta::UpsertObstacle { id: 11, obstacle: crate_ },
        MapDelta::SetSun(Sun::new(0.5, -1.0)?),
    ];
    let version = client.apply(map, Some(version), &batch, timeout)?;
    println!("applied 3 deltas: map {map} is at version {version}");

    // Removing an obstacle that does not exist rejects the whole batch.
    let bad = [MapDelta::RemoveObstacle { id: 10 }, MapDelta::RemoveObstacle { id: 999 }];
    match client.apply(map, Some(version), &bad, timeout) {
        Err(e) => println!("rejected as expected: {e}"),
        Ok(v) => return Err(format!("a bad batch was accepted (version {v})").into()),
    }
    let world = client.snapshot(map, timeout)?;
    println!("map {map} still at version {} with {} obstacles", world.version(), world.obstacles().len());
    Ok(())
}
