//! `dyfos-bench numerical`: the paper's numerical evaluation (SPEC §10, paper §V-A)
//! and the obstacle-count scaling of a `dyfos` query.

use anyhow::{Context, bail};
use dyfos_bench::evaluation::{Contender, Evaluation, duration, evaluate, query_seed};
use dyfos_bench::numerical::{NumericalConfig, numerical_maps};
use dyfos_bench::scaling::{MapKind, obstacle_scaling, scaling_table};
use dyfos_bench::stats::Summary;
use dyfos_bench::svg::{Series, ViolinPlot, line_plot};
use dyfos_service::search::{AnySearch, DifferentialEvolution, Polish, Stall, TieBreak};
use dyfos_shared::answer::Algorithm;
use dyfos_shared::params::ModelKind;
use std::fmt::Write;
use std::path::{Path, PathBuf};

/// Flags of `dyfos-bench numerical`.
#[derive(Debug, clap::Args)]
pub struct NumericalArgs {
    /// Random maps to evaluate (0 skips the evaluation, e.g. to run only the scaling).
    #[arg(long, default_value_t = 20)]
    maps: usize,
    /// Seed of the maps and of the searches (map i is searched with a seed derived from it and i).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// SDSMM the maps are scored with: `paper` or `anisotropic`.
    #[arg(long, default_value = "paper", value_parser = parse_model)]
    model: ModelKind,
    /// Algorithms to compare, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "dyfos,dyfos-scipy,brute,random,center", value_parser = parse_algorithm)]
    algos: Vec<Algorithm>,
    /// Also compare a differential evolution setting, as `NAME:key=value,...` starting
    /// from the `dyfos` default; keys: popsize, tol, atol, generations, recombination,
    /// stall and epsilon (stop after this many generations without a drop of the best
    /// energy over epsilon), nostall (SciPy's stop alone), polish (adaptive polish with
    /// at most this many evaluations), mirrored (the adaptive polish from the best
    /// member and from its mirror image, this many each), turns, heats and raced (the
    /// raced polish: heats of this many evaluations from this many turns of the viewer
    /// yaw, then at most `raced` from the lowest), floor (the polish's smallest step),
    /// tiebreak and widen (the margin tie-break: costs within this tolerance of the
    /// lowest are ties, at most `widen` evaluations), notiebreak (the lowest cost found).
    /// Repeatable. Example, the default before the raced setting:
    /// `--de before:popsize=15,nostall=1,mirrored=150,floor=1e-9,notiebreak=1`.
    #[arg(long = "de", value_name = "NAME:SETTINGS")]
    de: Vec<String>,
    /// Threads for `brute` (default: all cores); the other algorithms use one.
    #[arg(long)]
    threads: Option<usize>,
    /// Runs of each query; its time is their median.
    #[arg(long, default_value_t = 3)]
    repeats: usize,
    /// Scaling: cylinder counts to time a `dyfos` query on, e.g. `25,100,400,1600`
    /// (maps grow to keep the paper's density).
    #[arg(long, value_delimiter = ',')]
    obstacles: Vec<usize>,
    /// Scaling: maps per cylinder count.
    #[arg(long, default_value_t = 5)]
    scaling_maps: usize,
    /// Scaling: cell side of the occupancy-grid version of each map, m; 0 skips it.
    #[arg(allow_hyphen_values = true, long, default_value_t = 0.1)]
    voxel_resolution: f64,
    /// Also write each evaluated map as a scenario file (`map_NN.json`, for `dyfos solve`) here.
    #[arg(long, value_name = "DIR")]
    write_maps: Option<PathBuf>,
    /// Directory for the tables (markdown), raw results (JSON) and plots (SVG).
    #[arg(long, default_value = "bench/out")]
    out: PathBuf,
}

fn parse_model(s: &str) -> Result<ModelKind, String> {
    match s {
        "paper" => Ok(ModelKind::Paper),
        "anisotropic" => Ok(ModelKind::Anisotropic),
        _ => Err(format!("unknown model `{s}`: use `paper` or `anisotropic`")),
    }
}

fn parse_algorithm(s: &str) -> Result<Algorithm, String> {
    Algorithm::from_name(s).ok_or_else(|| {
        let names: Vec<&str> = Algorithm::ALL.iter().map(|a| a.name()).collect();
        format!("unknown algorithm `{s}`: use one of {}", names.join(", "))
    })
}

