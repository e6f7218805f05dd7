//! `pedscan`: parses flags into a checked configuration and calls the library.
//! Exit codes: 0 ok, 1 failure, 2 bad input (usage, config, files), 128 + N stopped by
//! signal N (130 SIGINT, 143 SIGTERM).

use anyhow::Context as _;
use clap::{Parser, Subcommand};
use pedscan::config::{Config, Flags};
use pedscan::commands::run::{RunOptions, Shard};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicUsize};
use std::sync::Arc;

/// `verify` found problems (already printed): exit 1.
#[derive(Debug, thiserror::Error)]
#[error("the folder does not verify")]
struct VerifyFailed;

#[derive(Parser)]
#[command(name = "pedscan", version, about = "Automatically labeled LiDAR sequences of walking people")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Generate labeled sequences (HDF5 + XML, optional PNG) on the bundled defaults or a config.
    Generate {
        #[command(flatten)]
        args: Flags,
        /// Skip sequences whose files already verify against the output's manifest.jsonl
        /// (continue a killed run; extend a job with more --sequences).
        #[arg(long)]
        resume: bool,
        /// Replace sequences that another configuration wrote (refused otherwise).
        #[arg(long)]
        overwrite: bool,
        /// Write only every N-th sequence, starting at I: `I/N`; `auto` (a Slurm array task)
        /// or `auto/N` (a Slurm or Kubernetes Indexed Job task, of N).
        #[arg(long)]
        shard: Option<String>,
    },
    /// Check an output folder against its manifest.jsonl: every file there, with its size and
    /// SHA-256; every sequence file listed. Exit 0 when all verify, 1 otherwise.
    Verify {
        /// The output folder of `generate`.
        dir: PathBuf,
    },
    /// Hold the raster path against the CPU ray-cast reference on the same posed triangles.
    Crosscheck {
        #[command(flatten)]
        args: Flags,
        /// Write the report as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Write a PNG strip (raster, reference, error, unrefined mask disagreement).
        #[arg(long = "strip-png")]
        strip_png: Option<PathBuf>,
    },
    /// Hold the rolling shutter's default (people posed over their column span) against
    /// posing the whole frame at every column's time, beam by beam.
    ShutterCheck {
        #[command(flatten)]
        args: Flags,
        /// Compare every N-th column (the reference poses the frame once per column).
        #[arg(long, default_value_t = 1)]
        column_stride: usize,
        /// Write the report as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Time against error: sweep resolution, level of detail, refinement, people and columns;
    /// then the triangle rate of the raster renderer against the ray caster (in `bench.md`).
    Bench {
        /// A reduced sweep (under a minute).
        #[arg(long)]
        quick: bool,
        /// Base configuration (the sweep overrides its render and workload keys).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Write the points as JSON.
        #[arg(long, default_value = "bench.json")]
        json: PathBuf,
        /// Write a Markdown table.
        #[arg(long, default_value = "bench.md")]
        markdown: PathBuf,
        /// Write the time-vs-error plot.
        #[arg(long, default_value = "bench.png")]
        plot: PathBuf,
        /// Run one point (internal: the sweep runs each point in a child process).
        #[arg(long, hide = true)]
        point: Option<String>,
        /// Redraw the table and plot from the points of an earlier `--json` file; runs nothing.
        #[arg(long)]
        from_json: Option<PathBuf>,
    },
    /// Contact sheet of human models at several gait phases, rendered by pedscan itself.
    Sheet {
        /// Output PNG.
        #[arg(long, default_value = "humans.png")]
        out: PathBuf,
        /// Human models: folders of .glb files or files (default: the bundled humans).
        #[arg(long)]
        models: Vec<PathBuf>,
        /// Gait phases, comma separated.
        #[arg(long, value_delimiter = ',', default_value = "0,0.25,0.5,0.75")]
        phases: Vec<f32>,
        #[arg(long)]
        validation: bool,
    },
    /// What a generated dataset holds: frames, people per frame, human beams per distance
    /// bin, class balance, walking speeds; with a PNG of the histograms.
    Stats {
        /// An output folder of `generate` (every seq_*.h5) or one sequence file.
        path: PathBuf,
        /// Write the histograms as a PNG.
        #[arg(long, default_value = "stats.png")]
        png: PathBuf,
        /// Also write the numbers as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Summarise a sequence file written by `generate`.
    Info {
        /// A `seq_NNNNNN.h5` file.
        file: PathBuf,
    },
    /// List the Vulkan devices pedscan can use (for `--device`).
    Devices,
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Generate { args, resume, overwrite, shard } => {
            let shard = match shard {
                Some(spec) => Shard::parse(&spec, |k| std::env::var(k).ok())?,
                None => Shard::default(),
            };
            // SIGINT and SIGTERM ask the run to stop between frames; a second one ends the
            // process at once (temporaries may then remain; `--resume` cleans them up).
            let stop = Arc::new(AtomicUsize::new(0));
            let asked = Arc::new(AtomicBool::new(false));
            for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
                // In this order: the first signal finds `asked` still false.
                signal_hook::flag::register_conditional_shutdown(signal, 128 + signal, asked.clone())
                    .and_then(|_| signal_hook::flag::register(signal, asked.clone()))
                    .and_then(|_| signal_hook::flag::register_usize(signal, stop.clone(), signal as usize))
                    .context("installing a signal handler")?;
            }
            let opts = RunOptions { progress: true, export_geometry: args.export_geometry.clone(), resume, overwrite, shard, stop: Some(stop) };
            let summary = pedscan::commands::run::generate(args.config()?, &opts)?;
            eprintln!("{summary}");
            if args.timings {
                eprintln!("{}", summary.timings);
            }
        }
        Command::Verify { dir } => {
            let report = pedscan::output::manifest::verify_dir(&dir)?;
            println!("{report}");
            if !report.ok() {
                return Err(VerifyFailed.into());
            }
        }
        Command::Crosscheck { mut args, json, strip_png } => {
            // By default 4 sequences of 32 frames: over 100 frames.
            args.sequences = args.sequences.or(Some(4));
            let opts = pedscan::commands::crosscheck::CrosscheckOptions { json, png: strip_png, export_geometry: args.export_geometry.clone() };
            let report = pedscan::commands::crosscheck::crosscheck(args.config()?, &opts)?;
            println!("{report}");
        }
        Command::ShutterCheck { args, column_stride, json } => {
            let report = pedscan::commands::shutter::shutter_check(args.config()?, column_stride)?;
            if let Some(p) = json {
                let text = serde_json::to_string_pretty(&report).context("report as JSON")?;
                std::fs::write(&p, text).with_context(|| p.display().to_string())?;
            }
            println!("{report}");
        }
        Command::Bench { quick, config, json, markdown, plot, point, from_json } => {
            if let Some(src) = from_json {
                let text = std::fs::read_to_string(&src).with_context(|| src.display().to_string())?;
                let points: Vec<pedscan::commands::bench::Point> = serde_json::from_str(&text)
                    .map_err(|e| pedscan::Error::input(src.display(), format!("not a bench JSON: {e}")))?;
                let table = pedscan::commands::bench::markdown(&points);
                std::fs::write(&markdown, &table).with_context(|| markdown.display().to_string())?;
                pedscan::commands::bench::plot(&points).save(&plot)?;
                print!("{table}");
                return Ok(());
            }
            let base = match &config {
                Some(p) => Config::from_file(p)?,
                None => Config::default(),
            };
            if let Some(spec) = point {
                let spec: pedscan::commands::bench::PointSpec = serde_json::from_str(&spec).context("--point")?;
                let p = pedscan::commands::bench::run_point(&base, &spec)?;
                println!("{}", serde_json::to_string(&p)?);
                return Ok(());
            }
            let exe = std::env::current_exe().context("locating the pedscan executable")?;
            let specs = pedscan::commands::bench::sweep(quick);
            let n = specs.len();
            let points = pedscan::commands::bench::run_sweep(&exe, config.as_deref(), &specs, |i, p| {
                eprintln!(
                    "[{}/{n}] {}: {:.1} frames/s, agreement {:.4} %, median error {:.4} mm, peak {:.0} MiB",
                    i + 1,
                    p.spec,
                    p.frames_per_s,
                    100.0 * p.human_beam_agreement,
                    p.median_range_error_m * 1e3,
                    p.peak_rss_mb
                );
            })?;
            std::fs::write(&json, serde_json::to_string_pretty(&points)?).with_context(|| json.display().to_string())?;
            let mut table = pedscan::commands::bench::markdown(&points);
            table += &bench_rates(&base, quick);
            table += &bench_terms(&base, quick);
            table += &bench_shares(&base, quick);
            std::fs::write(&markdown, &table).with_context(|| markdown.display().to_string())?;
            pedscan::commands::bench::plot(&points).save(&plot)?;
            print!("{table}");
        }
        Command::Sheet { out, models, phases, validation } => {
            let models = if models.is_empty() { Config::default().humans.models } else { models };
            pedscan::commands::sheet::write_contact_sheet(&models, &phases, &out, validation)?;
            eprintln!("wrote {}", out.display());
        }
        Command::Stats { path, png, json } => {
            let stats = pedscan::commands::stats::Stats::of(&path)?;
            println!("{stats}");
            pedscan::plot::save_image(&stats.plot(), &png)?;
            if let Some(json) = json {
                std::fs::write(&json, serde_json::to_string_pretty(&stats)?).with_context(|| json.display().to_string())?;
            }
            eprintln!("wrote {}", png.display());
        }
        Command::Info { file } => {
            print!("{}", pedscan::output::info(&file)?);
        }
        Command::Devices => {
            for (i, d) in pedscan::gpu::Context::list_devices().context("listing Vulkan devices")?.iter().enumerate() {
                println!("{i}: {d}");
            }
        }
    }
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            for cause in e.chain().skip(1) {
                eprintln!("  caused by: {cause}");
            }
            match e.downcast_ref::<pedscan::Error>() {
                Some(pedscan::Error::Interrupted { signal }) => ExitCode::from((128 + signal) as u8),
                Some(e) if e.is_input() => ExitCode::from(2),
                _ => ExitCode::from(1),
            }
        }
    }
}

