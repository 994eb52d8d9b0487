//! `brute`: the exhaustive grid of SPEC §8, the "best possible" answer.
//!
//! Points are numbered with ρ slowest and ψ_v fastest. The answer is the minimum
//! cost, and among points within 1e-9 of it the lowest index: the same whatever
//! the thread count. Every point gets [`Lupp::evaluate`]'s verdict, and is counted
//! as it would be; the work is made smaller without changing a bit of it:
//!
//! - a pose is assembled from parts computed once per search (`d_s` per (ψ, φ),
//!   the rotation and offset per ψ_v: [`SensorRig::pose_from`]), not from
//!   `tan`, `normalize` and `sin_cos` per point;
//! - the 72 yaws of one (ρ, ψ, φ) put the viewer on a circle: the query's list of
//!   obstacles near any collision star is narrowed once per arc of `ARC` yaws to
//!   those near the box around the arc's stars ([`dyfos_shared::world::World::nearby_within`]), so each
//!   star is compared with the few boxes left (an arc with none left skips its
//!   stars: [`PoseFacts`]'s `collision_clear`); the sight lines go
//!   through the query's sight fan, as for any candidate, but on a map with a
//!   voxel grid (listed in every direction of the fan) an arc whose sight lines
//!   have nothing solid near ([`dyfos_shared::world::World::box_is_clear`]) skips them;
//! - what the row knows of each point is passed on, not found again
//!   ([`PoseFacts`]): whether its viewer is in the workspace, and its yaw's
//!   `sin_cos` (computed once per search), with which most stars beside an
//!   obstacle are decided by their segments' directions without the exact test
//!   ([`dyfos_shared::world::World::star_contact_near_turned`]);
//! - threads take blocks of rows from a shared counter (infeasible rows are cheap,
//!   so fixed shares are unbalanced), and each keeps, per block, only the points
//!   that could still be the answer (each new minimum of the block, within 1e-9 of
//!   the block's minimum) instead of a cost per point;
//! - so a point's cost matters only below a bound (the block's minimum, or just
//!   above the thread's): a feasible point whose determinants prove its cost at
//!   least that far up skips the cost's logarithms ([`Lupp::evaluate_pose_below`]).

use super::{Evaluator, Found, Search, SearchControl, SearchOutcome};
use crate::lupp::{Evaluation, Lupp, PoseFacts};
use dyfos_shared::answer::{EvalStats, StopReason};
use dyfos_shared::math::{Point3, Vector3};
use dyfos_shared::posterior::{CostBound, Prior};
use dyfos_shared::sensor::{SearchSpace, SensorPose, SensorRig, SensorState, YawFrame};
use dyfos_shared::world::Nearby;
use std::f64::consts::PI;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Grid sizes over (ρ, ψ, φ, ψ_v).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Brute {
    /// Points per axis; SPEC's default is 25 × 17 × 13 × 72.
    pub grid: [usize; 4],
}

impl Default for Brute {
    fn default() -> Self {
        Brute { grid: [25, 17, 13, 72] }
    }
}

/// `lo + i·(hi − lo)/(n − 1)`, the last exactly `hi`; one point sits mid-range.
fn axis(lo: f64, hi: f64, i: usize, n: usize) -> f64 {
    match n {
        1 => 0.5 * (lo + hi),
        _ if i == n - 1 => hi,
        _ => lo + i as f64 * (hi - lo) / (n - 1) as f64,
    }
}

/// Yaws of a row that share one narrowed list of obstacles near their stars.
const ARC: usize = 12;

/// Rows (one (ρ, ψ, φ), all yaws) a thread takes at a time.
const BLOCK_ROWS: usize = 8;

impl Brute {
    /// Number of grid points.
    pub fn len(&self) -> usize {
        self.grid.iter().product()
    }

    /// Whether the grid has no points.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The candidate numbered `index`.
    pub fn point(&self, space: &SearchSpace, index: usize) -> SensorState {
        let [nr, np, nf, ny] = self.grid;
        let iy = index % ny;
        let i_phi = index / ny % nf;
        let i_psi = index / (ny * nf) % np;
        let i_rho = index / (ny * nf * np);
        SensorState::new(
            axis(space.lo[0], space.hi[0], i_rho, nr),
            axis(space.lo[1], space.hi[1], i_psi, np),
            axis(space.lo[2], space.hi[2], i_phi, nf),
            -PI + 2.0 * PI * iy as f64 / ny as f64,
        )
    }
}

