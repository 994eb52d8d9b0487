//! Plain SVG plots for benchmark reports: violins (the paper's Fig. 4) and lines.
//!
//! Written by hand, not with a plotting crate: the two plot kinds need a few dozen
//! SVG elements, and no plotting crate draws violins anyway.
//!
//! ```
//! use dyfos_bench::svg::{Series, ViolinPlot, line_plot};
//!
//! let plot = ViolinPlot {
//!     title: "E per algorithm".into(),
//!     y_label: "E = ln det Σ⁺".into(),
//!     groups: vec![("dyfos".into(), vec![-15.8, -15.6, -15.7]), ("random".into(), vec![-14.0, -12.5, -13.1])],
//! };
//! let svg = plot.to_svg();
//! assert!(svg.starts_with("<svg") && svg.contains("dyfos") && svg.contains("<polygon"));
//! let lines = line_plot("time", "obstacles", "µs", &[Series { name: "cylinders".into(), points: vec![(25.0, 500.0), (100.0, 600.0)] }], true);
//! assert!(lines.contains("<polyline"));
//! ```

use crate::stats::{Summary, kde};
use std::fmt::Write;

const WIDTH: f64 = 720.0;
const HEIGHT: f64 = 440.0;
const LEFT: f64 = 80.0;
const RIGHT: f64 = 20.0;
const TOP: f64 = 40.0;
const BOTTOM: f64 = 60.0;
const COLORS: [&str; 8] = ["#4477aa", "#ee6677", "#228833", "#ccbb44", "#66ccee", "#aa3377", "#bbbbbb", "#000000"];

/// Escapes text for SVG.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// About `n` round tick values covering [lo, hi].
fn ticks(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let span = (hi - lo).max(1e-12);
    let raw = span / n.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0].iter().map(|m| m * mag).find(|s| *s >= raw).unwrap_or(10.0 * mag);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(|i| i as f64 * step).collect()
}