/// What `stall=` or `epsilon=` alone leaves of the other: never stop on a stall.
const NO_STALL: Stall = Stall { epsilon: 0.0, generations: u32::MAX };

/// `NAME:key=value,...` over the `dyfos` default.
fn parse_de(spec: &str) -> anyhow::Result<Contender> {
    let (name, settings) = spec.split_once(':').unwrap_or((spec, ""));
    if name.is_empty() {
        bail!("--de `{spec}`: give a name before the colon, e.g. `fast:tol=0.02`");
    }
    let mut de = DifferentialEvolution::dyfos();
    for kv in settings.split(',').filter(|s| !s.is_empty()) {
        let (key, value) = kv.split_once('=').with_context(|| format!("--de `{spec}`: `{kv}` is not key=value"))?;
        let number: f64 = value.parse().with_context(|| format!("--de `{spec}`: `{value}` is not a number"))?;
        let count = || -> anyhow::Result<u64> {
            if number >= 0.0 && number.fract() == 0.0 {
                Ok(number as u64)
            } else {
                bail!("--de `{spec}`: {key} must be a whole number ≥ 0")
            }
        };
        match key {
            "popsize" => de.popsize = count()? as usize,
            "tol" => de.tol = number,
            "atol" => de.atol = number,
            "generations" => de.max_generations = u32::try_from(count()?)?,
            "polish" => de.polish = Polish::Adaptive { evaluations: count()? },
            "mirrored" => de.polish = Polish::Mirrored { evaluations: count()? },
            "recombination" => de.recombination = number,
            "stall" => de.stall = Some(Stall { generations: u32::try_from(count()?)?, ..de.stall.unwrap_or(NO_STALL) }),
            "epsilon" => de.stall = Some(Stall { epsilon: number, ..de.stall.unwrap_or(NO_STALL) }),
            "nostall" => de.stall = None,
            "floor" => de.polish_floor = number,
            "turns" | "heats" | "raced" => {
                let (mut turns, mut heats, mut evaluations) = match de.polish {
                    Polish::Raced { turns, heats, evaluations } => (u64::from(turns), heats, evaluations),
                    _ => (2, 50, 150),
                };
                *(match key {
                    "turns" => &mut turns,
                    "heats" => &mut heats,
                    _ => &mut evaluations,
                }) = count()?;
                de.polish = Polish::Raced { turns: u32::try_from(turns)?, heats, evaluations };
            }
            "tiebreak" => {
                de.tie_break = Some(TieBreak { tolerance: number, ..de.tie_break.unwrap_or(TieBreak::DEFAULT) })
            }
            "widen" => {
                de.tie_break = Some(TieBreak { evaluations: count()?, ..de.tie_break.unwrap_or(TieBreak::DEFAULT) })
            }
            "notiebreak" => de.tie_break = None,
            _ => bail!(
                "--de `{spec}`: unknown key `{key}` (popsize, tol, atol, generations, polish, mirrored, recombination, stall, epsilon, nostall, floor, turns, heats, raced, tiebreak, widen, notiebreak)"
            ),
        }
    }
    Ok(Contender { name: name.to_string(), search: AnySearch::DifferentialEvolution(de), threads: 1 })
}

fn write(dir: &Path, name: &str, text: &str) -> anyhow::Result<()> {
    let path = dir.join(name);
    std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
    eprintln!("wrote {}", path.display());
    Ok(())
}

