//! `dyfos-bench learned`: the learned SDSMM against the synthetic reference camera it
//! was trained on: held-out NLL, fit of the standard deviations (with plots
//! across the image), planning quality on the SPEC §10 maps judged by the true model,
//! and query time.

use anyhow::Context;
use dyfos_bench::evaluation::{Contender, duration};
use dyfos_bench::learned::{ImageLine, held_out_nll, noise_nanos, planning, std_fit, std_over_image};
use dyfos_bench::numerical::{NumericalConfig, numerical_maps};
use dyfos_bench::stats::Summary;
use dyfos_bench::svg::line_plot;
use dyfos_service::learned::{DataSpec, generate, load_model};
use dyfos_shared::answer::Algorithm;
use dyfos_shared::params::Params;
use dyfos_shared::sdsmm::{Anisotropic, NoiseModel, Paper, Synthetic};
use std::fmt::Write;
use std::path::{Path, PathBuf};

/// Flags of `dyfos-bench learned`.
#[derive(Debug, clap::Args)]
pub struct LearnedArgs {
    /// The trained model file.
    #[arg(long, default_value = "tests/data/learned/model.bin")]
    model: PathBuf,
    /// Held-out simulated measurements for the NLL and the std fit.
    #[arg(long, default_value_t = 100_000)]
    samples: usize,
    /// Seed of the held-out data (the committed model was trained on seed 0).
    #[arg(long, default_value_t = 1)]
    data_seed: u64,
    /// SPEC §10 maps to plan on (0 skips planning).
    #[arg(long, default_value_t = 20)]
    maps: usize,
    /// Seed of the maps and searches (as `dyfos-bench numerical`).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Search algorithms to plan with, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "dyfos,brute")]
    algos: Vec<String>,
    /// Threads for `brute` (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Runs of each query; its time is their median.
    #[arg(long, default_value_t = 3)]
    repeats: usize,
    /// Directory for the report (markdown) and plots (SVG).
    #[arg(long, default_value = "bench/out")]
    out: PathBuf,
}

fn write(dir: &Path, name: &str, text: &str) -> anyhow::Result<()> {
    let path = dir.join(name);
    std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
    eprintln!("wrote {}", path.display());
    Ok(())
}

fn f(v: Option<f64>) -> String {
    v.map_or("—".into(), |v| format!("{v:.3}"))
}

