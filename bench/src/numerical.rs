//! The random maps of the paper's numerical evaluation (SPEC §10), seeded.
//!
//! Map `index` of seed `seed` is drawn from its own ChaCha stream (`seed`, stream
//! `index`), so the same pair always gives the same map, and map 7 does not change
//! when more maps are asked for.
//!
//! ```
//! use dyfos_bench::numerical::{NumericalConfig, numerical_map, voxelized};
//!
//! let config = NumericalConfig::paper();
//! let map = numerical_map(42, 0, &config);
//! assert_eq!(map.world.obstacles().len(), 25);
//! assert_eq!(map, numerical_map(42, 0, &config));
//! assert_ne!(map, numerical_map(42, 1, &config));
//! // The same area as a 0.1 m occupancy grid, obstacles rasterized into cells.
//! let grid = voxelized(&map, 0.1).unwrap();
//! assert!(grid.world.obstacles().is_empty() && grid.world.voxels().unwrap().len() > 10_000);
//! ```
//!
//! What is drawn, in this order (SPEC §10, for `NumericalConfig::paper()`):
//! 1. the rover position U(−8, 8)² and heading U(−π, π);
//! 2. the prior position covariance AᵀA, A's entries N(0, 0.5²), A redrawn while the
//!    smaller eigenvalue of AᵀA is below 1e-4; heading variance 0.05, no correlation;
//! 3. the sun: elevation U(20°, 70°), azimuth U(−π, π);
//! 4. 25 cylinders, each with its centre uniform over the bounds [−10, −10, 10, 10],
//!    diameter U(0.5, 2.5) m and height 10 m; one whose centre is closer than
//!    r + rover_radius + 0.1 m to the rover is redrawn whole (centre and diameter).
//!
//! Interpretations: "its smaller eigenvalue" is read as AᵀA's (A's own may be
//! complex); a uniform draw is `lo + (hi − lo)·u` with u ∈ [0, 1) and a normal one
//! is Box–Muller, written out so that maps do not change with a library's sampler.
//! The golden maps in `tests/data/golden/scenarios/numerical` come from another
//! generator: they share these distributions, not these numbers.
//!
//! Larger maps ([`NumericalConfig::with_cylinders`]) keep the paper's density of 25
//! cylinders per 400 m² by growing the square, so that query times show how the
//! map's size costs, not how a crowded map blocks every view; the rover stays 2 m
//! inside the bounds as in the paper.

use dyfos_shared::params::{ModelKind, Params};
use dyfos_shared::posterior::Belief;
use dyfos_shared::scenario::Scenario;
use dyfos_shared::world::{Bounds, CellIndex, Obstacle, Sun, VerticalCylinder, VoxelError, VoxelGrid, World};
use nalgebra::{Point2, Point3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::{PI, TAU};

/// Cylinders of the paper's maps.
pub const PAPER_CYLINDERS: usize = 25;
/// Half the side of the paper's square map, m.
pub const PAPER_HALF_WIDTH: f64 = 10.0;
/// Height of every cylinder, m.
pub const CYLINDER_HEIGHT: f64 = 10.0;
/// Diameter range of the cylinders, m.
pub const DIAMETER: (f64, f64) = (0.5, 2.5);
/// Extra clearance between a cylinder and the rover's footprint, m.
pub const ROVER_CLEARANCE: f64 = 0.1;
/// How far inside the bounds the rover stays, m (the paper's U(−8, 8) on ±10).
pub const ROVER_INSET: f64 = 2.0;
/// Standard deviation of the entries of A.
pub const PRIOR_A_STD: f64 = 0.5;
/// A is redrawn while AᵀA's smaller eigenvalue is below this.
pub const PRIOR_MIN_EIGENVALUE: f64 = 1e-4;
/// Heading variance of the prior, rad².
pub const HEADING_VARIANCE: f64 = 0.05;
/// Sun elevation range, degrees.
pub const SUN_ELEVATION_DEG: (f64, f64) = (20.0, 70.0);

/// What kind of numerical map to draw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NumericalConfig {
    /// Number of cylinders.
    pub cylinders: usize,
    /// The map is the square `[−half_width, half_width]²`.
    pub half_width: f64,
    /// The SDSMM the scenario asks for.
    pub model: ModelKind,
}

