//! The evidence for the learned SDSMM: how well a trained model fits the
//! synthetic reference camera it was trained against, and what planning with it is
//! worth when the poses are judged by that reference ("true") camera.
//!
//! - [`held_out_nll`]: mean negative log-likelihood per sample (paper eq. 5 / K) of
//!   each model on data it was not trained on;
//! - [`std_fit`]: relative error of the predicted standard deviations along and
//!   across the line of sight, against the true ones, over held-out features;
//! - [`std_over_image`]: those standard deviations along a line across the image,
//!   for a plot;
//! - [`planning`]: each model plans on the SPEC §10 maps; each answer's pose is then
//!   scored with the true model (its *true* posterior cost).
//!
//! ```
//! use dyfos_bench::learned::{held_out_nll, planning};
//! use dyfos_bench::evaluation::Contender;
//! use dyfos_bench::numerical::{NumericalConfig, numerical_maps};
//! use dyfos_service::learned::{DataSpec, generate};
//! use dyfos_shared::answer::Algorithm;
//! use dyfos_shared::sdsmm::{NoiseModel, Paper, Synthetic};
//!
//! let truth = NoiseModel::Synthetic(Synthetic::default());
//! let models = [("true".to_string(), truth.clone()), ("paper".to_string(), NoiseModel::Paper(Paper))];
//! let data = generate(&DataSpec { samples: 2000, seed: 9, ..DataSpec::default() });
//! let nll = held_out_nll(&models, &data.samples);
//! assert!(nll[0] < nll[1]); // the truth fits its own data best
//!
//! let maps = numerical_maps(3, 2, &NumericalConfig::paper());
//! let run = planning(&maps, &models, &truth, &[Contender::algorithm(Algorithm::Center, 1)], 3, 1);
//! // Planned with the truth, the planned cost is the true cost.
//! assert_eq!(run.true_costs[0][0][0], run.evaluations[0].queries[0][0].cost);
//! ```

use crate::evaluation::{Contender, Evaluation, evaluate_with};
use crate::svg::Series;
use dyfos_service::learned::{Sample, mean_nll};
use dyfos_service::lupp::Lupp;
use dyfos_shared::math::{Point3, Vector2};
use dyfos_shared::params::Params;
use dyfos_shared::scenario::Scenario;
use dyfos_shared::sdsmm::{Features, NoiseModel, Sdsmm};
use dyfos_shared::sensor::{SensorRig, SensorState};
use dyfos_shared::world::Sun;
use std::time::Instant;

/// Mean NLL per sample of each model on `samples`, nats, in the order given.
pub fn held_out_nll(models: &[(String, NoiseModel)], samples: &[Sample]) -> Vec<f64> {
    models.iter().map(|(_, m)| mean_nll(m, samples)).collect()
}

/// Standard deviations (along, across) the horizontal line of sight of R, m.
pub fn principal_std(model: &impl Sdsmm, f: &Features) -> (f64, f64) {
    let r = model.noise(f);
    let (s, c) = f.bearing.sin_cos();
    let along = Vector2::new(c, s);
    let across = Vector2::new(-s, c);
    let m = r.matrix();
    (along.dot(&(m * along)).sqrt(), across.dot(&(m * across)).sqrt())
}

/// How closely `model`'s standard deviations follow `truth`'s on `samples`:
/// `|σ_model/σ_true − 1|` along and across the line of sight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StdFit {
    /// Median relative error along the line of sight.
    pub along_median: f64,
    /// 95th percentile along.
    pub along_p95: f64,
    /// Median relative error across.
    pub across_median: f64,
    /// 95th percentile across.
    pub across_p95: f64,
}