/// Runs everything, prints the report and writes it with the plots.
pub fn run(args: &LearnedArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    let weights = load_model(&args.model)?;
    let threads = args.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let params = Params::default();
    let truth = NoiseModel::Synthetic(Synthetic::default());
    let models: Vec<(String, NoiseModel)> = vec![
        ("true".into(), truth.clone()),
        ("learned".into(), NoiseModel::Learned(weights.clone())),
        ("paper".into(), NoiseModel::Paper(Paper)),
        ("anisotropic".into(), NoiseModel::Anisotropic(Anisotropic { lambda: params.lambda })),
    ];
    let load = || std::fs::read_to_string("/proc/loadavg").map(|l| l.split(' ').take(3).collect::<Vec<_>>().join(" "));
    let mut report = format!(
        "Model: `{}` — {}\n\nLoad average at start: {}\n\n",
        args.model.display(),
        weights.note(),
        load().unwrap_or_else(|_| "unknown".into())
    );

    // Held-out NLL and std fit.
    let data = generate(&DataSpec { samples: args.samples, seed: args.data_seed, ..DataSpec::default() });
    let nll = held_out_nll(&models, &data.samples);
    let _ = writeln!(
        report,
        "### Held-out NLL ({} samples, data seed {})\n\n| model | mean NLL (nats) | − true | relative to |true| |\n|---|---:|---:|---:|",
        data.samples.len(),
        args.data_seed
    );
    for ((name, _), v) in models.iter().zip(&nll) {
        let _ = writeln!(
            report,
            "| {name} | {v:.4} | {:+.4} | {:+.2} % |",
            v - nll[0],
            100.0 * (v - nll[0]) / nll[0].abs()
        );
    }
    let _ = writeln!(
        report,
        "\n### Standard deviations against the truth (|σ/σ_true − 1| over the held-out features)\n\n| model | along median | along p95 | across median | across p95 |\n|---|---:|---:|---:|---:|"
    );
    for (name, model) in &models[1..] {
        let s = std_fit(model, &truth, &data.samples);
        let _ = writeln!(
            report,
            "| {name} | {:.1} % | {:.1} % | {:.1} % | {:.1} % |",
            100.0 * s.along_median,
            100.0 * s.along_p95,
            100.0 * s.across_median,
            100.0 * s.across_p95
        );
    }
    let plotted = &models[..3];
    for (line, file, axis) in
        [(ImageLine::Horizontal, "learned-std-u.svg", "u"), (ImageLine::Vertical, "learned-std-v.svg", "v")]
    {
        let svg = line_plot(
            &format!("Noise std along / across the line of sight, across the image ({axis})"),
            &format!("image position {axis} (−1 … 1 edge to edge)"),
            "standard deviation, m",
            &std_over_image(plotted, &params, line),
            false,
        );
        write(&args.out, file, &svg)?;
    }

    // Planning on the SPEC §10 maps, judged by the true model.
    let contenders: Vec<Contender> = args
        .algos
        .iter()
        .map(|a| {
            Algorithm::from_name(a)
                .map(|a| Contender::algorithm(a, threads))
                .with_context(|| format!("unknown algorithm `{a}` in --algos"))
        })
        .collect::<anyhow::Result<_>>()?;
    if args.maps > 0 {
        let maps = numerical_maps(args.seed, args.maps, &NumericalConfig::paper());
        let run = planning(&maps, &models, &truth, &contenders, args.seed, args.repeats);
        for (c, contender) in contenders.iter().enumerate() {
            let _ = writeln!(
                report,
                "\n### Planning with `{}` on {} SPEC §10 maps (seed {}), poses scored by the true model\n\n\
                 | planned with | median true E | mean true E | mean gap to true-planned | max gap | maps within 0.1 | no pose |\n\
                 |---|---:|---:|---:|---:|---:|---:|",
                contender.name,
                maps.len(),
                args.seed
            );
            for (p, name) in run.planners.iter().enumerate() {
                let costs: Vec<f64> = run.true_costs[p][c].iter().flatten().copied().collect();
                let gaps: Vec<f64> = run.gaps(p, 0, c).into_iter().flatten().collect();
                let s = Summary::of(&costs);
                let g = Summary::of(&gaps);
                let _ = writeln!(
                    report,
                    "| {name} | {} | {} | {} | {} | {}/{} | {} |",
                    f(s.map(|s| s.median)),
                    f(s.map(|s| s.mean)),
                    f(g.map(|g| g.mean)),
                    f(g.map(|g| g.max)),
                    gaps.iter().filter(|g| **g <= 0.1).count(),
                    gaps.len(),
                    run.true_costs[p][c].iter().filter(|v| v.is_none()).count()
                );
            }
            // Per map, so a gap can be traced to its map (`numerical --write-maps`).
            let _ = writeln!(
                report,
                "\nPer map: true E of the pose planned with the truth, and each model's gap to it\n\n| map | true-planned E | {} |\n|---:|---:|{}",
                run.planners[1..].join(" | "),
                "---:|".repeat(run.planners.len() - 1)
            );
            let per_planner: Vec<Vec<Option<f64>>> = (1..run.planners.len()).map(|p| run.gaps(p, 0, c)).collect();
            for (m, truth_cost) in run.true_costs[0][c].iter().enumerate() {
                let gaps: Vec<String> =
                    per_planner.iter().map(|g| g[m].map_or("–".into(), |g| format!("{g:+.3}"))).collect();
                let _ = writeln!(report, "| {m} | {} | {} |", f(*truth_cost), gaps.join(" | "));
            }
            let _ = writeln!(
                report,
                "\nMedian query time (`{}`, {} thread{}):",
                contender.name,
                contender.threads,
                if contender.threads == 1 { "" } else { "s" }
            );
            let base = run.median_seconds(2, c);
            for (p, name) in run.planners.iter().enumerate() {
                let t = run.median_seconds(p, c);
                let _ = writeln!(report, "- {name}: {} ({:.2}× paper)", duration(t), t / base);
            }
        }
    }

    // Cost of one noise prediction.
    let features: Vec<_> = data.samples.iter().take(20_000).map(|s| s.features).collect();
    let _ = writeln!(
        report,
        "\n### One `noise` call (median over batches of 256 calls, 9 passes over {} held-out features)\n",
        features.len()
    );
    for (name, model) in &models {
        let _ = writeln!(report, "- {name}: {:.1} ns", noise_nanos(model, &features, 9));
    }
    let _ = writeln!(report, "\nLoad average at the end: {}", load().unwrap_or_else(|_| "unknown".into()));
    print!("{report}");
    write(&args.out, "learned.md", &report)
}