/// Runs the evaluation and/or the scaling, prints the tables, writes the files.
pub fn run(args: &NumericalArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    let threads = args.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let mut report = String::new();
    if args.maps > 0 {
        let mut contenders: Vec<Contender> = args.algos.iter().map(|a| Contender::algorithm(*a, threads)).collect();
        for spec in &args.de {
            contenders.push(parse_de(spec)?);
        }
        let config = NumericalConfig::paper().model(args.model);
        let maps = numerical_maps(args.seed, args.maps, &config);
        if let Some(dir) = &args.write_maps {
            std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
            for (i, map) in maps.iter().enumerate() {
                let path = dir.join(format!("map_{i:02}.json"));
                std::fs::write(&path, map.to_json()).with_context(|| format!("cannot write {}", path.display()))?;
            }
        }
        eprintln!(
            "numerical: {} maps, model {}, seed {}, {} repeats, brute on {threads} threads",
            args.maps,
            args.model.name(),
            args.seed,
            args.repeats
        );
        let run = evaluate(&maps, &contenders, args.seed, args.repeats);
        report.push_str(&evaluation_report(&run, args, threads));
        let stem = format!("numerical-{}", args.model.name());
        write(&args.out, &format!("{stem}-cost.svg"), &cost_plot(&run, args).to_svg())?;
        write(&args.out, &format!("{stem}.json"), &raw_json(&run, args))?;
        write(&args.out, &format!("{stem}.md"), &report)?;
    }
    if !args.obstacles.is_empty() {
        let resolution = (args.voxel_resolution > 0.0).then_some(args.voxel_resolution);
        eprintln!("scaling: cylinders {:?}, {} maps each, voxels {resolution:?}", args.obstacles, args.scaling_maps);
        let dyfos = AnySearch::from(Algorithm::Dyfos);
        let rows = obstacle_scaling(&args.obstacles, args.scaling_maps, args.seed, &dyfos, resolution);
        let mut text = format!(
            "## `dyfos` query time as the map grows\n\n{} maps per row, seed {}, one thread, median of 3 runs per query; \
             the map's side grows to keep 25 cylinders per 400 m².\n\n",
            args.scaling_maps, args.seed
        );
        text.push_str(&scaling_table(&rows));
        let series = |kind: fn(&MapKind) -> bool, name: &str| Series {
            name: name.into(),
            points: rows
                .iter()
                .filter(|r| kind(&r.kind))
                .filter_map(|r| Some((r.obstacles as f64, r.seconds?.median * 1e6)))
                .collect(),
        };
        let svg = line_plot(
            "dyfos query time vs. map size (median, one core)",
            "cylinders (map side grows with √n)",
            "µs per query",
            &[
                series(|k| *k == MapKind::Cylinders, "cylinders"),
                series(|k| matches!(k, MapKind::Voxels { .. }), "voxel grid"),
            ],
            true,
        );
        write(&args.out, "scaling.svg", &svg)?;
        write(&args.out, "scaling.md", &text)?;
        report.push('\n');
        report.push_str(&text);
    }
    if report.is_empty() {
        bail!("nothing to do: give --maps > 0 or --obstacles");
    }
    println!("{report}");
    Ok(())
}

fn evaluation_report(run: &Evaluation, args: &NumericalArgs, threads: usize) -> String {
    let mut out = format!(
        "## Numerical evaluation, model `{}`\n\n{} maps (seed {}), {} runs per query (median time), brute on {threads} threads, \
         the others on one.\n\n### Cost E = ln det Σ⁺\n\n",
        args.model.name(),
        args.maps,
        args.seed,
        args.repeats
    );
    out.push_str(&run.cost_table());
    out.push_str("\n### Run time per query\n\n");
    out.push_str(&run.time_table());
    if let Some(brute) = run.index("brute") {
        let median = run.median_map(brute);
        let _ = writeln!(out, "\n### Gap to `brute` per map\n");
        let others: Vec<usize> = (0..run.names.len())
            .filter(|c| *c != brute && (run.names[*c].starts_with("dyfos") || *c >= args.algos.len()))
            .collect();
        let mut header = String::from("| map | E brute |");
        let mut rule = String::from("|---:|---:|");
        for c in &others {
            let _ = write!(header, " {} − brute |", run.names[*c]);
            rule.push_str("---:|");
        }
        let _ = writeln!(out, "{header}\n{rule}");
        for m in 0..run.queries[brute].len() {
            let mark = if Some(m) == median { " (median)" } else { "" };
            let e = run.queries[brute][m].cost.map_or("–".into(), |e| format!("{e:.5}"));
            let _ = write!(out, "| {m}{mark} | {e} |");
            for c in &others {
                let g = run.gaps(*c, brute)[m];
                let _ = write!(out, " {} |", g.map_or("–".into(), |g| format!("{g:+.5}")));
            }
            out.push('\n');
        }
        let _ = writeln!(
            out,
            "\n| algorithm | gap on brute's median map | gap median | gap max | maps > +0.001 | > +0.01 | > +0.1 | time ratio to brute (medians) |\n|---|---:|---:|---:|---:|---:|---:|---:|"
        );
        let brute_time = Summary::of(&run.queries[brute].iter().map(|q| q.seconds).collect::<Vec<_>>());
        for c in &others {
            let gaps: Vec<f64> = run.gaps(*c, brute).into_iter().flatten().collect();
            let at_median = median.and_then(|m| run.gaps(*c, brute)[m]);
            let time = Summary::of(&run.queries[*c].iter().map(|q| q.seconds).collect::<Vec<_>>());
            let ratio = match (time, brute_time) {
                (Some(t), Some(b)) if b.median > 0.0 => format!("{:.5}", t.median / b.median),
                _ => "–".into(),
            };
            match Summary::of(&gaps) {
                Some(s) => {
                    let above = |t: f64| gaps.iter().filter(|g| **g > t).count();
                    let _ = writeln!(
                        out,
                        "| {} | {} | {:+.5} | {:+.5} | {} | {} | {} | {ratio} |",
                        run.names[*c],
                        at_median.map_or("–".into(), |g| format!("{g:+.5}")),
                        s.median,
                        s.max,
                        above(0.001),
                        above(0.01),
                        above(0.1)
                    );
                }
                None => {
                    let _ = writeln!(out, "| {} | – | – | – | – | – | – | {ratio} |", run.names[*c]);
                }
            }
        }
    }
    if let Some(d) = run.index("dyfos") {
        let t = Summary::of(&run.queries[d].iter().map(|q| q.seconds).collect::<Vec<_>>());
        if let Some(t) = t {
            let _ = writeln!(out, "\n`dyfos` median query: {} (one thread).", duration(t.median));
        }
    }
    out
}

