//! `pedscan`: parses flags into a checked configuration and calls the library.
//! Exit codes: 0 ok, 1 failure, 2 bad input (usage, config, files), 128 + N stopped by
//! signal N (130 SIGINT, 143 SIGTERM).

use anyhow::Context as _;
use clap::{Parser, Subcommand};
use pedscan::config::Flags;
use pedscan::commands::run::{RunOptions, Shard};
use std::path::PathBuf;
use std::process::ExitCode;

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
    Bench(pedscan::commands::bench::BenchRequest),
    /// Contact sheet of human models at several gait phases, rendered by pedscan itself.
    Sheet(pedscan::commands::sheet::SheetRequest),
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
    /// A recording against a pedscan output, measured the same way: hole rate by incidence,
    /// range and row, range noise, intensity; the largest gap of each curve.
    Realism(pedscan::commands::realism::RealismRequest),
    /// Fit the `[sensor_model]` terms a recording can tell (detection by incidence and power,
    /// dropout, range noise) and write them as TOML.
    SensorFit(pedscan::commands::realism::SensorFitRequest),
    /// KITTI .bin scans on a sensor's grid by `generate`'s projection: each point's cell, range and intensity images.
    Project(pedscan::commands::project::ProjectRequest),
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
            let stop = pedscan::commands::run::stop_on_signals()?;
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
        Command::Bench(req) => {
            let exe = std::env::current_exe().context("locating the pedscan executable")?;
            print!("{}", pedscan::commands::bench::bench(&exe, &req)?);
        }
        Command::Sheet(req) => {
            pedscan::commands::sheet::write_contact_sheet(&req)?;
            eprintln!("wrote {}", req.out.display());
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
        Command::Realism(req) => println!("{}", pedscan::commands::realism::realism(&req)?),
        Command::SensorFit(req) => print!("{}", pedscan::commands::realism::sensor_fit(&req)?.toml),
        Command::Project(req) => eprintln!("{}", pedscan::commands::project::project(&req)?),
        Command::Info { file } => print!("{}", pedscan::output::info(&file)?),
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
            eprintln!("error: {}", pedscan::error::clipped(&e.to_string()));
            for cause in e.chain().skip(1) {
                eprintln!("  caused by: {}", pedscan::error::clipped(&cause.to_string()));
            }
            match e.downcast_ref::<pedscan::Error>() {
                Some(pedscan::Error::Interrupted { signal }) => ExitCode::from((128 + signal) as u8),
                Some(e) if e.is_input() => ExitCode::from(2),
                _ => ExitCode::from(1),
            }
        }
    }
}