/// What every point's pose is made of, computed once per search.
struct Plan {
    rho: Vec<f64>,
    psi: Vec<f64>,
    phi: Vec<f64>,
    /// `d_s` per (ψ, φ), φ fastest.
    directions: Vec<Vector3<f64>>,
    /// Per yaw, with the yaw as [`Brute::point`] wraps it.
    frames: Vec<YawFrame>,
    /// Per yaw, its `sin_cos()` (for the collision star's segments).
    turns: Vec<(f64, f64)>,
}

impl Plan {
    fn new(brute: &Brute, lupp: &Lupp) -> Self {
        let s = lupp.space();
        let [nr, np, nf, ny] = brute.grid;
        let rho: Vec<f64> = (0..nr).map(|i| axis(s.lo[0], s.hi[0], i, nr)).collect();
        let psi: Vec<f64> = (0..np).map(|i| axis(s.lo[1], s.hi[1], i, np)).collect();
        let phi: Vec<f64> = (0..nf).map(|i| axis(s.lo[2], s.hi[2], i, nf)).collect();
        let directions = psi.iter().flat_map(|p| phi.iter().map(|f| SensorRig::direction(*p, *f))).collect();
        let frames: Vec<YawFrame> = (0..ny)
            .map(|k| lupp.rig().yaw_frame(SensorState::new(0.0, 0.0, 0.0, -PI + 2.0 * PI * k as f64 / ny as f64).yaw))
            .collect();
        let turns = frames.iter().map(|f| f.yaw.sin_cos()).collect();
        Plan { rho, psi, phi, directions, frames, turns }
    }
}

/// A point that may be the answer: its index and cost.
type Record = (usize, f64);

/// One thread's points that may still be the answer, kept per block of rows
/// (each new minimum of the block, within 1e-9 of the block's minimum), and the
/// bound above which a cost need not be computed exactly: the block's minimum (a
/// point at or above it is no new minimum), or 2e-9 above the thread's (it cannot
/// be within 1e-9 of the search's minimum, which is at most the thread's).
struct Kept<'p> {
    prior: &'p Prior,
    records: Vec<Record>,
    block: Vec<Record>,
    block_min: f64,
    thread_min: f64,
    bound: CostBound,
}

impl<'p> Kept<'p> {
    fn new(prior: &'p Prior) -> Self {
        Kept {
            prior,
            records: Vec::new(),
            block: Vec::new(),
            block_min: f64::INFINITY,
            thread_min: f64::INFINITY,
            bound: CostBound::NONE,
        }
    }

    /// Keeps the previous block's records and starts a new block.
    fn next_block(&mut self) {
        self.records.append(&mut self.block);
        self.block_min = f64::INFINITY;
        self.rebound();
    }

    /// A feasible point's cost (+∞ when it is sure to be at least the bound).
    fn found(&mut self, index: usize, cost: f64) {
        // A new minimum of the block: earlier records more than 1e-9 above it can
        // no longer be the answer.
        if cost < self.block_min {
            self.block_min = cost;
            self.block.retain(|(_, c)| *c <= cost + 1e-9);
            self.block.push((index, cost));
            self.thread_min = self.thread_min.min(cost);
            self.rebound();
        }
    }

    fn rebound(&mut self) {
        let bound = self.block_min.min(self.thread_min + 2e-9);
        self.bound = if bound.is_finite() { self.prior.cost_bound(bound) } else { CostBound::NONE };
    }

    /// Every record, the last block's included.
    fn into_records(mut self) -> Vec<Record> {
        self.records.append(&mut self.block);
        self.records
    }
}

/// `span` grown to hold the box `(lo, hi)`.
#[inline]
fn grow(span: &mut Option<(Point3<f64>, Point3<f64>)>, (lo, hi): (Point3<f64>, Point3<f64>)) {
    *span = Some(span.map_or((lo, hi), |(l, h)| (l.inf(&lo), h.sup(&hi))));
}

/// One thread's reusable buffers (sized once, so no allocation per point).
struct Row {
    poses: Vec<(SensorPose, bool)>,
    near: Nearby,
}

