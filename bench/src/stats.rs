//! Summary statistics and density estimates for benchmark tables and plots.
//!
//! ```
//! use dyfos_bench::stats::Summary;
//!
//! let s = Summary::of(&[3.0, 1.0, 2.0, 10.0]).unwrap();
//! assert_eq!((s.min, s.median, s.max, s.mean), (1.0, 2.5, 10.0, 4.0));
//! assert!(Summary::of(&[]).is_none());
//! ```

/// Order statistics, mean and standard deviation of a sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Summary {
    /// Sample size.
    pub count: usize,
    /// Smallest value.
    pub min: f64,
    /// First quartile (linear interpolation, as numpy's default).
    pub q1: f64,
    /// Median.
    pub median: f64,
    /// Third quartile.
    pub q3: f64,
    /// Largest value.
    pub max: f64,
    /// Arithmetic mean.
    pub mean: f64,
    /// Sample standard deviation (n − 1); 0 for one value.
    pub std: f64,
}

/// The `p`-quantile (0 ≤ p ≤ 1) of sorted values, linearly interpolated.
pub fn quantile_sorted(sorted: &[f64], p: f64) -> f64 {
    let n = sorted.len();
    assert!(n > 0, "quantile of an empty sample");
    let h = p.clamp(0.0, 1.0) * (n - 1) as f64;
    let (lo, frac) = (h.floor() as usize, h - h.floor());
    if lo + 1 < n { sorted[lo] + frac * (sorted[lo + 1] - sorted[lo]) } else { sorted[lo] }
}

impl Summary {
    /// The summary of `values` (NaNs are a caller bug); `None` for no values.
    pub fn of(values: &[f64]) -> Option<Self> {
        if values.is_empty() {
            return None;
        }
        let mut v = values.to_vec();
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let mean = v.iter().sum::<f64>() / n as f64;
        let var = if n > 1 { v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1) as f64 } else { 0.0 };
        Some(Summary {
            count: n,
            min: v[0],
            q1: quantile_sorted(&v, 0.25),
            median: quantile_sorted(&v, 0.5),
            q3: quantile_sorted(&v, 0.75),
            max: v[n - 1],
            mean,
            std: var.sqrt(),
        })
    }
}

/// A Gaussian kernel density estimate with Silverman's bandwidth, evaluated at
/// `points` evenly spaced values over `[lo, hi]`; returns `(value, density)` pairs.
/// A sample with no spread gets a bandwidth of 1 % of `hi − lo` (or 1e-3).
pub fn kde(values: &[f64], lo: f64, hi: f64, points: usize) -> Vec<(f64, f64)> {
    let Some(s) = Summary::of(values) else {
        return Vec::new();
    };
    let spread = s.std.min((s.q3 - s.q1) / 1.34);
    let spread = if spread > 0.0 { spread } else { s.std };
    let mut h = 0.9 * spread * (s.count as f64).powf(-0.2);
    if h <= 0.0 || !h.is_finite() {
        h = ((hi - lo) * 0.01).max(1e-3);
    }
    let norm = 1.0 / (values.len() as f64 * h * (2.0 * std::f64::consts::PI).sqrt());
    (0..points)
        .map(|i| {
            let x = if points > 1 { lo + (hi - lo) * i as f64 / (points - 1) as f64 } else { 0.5 * (lo + hi) };
            let d: f64 = values.iter().map(|v| (-0.5 * ((x - v) / h).powi(2)).exp()).sum();
            (x, d * norm)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_match_numpy() {
        // numpy.percentile([1, 2, 3, 4, 10], [25, 50, 75]) = [2, 3, 4].
        let s = Summary::of(&[10.0, 4.0, 3.0, 2.0, 1.0]).unwrap();
        assert_eq!((s.q1, s.median, s.q3), (2.0, 3.0, 4.0));
        // Sample std of 1..=5 is sqrt(2.5).
        let s = Summary::of(&[1.0, 2.0, 3.0, 4.0, 5.0]).unwrap();
        assert!((s.std - 2.5f64.sqrt()).abs() < 1e-15);
        assert_eq!(Summary::of(&[7.0]).unwrap().std, 0.0);
    }

    #[test]
    fn kde_integrates_to_about_one() {
        let values: Vec<f64> = (0..50).map(|i| (i as f64 * 0.37).sin()).collect();
        let curve = kde(&values, -4.0, 4.0, 801);
        let step = 8.0 / 800.0;
        let area: f64 = curve.iter().map(|(_, d)| d * step).sum();
        assert!((area - 1.0).abs() < 0.01, "{area}");
        let flat = kde(&[2.0, 2.0], 0.0, 4.0, 5);
        assert!(flat[2].1 > flat[0].1 && flat[0].1 >= 0.0);
    }
}