/// The bench's triangle-rate table, or a line saying why there is none.
/// The sensor model's terms timed on both backends (the raster one where Vulkan opens).
fn bench_terms(base: &Config, quick: bool) -> String {
    use pedscan::commands::bench::{sensor_model_costs, terms_markdown};
    use pedscan::config::BackendChoice;
    let (frames, repeats) = if quick { (4, 3) } else { (16, 5) };
    let mut rows = Vec::new();
    let mut notes = String::new();
    for backend in [BackendChoice::Raycast, BackendChoice::Raster] {
        match sensor_model_costs(base, &[backend], frames, repeats) {
            Ok(r) => rows.extend(r),
            Err(e) => notes += &format!("\n{backend:?}: not measured ({e})\n"),
        }
    }
    terms_markdown(&rows, frames, repeats) + &notes
}

/// The bench's table of where the raster background's work runs, or a line saying why there
/// is none.
fn bench_shares(base: &Config, quick: bool) -> String {
    use pedscan::commands::bench::{host_share_costs, shares_markdown};
    let (frames, repeats) = if quick { (8, 3) } else { (32, 5) };
    match host_share_costs(base, frames, repeats) {
        Ok((device, rows)) => shares_markdown(&device, &rows, frames, repeats),
        Err(e) => format!("\nWhere the raster background's work runs: not measured ({e})\n"),
    }
}

fn bench_rates(base: &Config, quick: bool) -> String {
    use pedscan::commands::bench::{rates_markdown, triangle_rates};
    let counts: &[usize] = if quick { &[1_000, 16_000] } else { &[1_000, 4_000, 16_000, 64_000] };
    let mut gpu = pedscan::backend::Gpu::new(&base.device, false);
    match gpu.context().and_then(|ctx| Ok((ctx.device_name(), triangle_rates(&ctx, counts, 9)?))) {
        Ok((device, rows)) => rates_markdown(&device, &rows),
        Err(e) => format!("\nTriangle rate: not measured ({e})\n"),
    }
}