impl Search for Brute {
    fn search(&self, lupp: &Lupp, control: &SearchControl) -> SearchOutcome {
        let space = *lupp.space();
        let n = self.len().min(usize::try_from(control.budget.unwrap_or(u64::MAX)).unwrap_or(usize::MAX));
        let ny = self.grid[3].max(1);
        let rows = n.div_ceil(ny);
        let blocks = rows.div_ceil(BLOCK_ROWS);
        let threads = control.threads.clamp(1, 256).min(blocks.max(1));
        let plan = Plan::new(self, lupp);
        let next_block = AtomicUsize::new(0);
        // Each worker evaluates with its own evaluator (no budget: the grid is
        // already cut to it) and reports counts, early stops and its records.
        let unbudgeted = SearchControl { budget: None, ..*control };
        let parts: Vec<(EvalStats, Option<StopReason>, Vec<Record>)> = std::thread::scope(|scope| {
            let handles: Vec<_> = (0..threads)
                .map(|_| {
                    let (control, plan, next_block) = (&unbudgeted, &plan, &next_block);
                    scope.spawn(move || {
                        let mut eval = Evaluator::new(lupp, control);
                        let mut kept = Kept::new(lupp.prior());
                        let mut row = Row { poses: Vec::with_capacity(ARC), near: Nearby::default() };
                        'blocks: loop {
                            let block = next_block.fetch_add(1, Ordering::Relaxed);
                            if block >= blocks {
                                break;
                            }
                            kept.next_block();
                            for r in block * BLOCK_ROWS..((block + 1) * BLOCK_ROWS).min(rows) {
                                let first = r * ny;
                                let count = ny.min(n - first);
                                if !self.scan_row(lupp, plan, &mut eval, &mut row, first, count, &mut kept) {
                                    break 'blocks;
                                }
                            }
                        }
                        let records = kept.into_records();
                        (eval.stats, eval.stopped(), records)
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().expect("brute worker panicked")).collect()
        });
        let mut stats = EvalStats::default();
        let mut stop = if n < self.len() { StopReason::Budget } else { StopReason::Finished };
        let mut records = Vec::new();
        for (s, stopped, r) in parts {
            stats += s;
            records.extend(r);
            // One abandoning thread abandons the whole search.
            if let Some(reason) = stopped
                && stop != StopReason::Abandoned
            {
                stop = reason;
            }
        }
        // The lowest index within 1e-9 of the minimum is the first point of its
        // block at or below that bound, so a new minimum of its block: a record.
        let min = records.iter().map(|r| r.1).fold(f64::INFINITY, f64::min);
        let best = min
            .is_finite()
            .then(|| records.iter().filter(|r| r.1 <= min + 1e-9).min_by_key(|r| r.0).expect("the minimum is a record"))
            .map(|&(i, cost)| Found { x: self.point(&space, i), cost });
        SearchOutcome { best, stats, stop }
    }
}

impl Brute {
    /// Evaluates the `count` first yaws of the row starting at point `first`,
    /// giving `kept` each feasible one (in index order). Returns `false` when the
    /// evaluator stopped.
    #[allow(clippy::too_many_arguments)]
    fn scan_row(
        &self,
        lupp: &Lupp,
        plan: &Plan,
        eval: &mut Evaluator,
        row: &mut Row,
        first: usize,
        count: usize,
        kept: &mut Kept,
    ) -> bool {
        let [_, np, nf, ny] = self.grid;
        let i_phi = first / ny % nf;
        let i_psi = first / (ny * nf) % np;
        let i_rho = first / (ny * nf * np);
        let (rho, psi, phi) = (plan.rho[i_rho], plan.psi[i_psi], plan.phi[i_phi]);
        let direction = &plan.directions[i_psi * nf + i_phi];
        let target = lupp.marker();
        let world = lupp.world();
        let voxels = world.voxels().is_some();
        for (a, frames) in plan.frames[..count].chunks(ARC).enumerate() {
            row.poses.clear();
            let mut span: Option<(Point3<f64>, Point3<f64>)> = None;
            let mut sight_span: Option<(Point3<f64>, Point3<f64>)> = None;
            for frame in frames {
                let pose = lupp.rig().pose_from(&target, rho, direction, frame);
                // A viewer outside the workspace fails before its star is checked.
                let inside = lupp.in_workspace(&pose.viewer_position);
                if inside {
                    grow(&mut span, lupp.collision_box(&pose));
                    if voxels {
                        grow(&mut sight_span, lupp.sight_box(&pose));
                    }
                }
                row.poses.push((pose, inside));
            }
            let near = match span {
                Some((lo, hi)) => {
                    world.nearby_within(lupp.nearby(), &lo, &hi, &mut row.near);
                    &row.near
                }
                None => lupp.nearby(),
            };
            // Nothing near the box holding the arc's stars: no star touches anything.
            let collision_clear = span.is_some() && near.is_empty();
            // A voxel grid is listed in every direction of the sight fan: when
            // nothing solid is near the arc's sight lines, skip them all.
            let sight_clear = sight_span.is_some_and(|(lo, hi)| world.box_is_clear(&lo, &hi));
            let turns = &plan.turns[a * ARC..];
            for (k, ((pose, in_workspace), frame)) in row.poses.iter().zip(frames).enumerate() {
                let x = SensorState { rho, psi, phi, yaw: frame.yaw };
                let facts = PoseFacts { in_workspace: *in_workspace, turn: turns[k], collision_clear, sight_clear };
                match eval.evaluate_with(&x, |l| l.evaluate_pose_below(pose, &facts, near, &kept.bound)) {
                    None => return false,
                    Some(Evaluation::Feasible { cost }) if !cost.is_nan() => kept.found(first + a * ARC + k, cost),
                    Some(_) => {}
                }
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_shared::scenario::Scenario;
    use dyfos_shared::sdsmm::NoiseModel;
    use dyfos_shared::world::{AxisBox, MapDelta, Obstacle, VoxelBlock};

    /// The grid searched one point at a time with [`Lupp::evaluate`], a cost per
    /// point, then the minimum and the lowest index within 1e-9 of it: SPEC §8 as
    /// plainly as it can be written.
    fn reference(brute: &Brute, lupp: &Lupp, budget: Option<u64>) -> SearchOutcome {
        let n = brute.len().min(budget.map_or(usize::MAX, |b| b as usize));
        let mut stats = EvalStats::default();
        let costs: Vec<f64> = (0..n)
            .map(|i| {
                let e = lupp.evaluate(&brute.point(lupp.space(), i));
                e.count(&mut stats);
                e.cost().filter(|c| !c.is_nan()).unwrap_or(f64::INFINITY)
            })
            .collect();
        let min = costs.iter().copied().fold(f64::INFINITY, f64::min);
        let best = min.is_finite().then(|| {
            let i = costs.iter().position(|c| *c <= min + 1e-9).unwrap();
            Found { x: brute.point(lupp.space(), i), cost: costs[i] }
        });
        let stop = if n < brute.len() { StopReason::Budget } else { StopReason::Finished };
        SearchOutcome { best, stats, stop }
    }

    fn scenario(path: &str) -> Scenario {
        let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data").join(path);
        Scenario::from_json(&std::fs::read_to_string(&file).unwrap()).unwrap()
    }

    /// The golden maps, a map with a box over the rover's shoulder, and one with a
    /// voxel layer around the rover: open and cluttered, obstacles and voxels.
    fn scenarios() -> Vec<(String, Scenario)> {
        let mut all: Vec<(String, Scenario)> = ["example.json", "golden/scenarios/numerical/map_00.json"]
            .into_iter()
            .chain(["golden/scenarios/numerical/map_01.json", "golden/scenarios/hard/hard_00.json"])
            .chain(["golden/scenarios/hard/hard_01.json"])
            .map(|p| (p.to_string(), scenario(p)))
            .collect();
        let mut boxed = scenario("golden/scenarios/numerical/map_02.json");
        let m = boxed.belief.mean;
        let min = Point3::new(m.x + 0.8, m.y - 0.5, 0.0);
        let shoulder = Obstacle::Box(AxisBox { min, max: min + Vector3::new(0.6, 1.5, 1.2) });
        boxed.world = boxed.world.apply(&[MapDelta::UpsertObstacle { id: 900, obstacle: shoulder }]).unwrap();
        all.push(("map_02 + box".into(), boxed));
        let mut voxels = scenario("golden/scenarios/numerical/map_00.json");
        let m = voxels.belief.mean;
        let (cx, cy) = ((m.x / 0.2).floor() as i64, (m.y / 0.2).floor() as i64);
        let cells: Vec<_> = (-15i64..15)
            .flat_map(|i| (-15i64..15).map(move |j| (i, j)))
            .filter(|(i, j)| (i * 7 + j * 13).rem_euclid(5) == 0 && (i.abs() > 2 || j.abs() > 2))
            .map(|(i, j)| [cx + i, cy + j, 2 + (i + j).rem_euclid(6)])
            .collect();
        voxels.world = voxels
            .world
            .apply(&[MapDelta::SetVoxelBlocks {
                resolution: 0.2,
                origin: Point3::origin(),
                blocks: VoxelBlock::from_cells(cells),
                occupied: true,
            }])
            .unwrap();
        all.push(("map_00 + voxels".into(), voxels));
        all
    }

    /// On every map, thread count and budget: the answer and every count are the
    /// per-point search's, bit for bit.
    #[test]
    fn brute_is_the_point_by_point_search_bit_for_bit() {
        let mut all = EvalStats::default();
        for (name, s) in scenarios() {
            let model = NoiseModel::from_params(&s.params).unwrap();
            let lupp = Lupp::new(&s.world, &s.belief, &s.params, &model);
            let brute = Brute { grid: [6, 5, 5, 72] };
            for budget in [None, Some(1000), Some(7777)] {
                let want = reference(&brute, &lupp, budget);
                all += want.stats;
                for threads in [1, 3] {
                    let control = SearchControl { threads, budget, ..SearchControl::seeded(0) };
                    let got = brute.search(&lupp, &control);
                    assert_eq!(got.stats, want.stats, "{name}, budget {budget:?}, {threads} threads");
                    assert_eq!(got.stop, want.stop);
                    let bits = |o: &SearchOutcome| o.best.map(|b| (b.x.to_array().map(f64::to_bits), b.cost.to_bits()));
                    assert_eq!(bits(&got), bits(&want), "{name}, budget {budget:?}, {threads} threads");
                }
            }
        }
        // Every verdict occurs, so every path was compared.
        assert!(all.workspace > 0 && all.collision > 0 && all.occlusion > 0 && all.feasible() > 0, "{all:?}");
    }

    /// The default grid on the most cluttered golden map, where the arcs split most.
    #[test]
    fn the_default_grid_on_a_hard_map_is_the_point_by_point_search() {
        let s = scenario("golden/scenarios/hard/hard_01.json");
        let model = NoiseModel::from_params(&s.params).unwrap();
        let lupp = Lupp::new(&s.world, &s.belief, &s.params, &model);
        let want = reference(&Brute::default(), &lupp, None);
        let got = Brute::default().search(&lupp, &SearchControl { threads: 2, ..SearchControl::seeded(0) });
        assert_eq!(got.stats, want.stats);
        assert!(want.stats.collision > 0 && want.stats.occlusion > 0, "{want:?}");
        assert_eq!(got.best.map(|b| b.cost.to_bits()), want.best.map(|b| b.cost.to_bits()));
        assert_eq!(got.best.map(|b| b.x), want.best.map(|b| b.x));
    }

    /// The plan's points are [`Brute::point`]'s, bit for bit.
    #[test]
    fn the_plan_holds_the_grid_points() {
        let s = scenario("example.json");
        let model = NoiseModel::from_params(&s.params).unwrap();
        let lupp = Lupp::new(&s.world, &s.belief, &s.params, &model);
        let brute = Brute { grid: [3, 4, 5, 7] };
        let plan = Plan::new(&brute, &lupp);
        let [_, np, nf, ny] = brute.grid;
        for i in 0..brute.len() {
            let p = brute.point(lupp.space(), i);
            let q = SensorState {
                rho: plan.rho[i / (ny * nf * np)],
                psi: plan.psi[i / (ny * nf) % np],
                phi: plan.phi[i / ny % nf],
                yaw: plan.frames[i % ny].yaw,
            };
            assert_eq!(p.to_array().map(f64::to_bits), q.to_array().map(f64::to_bits));
        }
    }
}