/// The [`StdFit`] of `model` against `truth` over the features of `samples`.
pub fn std_fit(model: &impl Sdsmm, truth: &impl Sdsmm, samples: &[Sample]) -> StdFit {
    let mut along = Vec::with_capacity(samples.len());
    let mut across = Vec::with_capacity(samples.len());
    for s in samples {
        let (ma, mc) = principal_std(model, &s.features);
        let (ta, tc) = principal_std(truth, &s.features);
        along.push((ma / ta - 1.0).abs());
        across.push((mc / tc - 1.0).abs());
    }
    let q = |v: &mut Vec<f64>, p: f64| {
        if v.is_empty() {
            return f64::NAN;
        }
        v.sort_by(f64::total_cmp);
        crate::stats::quantile_sorted(v, p)
    };
    StdFit {
        along_median: q(&mut along, 0.5),
        along_p95: q(&mut along, 0.95),
        across_median: q(&mut across, 0.5),
        across_p95: q(&mut across, 0.95),
    }
}

/// Which line across the image [`std_over_image`] follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageLine {
    /// Left to right through the centre row (φ = 0, u from −1 to 1).
    Horizontal,
    /// Bottom to top through the centre column (ψ = 0, v from −1 to 1).
    Vertical,
}

/// The view of [`std_over_image`]: the rover at the origin heading 0.3 rad, the
/// camera 3.5 m away with the viewer facing +x, the sun at 45° elevation and
/// azimuth 2.5 rad: from u = −1 to u = 1 across the image the glare c grows from 0 to
/// about 0.65.
pub fn image_features(params: &Params, line: ImageLine, points: usize) -> Vec<Features> {
    let rig = SensorRig::new(params);
    let target = Point3::new(0.0, 0.0, params.marker_height);
    let sun = Sun::new(45f64.to_radians(), 2.5).expect("a valid sun").direction();
    (0..points)
        .map(|i| {
            let t = -1.0 + 2.0 * i as f64 / (points.max(2) - 1) as f64;
            let (psi, phi) = match line {
                ImageLine::Horizontal => (t * params.f_h / 2.0, 0.0),
                ImageLine::Vertical => (0.0, t * params.f_v / 2.0),
            };
            let pose = rig.pose(&target, &SensorState::new(3.5, psi, phi, 0.0));
            Features::new(params, &sun, &pose, &target).with_rover_heading(0.3)
        })
        .collect()
}

/// Standard deviations along and across the line of sight as the rover moves along
/// `line` of the image: two series per model (one for an isotropic model). x is u or v.
pub fn std_over_image(models: &[(String, NoiseModel)], params: &Params, line: ImageLine) -> Vec<Series> {
    let features = image_features(params, line, 41);
    let coord = |f: &Features| match line {
        ImageLine::Horizontal => f.u,
        ImageLine::Vertical => f.v,
    };
    let mut series = Vec::new();
    for (name, model) in models {
        let std: Vec<(f64, (f64, f64))> = features.iter().map(|f| (coord(f), principal_std(model, f))).collect();
        if std.iter().all(|(_, (a, c))| (a - c).abs() <= 1e-12 * a.max(*c)) {
            series.push(Series {
                name: format!("{name} (isotropic)"),
                points: std.iter().map(|(x, s)| (*x, s.0)).collect(),
            });
            continue;
        }
        series.push(Series { name: format!("{name}: along"), points: std.iter().map(|(x, s)| (*x, s.0)).collect() });
        series.push(Series { name: format!("{name}: across"), points: std.iter().map(|(x, s)| (*x, s.1)).collect() });
    }
    series
}

/// The outcome of [`planning`].
#[derive(Debug, Clone, PartialEq)]
pub struct Planning {
    /// Planner (model) names.
    pub planners: Vec<String>,
    /// The search run of each planner (contenders × maps).
    pub evaluations: Vec<Evaluation>,
    /// `true_costs[planner][contender][map]`: the true posterior cost of the pose
    /// the planner picked (`None` if it found none).
    pub true_costs: Vec<Vec<Vec<Option<f64>>>>,
}

