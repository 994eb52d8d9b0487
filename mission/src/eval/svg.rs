//! A picture of one mission in the style of paper Fig. 5: the obstacles, the true
//! path (dashed), the estimated path coloured by its error, the viewer's poses with
//! their lines of sight, the measurement covariances R and the rover's posterior
//! covariance after each update (both as 2σ ellipses), over x and y axes with
//! ticks and a grid in metres.

use super::MissionTrace;
use dyfos_shared::wire::mission::Observation;
use dyfos_shared::world::{Obstacle, World};
use std::fmt::Write;

const WIDTH: f64 = 720.0;
const MARGIN: f64 = 20.0;
const BAR: f64 = 170.0;
const TITLE: f64 = 34.0;
/// Room left of the map for the y ticks' labels and the axis name.
const LEFT: f64 = 58.0;
/// Room below the map for the x ticks' labels and the axis name.
const BOTTOM: f64 = 46.0;
/// Length of a tick mark, outside the map.
const TICK: f64 = 5.0;
/// Most intervals between ticks along an axis.
const MAX_TICKS: f64 = 10.0;

/// Viridis, sampled at 0, ¼, ½, ¾, 1.
const VIRIDIS: [[f64; 3]; 5] =
    [[68.0, 1.0, 84.0], [59.0, 82.0, 139.0], [33.0, 145.0, 140.0], [94.0, 201.0, 98.0], [253.0, 231.0, 37.0]];

fn colour(a: f64) -> String {
    let a = a.clamp(0.0, 1.0) * 4.0;
    let i = (a.floor() as usize).min(3);
    let f = a - i as f64;
    let c: [f64; 3] = std::array::from_fn(|k| VIRIDIS[i][k] + f * (VIRIDIS[i + 1][k] - VIRIDIS[i][k]));
    format!("rgb({:.0},{:.0},{:.0})", c[0], c[1], c[2])
}

struct Frame {
    x0: f64,
    y1: f64,
    scale: f64,
}

impl Frame {
    fn x(&self, x: f64) -> f64 {
        LEFT + (x - self.x0) * self.scale
    }
    fn y(&self, y: f64) -> f64 {
        TITLE + MARGIN + (self.y1 - y) * self.scale
    }
}

/// A round distance between ticks — 1, 2 or 5 × 10ᵏ m — giving at most
/// [`MAX_TICKS`] intervals over `span` m.
fn tick_step(span: f64) -> f64 {
    let raw = span / MAX_TICKS;
    let power = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0].into_iter().map(|m| m * power).find(|s| *s >= raw * (1.0 - 1e-9)).unwrap_or(10.0 * power)
}

/// The multiples of `step` within [`lo`, `hi`], labelled with the decimals the step needs.
fn ticks(lo: f64, hi: f64, step: f64) -> Vec<(f64, String)> {
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    let (first, last) = ((lo / step - 1e-9).ceil() as i64, (hi / step + 1e-9).floor() as i64);
    (first..=last)
        .map(|k| {
            let v = k as f64 * step;
            // No "-0" label.
            let label = format!("{:.*}", decimals, if k == 0 { 0.0 } else { v });
            (v, label)
        })
        .collect()
}

/// The grid, the ticks and their labels along the map's bottom and left edges,
/// and the axes' names.
fn axes(s: &mut String, f: &Frame, b: &dyfos_shared::world::Bounds) {
    let step = tick_step((b.max.x - b.min.x).max(b.max.y - b.min.y));
    let (left, right, top, bottom) = (f.x(b.min.x), f.x(b.max.x), f.y(b.max.y), f.y(b.min.y));
    for (x, label) in ticks(b.min.x, b.max.x, step) {
        let px = f.x(x);
        let _ = writeln!(
            s,
            r##"<line x1="{px:.2}" y1="{top:.2}" x2="{px:.2}" y2="{bottom:.2}" stroke="#ececec"/><line x1="{px:.2}" y1="{bottom:.2}" x2="{px:.2}" y2="{:.2}" stroke="#555"/><text class="xtick" x="{px:.2}" y="{:.2}" text-anchor="middle" fill="#333">{label}</text>"##,
            bottom + TICK,
            bottom + TICK + 13.0
        );
    }
    for (y, label) in ticks(b.min.y, b.max.y, step) {
        let py = f.y(y);
        let _ = writeln!(
            s,
            r##"<line x1="{left:.2}" y1="{py:.2}" x2="{right:.2}" y2="{py:.2}" stroke="#ececec"/><line x1="{:.2}" y1="{py:.2}" x2="{left:.2}" y2="{py:.2}" stroke="#555"/><text class="ytick" x="{:.2}" y="{:.2}" text-anchor="end" fill="#333">{label}</text>"##,
            left - TICK,
            left - TICK - 3.0,
            py + 4.0
        );
    }
    let _ = writeln!(
        s,
        r##"<text x="{:.2}" y="{:.2}" text-anchor="middle" fill="#333">x (m)</text><text x="16" y="{:.2}" text-anchor="middle" fill="#333" transform="rotate(-90 16 {:.2})">y (m)</text>"##,
        (left + right) / 2.0,
        bottom + TICK + 32.0,
        (top + bottom) / 2.0,
        (top + bottom) / 2.0
    );
}

