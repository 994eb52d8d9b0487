//! Our `.bt` reader against OctoMap's own (liboctomap, Debian's `liboctomap-dev`):
//! the same occupied nodes, node count and resolution, on OctoMap's published map of
//! a real building (`tests/data/octomap/geb079.bt`, BSD, licence beside it) and on maps
//! liboctomap writes here, pruned and unpruned, at several resolutions.
//!
//! The oracle, `tests/oracle/octomap_cells.cpp`, is compiled here with the system
//! C++ compiler; `scripts/test` installs `liboctomap-dev` on a fresh machine.

use dyfos_shared::world::octomap::Octomap;
use dyfos_tests::{Scratch, data};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The oracle, compiled for one test into a scratch directory under the system's
/// temporary directory, where the C/C++ tests' programs are compiled and run too: CI
/// could not execute it from the target directory (permission denied, the file's mode
/// 0600 as the linker left it there), nor from the target's `tmp`.
struct Oracle {
    dir: Scratch,
    exe: PathBuf,
}

impl Oracle {
    /// Compiles it into a scratch directory named after the test (`test`).
    fn build(test: &str) -> Oracle {
        use std::os::unix::fs::PermissionsExt;
        let dir = Scratch::new(&format!("octomap-{test}"));
        let exe = dir.0.join("octomap_cells");
        let source = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("oracle/octomap_cells.cpp");
        let built = Command::new("c++")
            .arg("-O1")
            .arg("-o")
            .arg(&exe)
            .arg(&source)
            .args(["-loctomap", "-loctomath"])
            .output()
            .expect("run the C++ compiler");
        assert!(
            built.status.success(),
            "cannot build the liboctomap oracle (install liboctomap-dev; scripts/test does): {}",
            String::from_utf8_lossy(&built.stderr)
        );
        // Executable whatever mode the linker's file was given.
        std::fs::set_permissions(&exe, std::fs::Permissions::from_mode(0o755)).expect("make the oracle executable");
        Oracle { dir, exe }
    }

    /// Runs the oracle with `args`; a failure to start it names the file and its mode.
    fn run(&self, args: &[&std::ffi::OsStr]) -> std::process::Output {
        Command::new(&self.exe).args(args).output().unwrap_or_else(|e| {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&self.exe).map(|m| format!("{:o}", m.permissions().mode()));
            panic!("cannot run the oracle {} (mode {mode:?}): {e}", self.exe.display())
        })
    }

    /// What liboctomap reads from `file`: occupied nodes (min index, side), sorted;
    /// node count; resolution.
    fn read(&self, file: &Path) -> (Vec<[i64; 4]>, u64, f64) {
        let listed = self.run(&[file.as_os_str()]);
        assert!(listed.status.success(), "{}", String::from_utf8_lossy(&listed.stderr));
        let text = String::from_utf8(listed.stdout).unwrap();
        let (cubes, last) = text.trim_end().rsplit_once('\n').unwrap_or(("", text.trim_end()));
        let mut nodes: Vec<[i64; 4]> = cubes
            .lines()
            .map(|l| {
                let v: Vec<i64> = l.split(' ').map(|n| n.parse().unwrap()).collect();
                [v[0], v[1], v[2], v[3]]
            })
            .collect();
        nodes.sort_unstable();
        let fields: Vec<&str> = last.split(' ').collect();
        assert_eq!((fields[0], fields[2]), ("nodes", "res"), "{last}");
        (nodes, fields[1].parse().unwrap(), fields[3].parse().unwrap())
    }
}

/// What our reader reads, in the same form.
fn ours(file: &Path) -> (Vec<[i64; 4]>, u64, f64) {
    let map = Octomap::from_bt(&std::fs::read(file).unwrap()).unwrap();
    let mut nodes: Vec<[i64; 4]> = map.occupied().iter().map(|c| [c.min[0], c.min[1], c.min[2], c.side]).collect();
    nodes.sort_unstable();
    (nodes, map.nodes(), map.resolution())
}

#[test]
fn the_reader_finds_the_occupied_nodes_liboctomap_finds() {
    let file = data("octomap/geb079.bt");
    let (expected, got) = (Oracle::build("geb079").read(&file), ours(&file));
    assert_eq!(got.0.len(), expected.0.len());
    assert_eq!(got.0, expected.0, "the occupied nodes differ");
    assert_eq!((got.1, got.2.to_bits()), (expected.1, expected.2.to_bits()));
    // The data's own README: 143 729 occupied leaves, 185 673 finest cells.
    let cells: i64 = got.0.iter().map(|c| c[3].pow(3)).sum();
    assert_eq!((got.0.len(), cells), (143_729, 185_673));
}

#[test]
fn maps_liboctomap_writes_pruned_or_not_read_the_same() {
    let oracle = Oracle::build("pruned-or-not");
    let mut pruned_nodes = 0;
    for (res, seed) in [("0.05", "1"), ("0.1", "2"), ("0.37", "3")] {
        let mut cells_by_form = Vec::new();
        for form in ["pruned", "unpruned"] {
            let file = oracle.dir.0.join(format!("map-{res}-{seed}-{form}.bt"));
            let made = oracle.run(&["generate".as_ref(), file.as_os_str(), res.as_ref(), seed.as_ref(), form.as_ref()]);
            assert!(made.status.success(), "{}", String::from_utf8_lossy(&made.stderr));
            let (expected, got) = (oracle.read(&file), ours(&file));
            assert_eq!(got.0, expected.0, "{res} {form}: the occupied nodes differ");
            assert_eq!((got.1, got.2.to_bits()), (expected.1, expected.2.to_bits()), "{res} {form}");
            pruned_nodes += got.0.iter().filter(|c| c[3] > 1).count();
            let mut cells: Vec<[i64; 3]> = Octomap::from_bt(&std::fs::read(&file).unwrap())
                .unwrap()
                .occupied()
                .iter()
                .flat_map(|c| c.cells().collect::<Vec<_>>())
                .collect();
            cells.sort_unstable();
            cells_by_form.push(cells);
        }
        // Pruning changes the tree, not the occupied cells.
        assert_eq!(cells_by_form[0], cells_by_form[1], "{res}: pruned and unpruned maps differ in cells");
    }
    assert!(pruned_nodes >= 9, "the pruned maps have no node above the finest depth to check");
}

/// What dyfos writes (`write_bt`, behind `dyfos map snapshot --bt`) liboctomap reads
/// back to the same occupied cells.
#[test]
fn liboctomap_reads_the_files_dyfos_writes() {
    let original = Octomap::from_bt(&std::fs::read(data("octomap/geb079.bt")).unwrap()).unwrap();
    let mut cells: Vec<[i64; 3]> = original.occupied().iter().flat_map(|c| c.cells().collect::<Vec<_>>()).collect();
    cells.sort_unstable();
    let oracle = Oracle::build("written-by-dyfos");
    let file = oracle.dir.0.join("written-by-dyfos.bt");
    let bytes = dyfos_shared::world::octomap::write_bt(original.resolution(), cells.iter().copied()).unwrap();
    std::fs::write(&file, bytes).unwrap();
    let (nodes, _, res) = oracle.read(&file);
    let mut back: Vec<[i64; 3]> = nodes
        .iter()
        .flat_map(|c| {
            let s = c[3];
            (0..s * s * s).map(move |n| [c[0] + n % s, c[1] + (n / s) % s, c[2] + n / (s * s)])
        })
        .collect();
    back.sort_unstable();
    assert_eq!(back.len(), cells.len());
    assert_eq!(back, cells, "liboctomap reads other cells from the written file");
    assert_eq!(res.to_bits(), original.resolution().to_bits());
}