/// Plans on every map with every model and scores each answer with `truth`.
pub fn planning(
    maps: &[Scenario],
    planners: &[(String, NoiseModel)],
    truth: &NoiseModel,
    contenders: &[Contender],
    seed: u64,
    repeats: usize,
) -> Planning {
    let mut evaluations = Vec::new();
    let mut true_costs = Vec::new();
    for (_, model) in planners {
        let run = evaluate_with(maps, |_| model.clone(), contenders, seed, repeats);
        let costs = run
            .queries
            .iter()
            .map(|row| {
                row.iter()
                    .zip(maps)
                    .map(|(q, s)| {
                        let lupp = Lupp::new(&s.world, &s.belief, &s.params, truth);
                        q.x.filter(|_| q.feasible()).and_then(|x| lupp.evaluate(&x).cost())
                    })
                    .collect()
            })
            .collect();
        evaluations.push(run);
        true_costs.push(costs);
    }
    Planning { planners: planners.iter().map(|(n, _)| n.clone()).collect(), evaluations, true_costs }
}

impl Planning {
    /// Per map, `true cost(planner a) − true cost(planner b)` for contender `c`.
    pub fn gaps(&self, a: usize, b: usize, c: usize) -> Vec<Option<f64>> {
        self.true_costs[a][c].iter().zip(&self.true_costs[b][c]).map(|(x, y)| Some((*x)? - (*y)?)).collect()
    }

    /// Median over maps of planner `p`'s query time with contender `c`, s.
    pub fn median_seconds(&self, p: usize, c: usize) -> f64 {
        let t: Vec<f64> = self.evaluations[p].queries[c].iter().map(|q| q.seconds).collect();
        crate::stats::Summary::of(&t).map_or(f64::NAN, |s| s.median)
    }
}

/// Median nanoseconds per `noise` call of `model`: `features` are timed in batches
/// of 256 calls, `rounds` times over, and the median batch counts. Short batches keep
/// a busy machine's preemptions out of the median.
pub fn noise_nanos(model: &NoiseModel, features: &[Features], rounds: usize) -> f64 {
    let mut per_call = Vec::new();
    for _ in 0..rounds.max(1) {
        for batch in features.chunks(256) {
            let started = Instant::now();
            let mut sink = 0.0;
            for f in batch {
                sink += model.noise(std::hint::black_box(f)).matrix()[(0, 1)];
            }
            std::hint::black_box(sink);
            per_call.push(started.elapsed().as_nanos() as f64 / batch.len() as f64);
        }
    }
    crate::stats::Summary::of(&per_call).map_or(f64::NAN, |s| s.median)
}

#[cfg(test)]
mod tests {
    use super::*;
    use dyfos_shared::sdsmm::{Paper, Synthetic};

    #[test]
    fn image_lines_cross_the_whole_image() {
        let p = Params::default();
        let h = image_features(&p, ImageLine::Horizontal, 5);
        assert!((h[0].u + 1.0).abs() < 1e-9 && (h[4].u - 1.0).abs() < 1e-9 && h[2].u.abs() < 1e-12);
        assert!(h.iter().all(|f| f.v.abs() < 1e-12));
        let v = image_features(&p, ImageLine::Vertical, 5);
        assert!((v[0].v + 1.0).abs() < 1e-9 && (v[4].v - 1.0).abs() < 1e-9);
        // From u = −1 to u = 1 the view swings into the sun's reflection lobe.
        let c: Vec<f64> = h.iter().map(|f| f.c).collect();
        assert!(c[0] == 0.0 && c[4] > 0.5, "glare across the plotted line: {c:?}");
    }

    #[test]
    fn principal_std_reads_the_true_axes() {
        let p = Params::default();
        let truth = Synthetic::default();
        for f in image_features(&p, ImageLine::Horizontal, 7) {
            let (a, c) = principal_std(&truth, &f);
            let (va, vc) = truth.principal_variances(&f);
            assert!((a * a - va).abs() < 1e-12 && (c * c - vc).abs() < 1e-12);
        }
    }

    #[test]
    fn std_fit_is_zero_for_the_truth_and_not_for_paper() {
        let data = dyfos_service::learned::generate(&dyfos_service::learned::DataSpec {
            samples: 500,
            seed: 4,
            ..Default::default()
        });
        let truth = Synthetic::default();
        let own = std_fit(&truth, &truth, &data.samples);
        assert_eq!((own.along_p95, own.across_p95), (0.0, 0.0));
        let paper = std_fit(&Paper, &truth, &data.samples);
        assert!(paper.along_median > 0.2, "{paper:?}");
    }
}