fn cost_plot(run: &Evaluation, args: &NumericalArgs) -> ViolinPlot {
    ViolinPlot {
        title: format!("Predicted posterior uncertainty, {} maps, model {}", args.maps, args.model.name()),
        y_label: "E = ln det Σ⁺ (lower is better)".into(),
        groups: run.names.iter().enumerate().map(|(c, n)| (n.clone(), run.costs(c))).collect(),
    }
}

fn raw_json(run: &Evaluation, args: &NumericalArgs) -> String {
    let contenders: Vec<serde_json::Value> = run
        .names
        .iter()
        .enumerate()
        .map(|(c, name)| {
            let queries: Vec<serde_json::Value> = run.queries[c]
                .iter()
                .enumerate()
                .map(|(m, q)| {
                    serde_json::json!({
                        "map": m,
                        "search_seed": query_seed(args.seed, m),
                        "x": q.x.map(|x| x.to_array()),
                        "cost": q.cost,
                        "verified": q.verified,
                        "repeatable": q.repeatable,
                        "seconds": q.seconds,
                        "cpu_seconds": if q.cpu_seconds.is_finite() { Some(q.cpu_seconds) } else { None },
                        "evaluations": q.evaluations,
                        "stop": q.stop,
                    })
                })
                .collect();
            serde_json::json!({"name": name, "threads": run.threads[c], "queries": queries})
        })
        .collect();
    let doc = serde_json::json!({
        "maps": args.maps,
        "seed": args.seed,
        "model": args.model.name(),
        "repeats": args.repeats,
        "contenders": contenders,
    });
    serde_json::to_string_pretty(&doc).expect("JSON values serialize")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn de_of(spec: &str) -> DifferentialEvolution {
        match parse_de(spec).unwrap().search {
            AnySearch::DifferentialEvolution(de) => de,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn de_keys_set_the_tie_break() {
        assert_eq!(de_of("d:").tie_break, Some(TieBreak::DEFAULT));
        assert_eq!(de_of("d:notiebreak=1").tie_break, None);
        assert_eq!(de_of("d:notiebreak=1,widen=8").tie_break, Some(TieBreak { evaluations: 8, ..TieBreak::DEFAULT }));
        assert_eq!(de_of("d:tiebreak=0.001,widen=0").tie_break, Some(TieBreak { tolerance: 0.001, evaluations: 0 }));
        // The former default, as the flag's documentation spells it.
        let before = de_of("before:popsize=15,nostall=1,mirrored=150,floor=1e-9,notiebreak=1");
        assert_eq!(before, DifferentialEvolution::mirrored());
        assert!(parse_de("d:widen=1.5").is_err());
    }
}