/// Formats a tick label without float noise.
fn label(v: f64) -> String {
    let s = format!("{:.6}", v);
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

/// Opens an SVG document with a white background, title and axis labels.
fn frame(out: &mut String, title: &str, x_label: &str, y_label: &str) {
    let _ = write!(
        out,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{HEIGHT}" viewBox="0 0 {WIDTH} {HEIGHT}" font-family="sans-serif" font-size="12">
<rect width="100%" height="100%" fill="white"/>
<text x="{}" y="22" text-anchor="middle" font-size="15">{}</text>
<text x="{}" y="{}" text-anchor="middle">{}</text>
<text transform="translate(18 {}) rotate(-90)" text-anchor="middle">{}</text>
"#,
        WIDTH / 2.0,
        esc(title),
        LEFT + (WIDTH - LEFT - RIGHT) / 2.0,
        HEIGHT - 12.0,
        esc(x_label),
        TOP + (HEIGHT - TOP - BOTTOM) / 2.0,
        esc(y_label)
    );
}

/// A linear or logarithmic axis mapping data to pixels.
#[derive(Clone, Copy)]
struct Axis {
    lo: f64,
    hi: f64,
    px_lo: f64,
    px_hi: f64,
    log: bool,
}

impl Axis {
    fn map(&self, v: f64) -> f64 {
        let (v, lo, hi) = if self.log { (v.log10(), self.lo.log10(), self.hi.log10()) } else { (v, self.lo, self.hi) };
        self.px_lo + (v - lo) / (hi - lo).max(1e-300) * (self.px_hi - self.px_lo)
    }

    fn ticks(&self) -> Vec<f64> {
        if !self.log {
            return ticks(self.lo, self.hi, 8);
        }
        let (a, b) = (self.lo.log10().floor() as i32, self.hi.log10().ceil() as i32);
        let mut t = Vec::new();
        for e in a..=b {
            for m in [1.0, 2.0, 5.0] {
                let v = m * 10f64.powi(e);
                if v >= self.lo * 0.999 && v <= self.hi * 1.001 {
                    t.push(v);
                }
            }
        }
        t
    }
}

/// Horizontal grid lines and labels for the y axis.
fn y_grid(out: &mut String, y: &Axis) {
    for t in y.ticks() {
        let py = y.map(t);
        let _ = writeln!(
            out,
            r##"<line x1="{LEFT}" x2="{}" y1="{py:.1}" y2="{py:.1}" stroke="#e0e0e0"/><text x="{}" y="{:.1}" text-anchor="end">{}</text>"##,
            WIDTH - RIGHT,
            LEFT - 6.0,
            py + 4.0,
            label(t)
        );
    }
    let _ = writeln!(
        out,
        r#"<rect x="{LEFT}" y="{TOP}" width="{}" height="{}" fill="none" stroke="black"/>"#,
        WIDTH - LEFT - RIGHT,
        HEIGHT - TOP - BOTTOM
    );
}

/// One violin per group, as in the paper's Fig. 4: a mirrored kernel density
/// estimate, notches at the extrema and the median, and the samples as dots.
#[derive(Debug, Clone, PartialEq)]
pub struct ViolinPlot {
    /// Plot title.
    pub title: String,
    /// Label of the value axis.
    pub y_label: String,
    /// (name, values) per violin, left to right. Empty groups are drawn as a name only.
    pub groups: Vec<(String, Vec<f64>)>,
}

impl ViolinPlot {
    /// The plot as a standalone SVG document.
    pub fn to_svg(&self) -> String {
        let all: Vec<f64> = self.groups.iter().flat_map(|(_, v)| v.iter().copied()).collect();
        let (mut lo, mut hi) = all.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(*v), b.max(*v)));
        if !lo.is_finite() {
            (lo, hi) = (0.0, 1.0);
        }
        let pad = ((hi - lo) * 0.05).max(1e-3);
        let y = Axis { lo: lo - pad, hi: hi + pad, px_lo: HEIGHT - BOTTOM, px_hi: TOP, log: false };
        let mut out = String::new();
        frame(&mut out, &self.title, "", &self.y_label);
        y_grid(&mut out, &y);
        let n = self.groups.len().max(1) as f64;
        let slot = (WIDTH - LEFT - RIGHT) / n;
        let half = slot * 0.38;
        for (g, (name, values)) in self.groups.iter().enumerate() {
            let cx = LEFT + slot * (g as f64 + 0.5);
            let color = COLORS[g % COLORS.len()];
            let _ = writeln!(
                out,
                r#"<text x="{cx:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
                HEIGHT - BOTTOM + 18.0,
                esc(name)
            );
            let Some(s) = Summary::of(values) else { continue };
            let curve = kde(values, s.min, s.max, 64);
            let peak = curve.iter().map(|(_, d)| *d).fold(0.0, f64::max);
            if peak > 0.0 && s.max > s.min {
                let mut pts = String::new();
                for (v, d) in curve.iter() {
                    let _ = write!(pts, "{:.1},{:.1} ", cx + half * d / peak, y.map(*v));
                }
                for (v, d) in curve.iter().rev() {
                    let _ = write!(pts, "{:.1},{:.1} ", cx - half * d / peak, y.map(*v));
                }
                let _ = writeln!(
                    out,
                    r#"<polygon points="{}" fill="{color}" fill-opacity="0.35" stroke="{color}"/>"#,
                    pts.trim_end()
                );
            }
            let _ = writeln!(
                out,
                r#"<line x1="{cx:.1}" x2="{cx:.1}" y1="{:.1}" y2="{:.1}" stroke="{color}" stroke-width="1.5"/>"#,
                y.map(s.min),
                y.map(s.max)
            );
            for (v, w) in [(s.min, 0.35), (s.median, 0.6), (s.max, 0.35)] {
                let _ = writeln!(
                    out,
                    r#"<line x1="{:.1}" x2="{:.1}" y1="{py:.1}" y2="{py:.1}" stroke="{color}" stroke-width="2"/>"#,
                    cx - half * w,
                    cx + half * w,
                    py = y.map(v)
                );
            }
            for (k, v) in values.iter().enumerate() {
                // Deterministic jitter so equal values stay visible.
                let jitter = ((k as f64 * 0.618_033_988_75).fract() - 0.5) * half * 0.5;
                let _ = writeln!(
                    out,
                    r#"<circle cx="{:.1}" cy="{:.1}" r="2" fill="{color}" fill-opacity="0.8"/>"#,
                    cx + jitter,
                    y.map(*v)
                );
            }
        }
        out.push_str("</svg>\n");
        out
    }
}