impl NumericalConfig {
    /// SPEC §10's maps: 25 cylinders on [−10, 10]², model `paper`.
    pub fn paper() -> Self {
        NumericalConfig { cylinders: PAPER_CYLINDERS, half_width: PAPER_HALF_WIDTH, model: ModelKind::Paper }
    }

    /// `n` cylinders at the paper's density: the square grows to
    /// `±10·sqrt(n/25)` m. `with_cylinders(25)` is [`NumericalConfig::paper`].
    pub fn with_cylinders(n: usize) -> Self {
        let half_width = PAPER_HALF_WIDTH * (n as f64 / PAPER_CYLINDERS as f64).sqrt();
        NumericalConfig { cylinders: n, half_width, ..Self::paper() }
    }

    /// The same maps, scored with `model`.
    pub fn model(self, model: ModelKind) -> Self {
        NumericalConfig { model, ..self }
    }

    /// The map bounds.
    pub fn bounds(&self) -> Bounds {
        let h = self.half_width;
        Bounds::new([-h, -h, h, h]).expect("half_width must be positive and finite")
    }
}

impl Default for NumericalConfig {
    fn default() -> Self {
        Self::paper()
    }
}

/// Uniform in [lo, hi).
fn uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

/// Standard normal by Box–Muller (one of the pair).
fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1 = 1.0 - rng.random::<f64>(); // (0, 1]: ln is finite
    let u2 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
}

/// The smaller eigenvalue of the symmetric 2×2 matrix [[a, b], [b, c]].
fn smaller_eigenvalue(a: f64, b: f64, c: f64) -> f64 {
    0.5 * (a + c) - (0.25 * (a - c) * (a - c) + b * b).sqrt()
}

/// Map `index` of seed `seed` (see the module docs for what is drawn).
pub fn numerical_map(seed: u64, index: u64, config: &NumericalConfig) -> Scenario {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(index);
    let params = Params { model: config.model, ..Params::default() };
    let bounds = config.bounds();
    let h = config.half_width;
    let reach = (h - ROVER_INSET).max(0.0);

    // 1. Rover.
    let rover = Point2::new(uniform(&mut rng, -reach, reach), uniform(&mut rng, -reach, reach));
    let heading = uniform(&mut rng, -PI, PI);

    // 2. Prior: position block AᵀA, heading variance, no correlation.
    let pos = loop {
        let a: [f64; 4] = std::array::from_fn(|_| PRIOR_A_STD * normal(&mut rng));
        // A = [[a0, a1], [a2, a3]]; AᵀA = [[a0² + a2², a0a1 + a2a3], [·, a1² + a3²]].
        let (xx, xy, yy) = (a[0] * a[0] + a[2] * a[2], a[0] * a[1] + a[2] * a[3], a[1] * a[1] + a[3] * a[3]);
        if smaller_eigenvalue(xx, xy, yy) >= PRIOR_MIN_EIGENVALUE {
            break [[xx, xy], [xy, yy]];
        }
    };
    let cov = [[pos[0][0], pos[0][1], 0.0], [pos[1][0], pos[1][1], 0.0], [0.0, 0.0, HEADING_VARIANCE]];
    let belief = Belief::new([rover.x, rover.y, heading], cov).expect("AᵀA with λ_min ≥ 1e-4 is SPD");

    // 3. Sun.
    let (el_lo, el_hi) = SUN_ELEVATION_DEG;
    let sun = Sun::new(uniform(&mut rng, el_lo.to_radians(), el_hi.to_radians()), uniform(&mut rng, -PI, PI))
        .expect("elevation in [20°, 70°]");

    // 4. Cylinders, redrawn while too close to the rover.
    let obstacles: Vec<(u32, Obstacle)> = (0..config.cylinders)
        .map(|i| {
            let cylinder = loop {
                let center = Point2::new(uniform(&mut rng, -h, h), uniform(&mut rng, -h, h));
                let radius = 0.5 * uniform(&mut rng, DIAMETER.0, DIAMETER.1);
                if (center - rover).norm() >= radius + params.rover_radius + ROVER_CLEARANCE {
                    break VerticalCylinder { center, radius, height: CYLINDER_HEIGHT };
                }
            };
            (u32::try_from(i + 1).expect("obstacle count fits u32"), Obstacle::Cylinder(cylinder))
        })
        .collect();
    let world = World::new(0, bounds, sun, obstacles, None).expect("generated cylinders are valid");
    Scenario { world, belief, params }
}