/// The 2σ ellipse of a 2×2 covariance `[[a, b], [b, c]]` at (x, y), as SVG.
fn ellipse(f: &Frame, x: f64, y: f64, cov: [[f64; 2]; 2], style: &str) -> String {
    let (a, b, c) = (cov[0][0], cov[0][1], cov[1][1]);
    let mid = (a + c) / 2.0;
    let half = (((a - c) / 2.0).powi(2) + b * b).sqrt();
    let (l1, l2) = ((mid + half).max(0.0), (mid - half).max(0.0));
    let angle = 0.5 * (2.0 * b).atan2(a - c);
    format!(
        r#"<ellipse cx="{:.2}" cy="{:.2}" rx="{:.2}" ry="{:.2}" transform="rotate({:.2} {:.2} {:.2})" {style}/>"#,
        f.x(x),
        f.y(y),
        2.0 * l1.sqrt() * f.scale,
        2.0 * l2.sqrt() * f.scale,
        -angle.to_degrees(),
        f.x(x),
        f.y(y),
    )
}

/// Renders `trace` of a mission over `world` with its `waypoints` as an SVG
/// document headed by `title`.
pub fn render_svg(world: &World, waypoints: &[[f64; 2]], trace: &MissionTrace, title: &str) -> String {
    let b = world.bounds();
    let scale = (WIDTH - LEFT - MARGIN) / (b.max.x - b.min.x);
    let f = Frame { x0: b.min.x, y1: b.max.y, scale };
    let height = TITLE + MARGIN + (b.max.y - b.min.y) * scale + BOTTOM;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{:.0}" height="{height:.0}" viewBox="0 0 {:.0} {height:.0}" font-family="sans-serif" font-size="12">"#,
        WIDTH + BAR,
        WIDTH + BAR
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(s, r#"<text x="{MARGIN}" y="22" font-size="16">{}</text>"#, escape(title));
    axes(&mut s, &f, b);
    let _ = writeln!(
        s,
        r##"<rect x="{:.2}" y="{:.2}" width="{:.2}" height="{:.2}" fill="none" stroke="#888"/>"##,
        f.x(b.min.x),
        f.y(b.max.y),
        (b.max.x - b.min.x) * scale,
        (b.max.y - b.min.y) * scale
    );
    for o in world.obstacles().values() {
        match o {
            Obstacle::Cylinder(c) => {
                let _ = writeln!(
                    s,
                    r##"<circle cx="{:.2}" cy="{:.2}" r="{:.2}" fill="#6a9f58" stroke="#3d6b31"/>"##,
                    f.x(c.center.x),
                    f.y(c.center.y),
                    c.radius * scale
                );
            }
            Obstacle::Box(bx) => {
                let _ = writeln!(
                    s,
                    r##"<rect x="{:.2}" y="{:.2}" width="{:.2}" height="{:.2}" fill="#8c7b5e" stroke="#5e513b"/>"##,
                    f.x(bx.min.x),
                    f.y(bx.max.y),
                    (bx.max.x - bx.min.x) * scale,
                    (bx.max.y - bx.min.y) * scale
                );
            }
        }
    }
    for (i, w) in waypoints.iter().enumerate() {
        let (x, y) = (f.x(w[0]), f.y(w[1]));
        let _ = writeln!(
            s,
            r##"<path d="M{:.2} {:.2}l8 8m0 -8l-8 8" stroke="#222" stroke-width="1.5"/><text x="{:.2}" y="{:.2}" fill="#222">{}</text>"##,
            x - 4.0,
            y - 4.0,
            x + 6.0,
            y - 6.0,
            i + 1
        );
    }

    let pairs = trace.pairs();
    let errors = trace.errors();
    let top = errors.iter().copied().fold(0.0_f64, f64::max).max(0.01);
    // True path, dashed.
    let truth: Vec<String> =
        pairs.iter().map(|(t, _)| format!("{:.2},{:.2}", f.x(t.pose[0]), f.y(t.pose[1]))).collect();
    if !truth.is_empty() {
        let _ = writeln!(
            s,
            r##"<polyline points="{}" fill="none" stroke="#333" stroke-width="1.5" stroke-dasharray="6 4"/>"##,
            truth.join(" ")
        );
    }
    // Estimated path, each segment coloured by its error.
    for (k, w) in pairs.windows(2).enumerate() {
        let (e0, e1) = (&w[0].1.belief.mean, &w[1].1.belief.mean);
        let err = (errors[k] + errors[k + 1]) / 2.0;
        let _ = writeln!(
            s,
            r#"<line x1="{:.2}" y1="{:.2}" x2="{:.2}" y2="{:.2}" stroke="{}" stroke-width="3" stroke-linecap="round"/>"#,
            f.x(e0.x),
            f.y(e0.y),
            f.x(e1.x),
            f.y(e1.y),
            colour(err / top)
        );
    }
    // Posterior covariance after each update.
    for (_, e) in pairs.iter().filter(|(_, e)| e.updated) {
        let c = e.belief.cov.matrix();
        let cov = [[c[(0, 0)], c[(0, 1)]], [c[(1, 0)], c[(1, 1)]]];
        let _ = writeln!(
            s,
            "{}",
            ellipse(
                &f,
                e.belief.mean.x,
                e.belief.mean.y,
                cov,
                r##"fill="none" stroke="#7b3294" stroke-dasharray="3 2""##
            )
        );
    }
    // Viewer poses, lines of sight and measurement covariances.
    for m in &trace.measurements {
        let Some(v) = m.viewer else { continue };
        let (vx, vy) = (f.x(v.position[0]), f.y(v.position[1]));
        if let Observation::Observed { position, r } = &m.observation {
            let _ = writeln!(
                s,
                r##"<line x1="{vx:.2}" y1="{vy:.2}" x2="{:.2}" y2="{:.2}" stroke="#2b83ba" stroke-width="0.8" stroke-dasharray="2 2"/>"##,
                f.x(position[0]),
                f.y(position[1])
            );
            let _ = writeln!(
                s,
                "{}",
                ellipse(
                    &f,
                    position[0],
                    position[1],
                    r.to_rows(),
                    r##"fill="#fdae61" fill-opacity="0.35" stroke="#d7191c""##
                )
            );
        }
        let (sy, cy) = v.yaw.sin_cos();
        let tip = |d: f64, side: f64| (vx + (cy * d - sy * side) * 1.0, vy - (sy * d + cy * side));
        let (a, bb, c) = (tip(11.0, 0.0), tip(-6.0, 6.0), tip(-6.0, -6.0));
        let fill = if matches!(m.observation, Observation::Observed { .. }) { "#2b83ba" } else { "#bbbbbb" };
        let _ = writeln!(
            s,
            r##"<polygon points="{:.2},{:.2} {:.2},{:.2} {:.2},{:.2}" fill="{fill}" stroke="#124"/><text x="{:.2}" y="{:.2}" font-size="10" fill="#124">{}</text>"##,
            a.0,
            a.1,
            bb.0,
            bb.1,
            c.0,
            c.1,
            vx + 8.0,
            vy + 12.0,
            m.step
        );
    }
    // Colour bar.
    let (bx, by, bh) = (WIDTH + 20.0, TITLE + MARGIN + 20.0, 240.0);
    let _ = writeln!(s, r#"<text x="{bx:.2}" y="{:.2}">error (cm)</text>"#, by - 8.0);
    for i in 0..48 {
        let a = 1.0 - i as f64 / 47.0;
        let _ = writeln!(
            s,
            r#"<rect x="{bx:.2}" y="{:.2}" width="18" height="{:.2}" fill="{}"/>"#,
            by + i as f64 * bh / 48.0,
            bh / 48.0 + 0.5,
            colour(a)
        );
    }
    for k in 0..=4 {
        let a = k as f64 / 4.0;
        let _ = writeln!(
            s,
            r#"<text x="{:.2}" y="{:.2}">{:.1}</text>"#,
            bx + 24.0,
            by + (1.0 - a) * bh + 4.0,
            a * top * 100.0
        );
    }
    let legend = [
        ("#333", "true path (dashed)"),
        ("#21918c", "estimate (by error)"),
        ("#2b83ba", "viewer pose"),
        ("#d7191c", "R (2σ)"),
        ("#7b3294", "Σ⁺ (2σ)"),
    ];
    for (i, (c, text)) in legend.iter().enumerate() {
        let y = by + bh + 30.0 + i as f64 * 18.0;
        let _ = writeln!(
            s,
            r#"<rect x="{bx:.2}" y="{:.2}" width="10" height="10" fill="{c}"/><text x="{:.2}" y="{:.2}" font-size="10">{text}</text>"#,
            y - 9.0,
            bx + 14.0,
            y
        );
    }
    s.push_str("</svg>\n");
    s
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mission::Mission;
    use dyfos_shared::math::Cov2;
    use dyfos_shared::posterior::Belief;
    use dyfos_shared::wire::mission::{Estimate, Measurement, Phase, TrueState, ViewerPose};

    #[test]
    fn draws_every_element() {
        let m = Mission::builtin();
        let b = Belief::new([0.0, 0.0, 0.0], [[0.01, 0.0, 0.0], [0.0, 0.02, 0.0], [0.0, 0.0, 0.01]]).unwrap();
        let mut trace = MissionTrace::default();
        for i in 0..3u64 {
            let x = i as f64;
            trace.truth.push(TrueState { sample: i, step: 1, phase: Phase::Driving, sim_time: x, pose: [x, 0.1, 0.0] });
            let belief = Belief { mean: nalgebra::Vector3::new(x, 0.0, 0.0), ..b };
            trace.estimates.push(Estimate {
                sample: i,
                step: 1,
                phase: Phase::Driving,
                updated: i == 2,
                sim_time: x,
                belief,
            });
        }
        trace.measurements.push(Measurement {
            step: 1,
            sim_time: 2.0,
            observation: Observation::Observed {
                position: [2.0, 0.05],
                r: Cov2::from_rows(&[[0.01, 0.0], [0.0, 0.01]]).unwrap(),
            },
            viewer: Some(ViewerPose { position: [0.0, -3.0, 3.0], yaw: 1.0 }),
            predicted_cost: Some(-10.0),
        });
        let svg = render_svg(&m.world, &m.waypoints, &trace, "test <run>");
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>\n"));
        assert_eq!(svg.matches("<circle").count(), 25);
        assert_eq!(svg.matches("<polyline").count(), 1);
        assert_eq!(svg.matches("stroke-linecap").count(), 2, "one segment per pair of samples");
        assert_eq!(svg.matches("<ellipse").count(), 2, "R and Σ⁺");
        assert_eq!(svg.matches("<polygon").count(), 1);
        assert!(svg.contains("test &lt;run&gt;"));
    }

    /// The value and position of each tick label of class `class`.
    fn labels(svg: &str, class: &str, position: &str) -> Vec<(f64, f64)> {
        svg.split(&format!(r#"<text class="{class}" "#))
            .skip(1)
            .map(|rest| {
                let at = rest.split(&format!(r#"{position}=""#)).nth(1).unwrap().split('"').next().unwrap();
                let value = rest.split('>').nth(1).unwrap().split('<').next().unwrap();
                (value.parse().unwrap(), at.parse().unwrap())
            })
            .collect()
    }

    #[test]
    fn axes_are_ticked_in_metres_where_the_map_is() {
        let m = Mission::builtin();
        let svg = render_svg(&m.world, &m.waypoints, &MissionTrace::default(), "axes");
        let b = m.world.bounds();
        let scale = (WIDTH - LEFT - MARGIN) / (b.max.x - b.min.x);
        let f = Frame { x0: b.min.x, y1: b.max.y, scale };
        // The built-in world spans 20 m: a tick every 2 m, from edge to edge.
        let expected: Vec<f64> = (-5..=5).map(|k| 2.0 * k as f64).collect();
        for (class, position) in [("xtick", "x"), ("ytick", "y")] {
            let ticks = labels(&svg, class, position);
            assert_eq!(ticks.iter().map(|t| t.0).collect::<Vec<_>>(), expected, "{class}");
            for (metres, at) in ticks {
                // A label sits at its own coordinate (y labels 4 px below, to centre the text).
                let want = if class == "xtick" { f.x(metres) } else { f.y(metres) + 4.0 };
                assert!((at - want).abs() < 0.01, "{class} {metres} m at {at}, not {want}");
            }
        }
        assert!(svg.contains(">x (m)</text>") && svg.contains(">y (m)</text>"));
        // Steps are round and labels carry the decimals they need.
        assert_eq!(tick_step(16.0), 2.0);
        assert_eq!(tick_step(3.0), 0.5);
        assert_eq!(tick_step(100.0), 10.0);
        assert_eq!(ticks(-0.6, 0.6, 0.5).into_iter().map(|t| t.1).collect::<Vec<_>>(), ["-0.5", "0.0", "0.5"]);
    }
}
