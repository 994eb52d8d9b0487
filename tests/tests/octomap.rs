//! Our `.bt` reader against OctoMap's own (liboctomap, Debian's `liboctomap-dev`):
//! the same occupied nodes, node count and resolution, on OctoMap's published map of
//! a real building (`tests/data/octomap/geb079.bt`, BSD, licence beside it).
//!
//! The oracle, `tests/oracle/octomap_cells.cpp`, is compiled here with the system
//! C++ compiler; `scripts/test` installs `liboctomap-dev` on a fresh machine.

use dyfos_shared::world::octomap::Octomap;
use dyfos_tests::data;
use std::path::PathBuf;
use std::process::Command;

fn oracle() -> PathBuf {
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("octomap_cells");
    let source = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("oracle/octomap_cells.cpp");
    let built = Command::new("c++")
        .arg("-O1")
        .arg("-o")
        .arg(&out)
        .arg(&source)
        .args(["-loctomap", "-loctomath"])
        .output()
        .expect("run the C++ compiler");
    assert!(
        built.status.success(),
        "cannot build the liboctomap oracle (install liboctomap-dev; scripts/test does): {}",
        String::from_utf8_lossy(&built.stderr)
    );
    out
}

#[test]
fn the_reader_finds_the_occupied_nodes_liboctomap_finds() {
    let file = data("octomap/geb079.bt");
    let listed = Command::new(oracle()).arg(&file).output().expect("run the oracle");
    assert!(listed.status.success(), "{}", String::from_utf8_lossy(&listed.stderr));
    let text = String::from_utf8(listed.stdout).unwrap();
    let (cubes, last) = text.trim_end().rsplit_once('\n').unwrap();
    let mut expected: Vec<[i64; 4]> = cubes
        .lines()
        .map(|l| {
            let v: Vec<i64> = l.split(' ').map(|n| n.parse().unwrap()).collect();
            [v[0], v[1], v[2], v[3]]
        })
        .collect();
    let map = Octomap::from_bt(&std::fs::read(&file).unwrap()).unwrap();
    let mut got: Vec<[i64; 4]> = map.occupied().iter().map(|c| [c.min[0], c.min[1], c.min[2], c.side]).collect();
    expected.sort_unstable();
    got.sort_unstable();
    assert_eq!(got.len(), expected.len());
    assert_eq!(got, expected, "the occupied nodes differ");
    let fields: Vec<&str> = last.split(' ').collect();
    assert_eq!(fields[..3], ["nodes", &map.nodes().to_string(), "res"], "{last}");
    assert_eq!(fields[3].parse::<f64>().unwrap().to_bits(), map.resolution().to_bits(), "{last}");
    // The data's own README: 143 729 occupied leaves, 185 673 finest cells.
    assert_eq!((got.len(), map.cell_count()), (143_729, 185_673));
}