/// The maps `0..count` of seed `seed`.
pub fn numerical_maps(seed: u64, count: usize, config: &NumericalConfig) -> Vec<Scenario> {
    (0..count as u64).map(|i| numerical_map(seed, i, config)).collect()
}

/// The same scenario with its obstacles replaced by an occupancy grid of cell side
/// `resolution`, origin at the map's (x_min, y_min, 0) corner (SPEC §1).
///
/// A cell is occupied when its interior overlaps an obstacle, so the grid covers
/// every obstacle (and may be up to one cell fatter). Fails when the grid exceeds
/// the map limits (`dyfos_shared::limits`).
pub fn voxelized(scenario: &Scenario, resolution: f64) -> Result<Scenario, VoxelError> {
    let world = &scenario.world;
    let b = world.bounds();
    let origin = Point3::new(b.min.x, b.min.y, 0.0);
    let mut grid = VoxelGrid::empty(resolution, origin)?;
    let mut cells: Vec<CellIndex> = Vec::new();
    // Index range of cells whose open interval overlaps the open interval (lo, hi).
    let span = |lo: f64, hi: f64, o: f64| -> (i64, i64) {
        (((lo - o) / resolution).floor() as i64, ((hi - o) / resolution).ceil() as i64 - 1)
    };
    for obstacle in world.obstacles().values() {
        match obstacle {
            Obstacle::Cylinder(c) => {
                let r = c.radius;
                let (i0, i1) = span(c.center.x - r, c.center.x + r, origin.x);
                let (j0, j1) = span(c.center.y - r, c.center.y + r, origin.y);
                let (k0, k1) = span(0.0, c.height, origin.z);
                for i in i0..=i1 {
                    for j in j0..=j1 {
                        // Nearest point of the cell's square to the axis; strictly
                        // inside the disc means the interiors overlap.
                        let x0 = origin.x + i as f64 * resolution;
                        let y0 = origin.y + j as f64 * resolution;
                        let dx = c.center.x.clamp(x0, x0 + resolution) - c.center.x;
                        let dy = c.center.y.clamp(y0, y0 + resolution) - c.center.y;
                        if dx * dx + dy * dy < r * r {
                            cells.extend((k0.max(0)..=k1).map(|k| [i, j, k]));
                        }
                    }
                }
            }
            Obstacle::Box(bx) => {
                let (i0, i1) = span(bx.min.x, bx.max.x, origin.x);
                let (j0, j1) = span(bx.min.y, bx.max.y, origin.y);
                let (k0, k1) = span(bx.min.z, bx.max.z, origin.z);
                for i in i0..=i1 {
                    for j in j0..=j1 {
                        cells.extend((k0..=k1).map(|k| [i, j, k]));
                    }
                }
            }
        }
        // Into the grid a million at a time: the list would outgrow the grid.
        if cells.len() > 1 << 20 {
            grid = grid.with_cells(&cells, true)?;
            cells.clear();
        }
    }
    let grid = grid.with_cells(&cells, true)?;
    let world = World::new(world.version(), *b, *world.sun(), [], Some(grid)).expect("no obstacles to reject");
    Ok(Scenario { world, ..scenario.clone() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_shared::world::Segment;
    use nalgebra::Vector3;

    #[test]
    fn maps_follow_spec_section_10() {
        let config = NumericalConfig::paper();
        let mut headings = Vec::new();
        for i in 0..200 {
            let s = numerical_map(7, i, &config);
            let w = &s.world;
            assert_eq!(w.bounds().to_array(), [-10.0, -10.0, 10.0, 10.0]);
            let m = s.belief.mean;
            assert!(m.x.abs() <= 8.0 && m.y.abs() <= 8.0 && m.z.abs() <= PI, "{m:?}");
            headings.push(m.z);
            let el = w.sun().elevation.to_degrees();
            assert!((20.0..=70.0).contains(&el), "{el}");
            assert!(w.sun().azimuth.abs() <= PI);
            let cov = s.belief.cov.matrix();
            assert_eq!((cov[(0, 2)], cov[(1, 2)], cov[(2, 2)]), (0.0, 0.0, HEADING_VARIANCE));
            assert!(smaller_eigenvalue(cov[(0, 0)], cov[(0, 1)], cov[(1, 1)]) >= 1e-4);
            assert_eq!(s.params.model, ModelKind::Paper);
            assert_eq!(w.obstacles().len(), 25);
            for o in w.obstacles().values() {
                let Obstacle::Cylinder(c) = o else { panic!("only cylinders") };
                assert!((0.25..1.25).contains(&c.radius) && c.height == 10.0);
                assert!(c.center.x.abs() <= 10.0 && c.center.y.abs() <= 10.0);
                let d = (c.center - Point2::new(m.x, m.y)).norm();
                assert!(d >= c.radius + 0.75 + 0.1, "cylinder {d} m from the rover");
            }
        }
        // Headings cover both half-turns (U(−π, π), not a constant).
        assert!(headings.iter().any(|h| *h < -2.0) && headings.iter().any(|h| *h > 2.0));
    }

    #[test]
    fn prior_entries_have_the_specified_spread() {
        // E[(AᵀA)_xx] = 2·0.5² = 0.5 for A's entries N(0, 0.5²); the rejection of
        // near-singular A barely moves it.
        let n = 2000;
        let mean_xx: f64 =
            (0..n).map(|i| numerical_map(3, i, &NumericalConfig::paper()).belief.cov.matrix()[(0, 0)]).sum::<f64>()
                / n as f64;
        assert!((mean_xx - 0.5).abs() < 0.05, "{mean_xx}");
    }

    #[test]
    fn larger_maps_keep_the_density() {
        let c = NumericalConfig::with_cylinders(400);
        assert_eq!(c.half_width, 40.0);
        assert_eq!(NumericalConfig::with_cylinders(25), NumericalConfig::paper());
        let s = numerical_map(1, 0, &c.model(ModelKind::Anisotropic));
        assert_eq!(s.world.obstacles().len(), 400);
        assert_eq!(s.params.model, ModelKind::Anisotropic);
        assert!(s.belief.mean.x.abs() <= 38.0);
    }

    #[test]
    fn voxel_map_covers_the_cylinders() {
        let s = numerical_map(5, 2, &NumericalConfig::paper());
        let v = voxelized(&s, 0.1).unwrap();
        assert_eq!(v.belief, s.belief);
        let grid = v.world.voxels().unwrap();
        // A vertical line through each cylinder's axis hits cells at every height
        // below 10 m; one just outside the cylinder plus a cell misses.
        for o in s.world.obstacles().values() {
            let Obstacle::Cylinder(c) = o else { unreachable!() };
            let probe = |x: f64, y: f64, z: f64| {
                let seg = Segment::closed(Point3::new(x, y, z), Vector3::z(), 0.0);
                grid.first_contact(&seg).is_some()
            };
            for z in [0.05, 5.0, 9.95] {
                assert!(probe(c.center.x, c.center.y, z));
                assert!(probe(c.center.x + 0.99 * c.radius, c.center.y, z));
            }
            assert!(!probe(c.center.x, c.center.y, 10.2));
            let outside = c.center.x + c.radius + 0.15;
            let clear = s.world.obstacles().values().all(|o| {
                let Obstacle::Cylinder(d) = o else { unreachable!() };
                (Point2::new(outside, c.center.y) - d.center).norm() > d.radius + 0.15
            });
            if clear {
                assert!(!probe(outside, c.center.y, 5.0), "cell past the cylinder at {outside}");
            }
        }
        // Rasterized area ≈ the discs' area (each within one cell ring of it).
        let cells_per_layer = grid.cells().filter(|c| c[2] == 0).count() as f64;
        let disc_area: f64 = s
            .world
            .obstacles()
            .values()
            .map(|o| match o {
                Obstacle::Cylinder(c) => PI * c.radius * c.radius,
                Obstacle::Box(_) => 0.0,
            })
            .sum();
        assert!(cells_per_layer * 0.01 > 0.8 * disc_area && cells_per_layer * 0.01 < 1.6 * disc_area);
        assert_eq!(grid.cells().filter(|c| c[2] == 99).count() as f64, cells_per_layer);
        assert_eq!(grid.cells().filter(|c| c[2] >= 100).count(), 0);
    }
}