/// One line of a [`line_plot`].
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend entry.
    pub name: String,
    /// (x, y) points, drawn in order.
    pub points: Vec<(f64, f64)>,
}

/// Lines with markers, log-log when `log` is set (non-positive values are dropped then).
pub fn line_plot(title: &str, x_label: &str, y_label: &str, series: &[Series], log: bool) -> String {
    let keep = |v: f64| v.is_finite() && (!log || v > 0.0);
    let pts: Vec<(f64, f64)> =
        series.iter().flat_map(|s| s.points.iter().copied()).filter(|(x, y)| keep(*x) && keep(*y)).collect();
    let range = |f: fn(&(f64, f64)) -> f64| {
        let (lo, hi) = pts.iter().map(f).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
        if !lo.is_finite() {
            (1.0, 10.0)
        } else if log {
            (lo / 1.5, hi * 1.5)
        } else {
            let pad = ((hi - lo) * 0.05).max(1e-9);
            ((lo - pad).min(0.0), hi + pad)
        }
    };
    let (xl, xh) = range(|p| p.0);
    let (yl, yh) = range(|p| p.1);
    let x = Axis { lo: xl, hi: xh, px_lo: LEFT, px_hi: WIDTH - RIGHT, log };
    let y = Axis { lo: yl, hi: yh, px_lo: HEIGHT - BOTTOM, px_hi: TOP, log };
    let mut out = String::new();
    frame(&mut out, title, x_label, y_label);
    y_grid(&mut out, &y);
    for t in x.ticks() {
        let px = x.map(t);
        let _ = writeln!(
            out,
            r##"<line x1="{px:.1}" x2="{px:.1}" y1="{TOP}" y2="{}" stroke="#f0f0f0"/><text x="{px:.1}" y="{}" text-anchor="middle">{}</text>"##,
            HEIGHT - BOTTOM,
            HEIGHT - BOTTOM + 16.0,
            label(t)
        );
    }
    for (i, s) in series.iter().enumerate() {
        let color = COLORS[i % COLORS.len()];
        let line: Vec<String> = s
            .points
            .iter()
            .filter(|(a, b)| keep(*a) && keep(*b))
            .map(|(a, b)| format!("{:.1},{:.1}", x.map(*a), y.map(*b)))
            .collect();
        let _ =
            writeln!(out, r#"<polyline points="{}" fill="none" stroke="{color}" stroke-width="2"/>"#, line.join(" "));
        for p in &line {
            let (a, b) = p.split_once(',').expect("x,y");
            let _ = writeln!(out, r#"<circle cx="{a}" cy="{b}" r="3.5" fill="{color}"/>"#);
        }
        let ly = TOP + 18.0 + 16.0 * i as f64;
        let _ = writeln!(
            out,
            r#"<line x1="{:.1}" x2="{:.1}" y1="{ly:.1}" y2="{ly:.1}" stroke="{color}" stroke-width="2"/><text x="{:.1}" y="{:.1}">{}</text>"#,
            LEFT + 12.0,
            LEFT + 32.0,
            LEFT + 38.0,
            ly + 4.0,
            esc(&s.name)
        );
    }
    out.push_str("</svg>\n");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_and_cover_the_range() {
        assert_eq!(ticks(0.0, 10.0, 5), vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        let t = ticks(-15.83, -12.1, 8);
        assert!(t.first().unwrap() >= &-15.83 && t.last().unwrap() <= &-12.1 && t.len() >= 4, "{t:?}");
        assert_eq!(label(-0.0), "0");
        assert_eq!(label(2.5), "2.5");
    }

    #[test]
    fn violin_marks_the_median_and_extrema() {
        let plot =
            ViolinPlot { title: "t".into(), y_label: "E".into(), groups: vec![("a".into(), vec![0.0, 1.0, 4.0])] };
        let svg = plot.to_svg();
        // Value axis from −0.2 to 4.2 over pixels 380 → 40: the median 1 sits at 287.3.
        assert!(svg.contains(r##"y1="287.3" y2="287.3" stroke="#4477aa" stroke-width="2""##), "{svg}");
        assert_eq!(svg.matches("<circle").count(), 3);
        assert_eq!(svg.matches("stroke-width=\"2\"/>").count(), 3);
    }
}
