//! `pedscan`: parses flags into a checked configuration and calls the library.
//! Exit codes: 0 ok, 1 failure, 2 bad input (usage, config, files).

use anyhow::Context as _;
use clap::{Args, Parser, Subcommand};
use pedscan::config::{Backend, CompressionChoice, Config, Projection, Refine, VelocityModel};
use pedscan::human::MotionMode;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "pedscan", version, about = "Automatically labeled LiDAR sequences of walking people")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Generate labeled sequences (HDF5 + XML, optional PNG) on the bundled defaults or a config.
    Generate(GenerateArgs),
    /// Hold the raster path against the CPU ray-cast reference on the same posed triangles.
    Crosscheck {
        #[command(flatten)]
        args: GenerateArgs,
        /// Write the report as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Write a PNG strip (raster, reference, error, unrefined mask disagreement).
        #[arg(long = "strip-png")]
        strip_png: Option<PathBuf>,
    },
    /// Time against error: sweep resolution, level of detail, refinement, people and columns.
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
    /// Summarise a sequence file written by `generate`.
    Info {
        /// A `seq_NNNNNN.h5` file.
        file: PathBuf,
    },
    /// List the Vulkan devices pedscan can use (for `--device`).
    Devices,
}

/// Flags override the config file, which overrides the defaults.
#[derive(Args, Clone, Debug, Default)]
struct GenerateArgs {
    /// A TOML configuration (see the README for every key).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Number of sequences.
    #[arg(long)]
    sequences: Option<usize>,
    /// Index of the first sequence (to split a job across machines with one seed).
    #[arg(long)]
    first_sequence: Option<usize>,
    /// Frames per sequence.
    #[arg(long)]
    frames: Option<usize>,
    /// People per sequence: `MIN..MAX` (uniform, inclusive) or one number.
    #[arg(long, value_parser = parse_count)]
    humans: Option<[usize; 2]>,
    #[arg(long)]
    seed: Option<u64>,
    /// Output folder.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Also write debug PNG range / label / velocity images per frame.
    #[arg(long)]
    png: bool,
    /// Print the time spent per stage (ms per frame) at the end.
    #[arg(long)]
    timings: bool,
    /// Vulkan device: `auto`, an index or part of a name (see `pedscan devices`).
    #[arg(long)]
    device: Option<String>,
    /// Keep background holes where a person stands in front of them (the paper's choice).
    #[arg(long)]
    keep_holes: bool,
    /// Sensor preset (`hdl32e`, `vlp16`) or a sensor TOML file.
    #[arg(long)]
    sensor: Option<String>,
    /// Background: an environment glTF (.glb/.gltf, rendered), a Velodyne .pcap, or a folder
    /// of KITTI .bin / PCD frames (recorded); `none` for an empty world.
    #[arg(long, visible_alias = "environment")]
    background: Option<PathBuf>,
    /// Sensor poses, KITTI poses.txt (3x4 per line) or TUM (t x y z qx qy qz qw).
    #[arg(long)]
    poses: Option<PathBuf>,
    /// Recorded pedestrian tracks to walk along (see --tracks-format).
    #[arg(long)]
    tracks: Option<PathBuf>,
    /// Format of --tracks: eth (obsmat.txt), eth4 (frame id x y), atc (CSV), csv (pedscan).
    #[arg(long, value_enum)]
    tracks_format: Option<pedscan::tracks::TrackFormat>,
    /// Seconds per frame number of eth / eth4 tracks (default 0.04).
    #[arg(long)]
    tracks_frame_period: Option<f64>,
    /// Places the tracks in the world: `X,Y,YAW_DEG[,SCALE]` (p_world = (X,Y) + SCALE R(YAW) p).
    #[arg(long, value_parser = parse_transform, allow_hyphen_values = true)]
    tracks_transform: Option<pedscan::tracks::Transform2>,
    /// Synthetic people walk to goals through the walkable area, or on arcs.
    #[arg(long, value_enum)]
    walk: Option<pedscan::config::WalkMode>,
    /// Human models: a folder of .glb files or files (repeatable).
    #[arg(long)]
    models: Vec<PathBuf>,
    /// How people move: full, sliding, in-place, static (the paper's Table 5 ablations).
    #[arg(long, value_enum)]
    motion: Option<MotionMode>,
    /// How beams find surfaces: Vulkan raster (default) or the CPU ray caster.
    #[arg(long, value_enum)]
    backend: Option<Backend>,
    /// Raster views: cube faces or one cylindrical panorama.
    #[arg(long, value_enum)]
    projection: Option<Projection>,
    /// Per-beam refinement of the raster result.
    #[arg(long, value_enum)]
    refine: Option<Refine>,
    /// Texels per beam spacing at a cube-face centre (cylinder: per column and elevation gap).
    #[arg(long)]
    oversample: Option<f64>,
    /// Velocity definition written to /velocity.
    #[arg(long, value_enum)]
    velocity: Option<VelocityModel>,
    /// HDF5 compression.
    #[arg(long, value_enum)]
    compression: Option<CompressionChoice>,
    /// Per-beam outputs to compute and store: range, label and instance always, plus any of
    /// xyz, velocity, background (comma separated, e.g. `range,label,instance,velocity`).
    #[arg(long, value_delimiter = ',')]
    outputs: Option<Vec<String>>,
    /// Turn on the Vulkan validation layer (slow; for debugging).
    #[arg(long)]
    validation: bool,
    /// Also write each frame's posed human triangles (sensor frame) as PLY under this folder.
    #[arg(long)]
    export_geometry: Option<PathBuf>,
}

fn parse_count(s: &str) -> Result<[usize; 2], String> {
    let parse = |t: &str| t.trim().parse::<usize>().map_err(|_| format!("`{s}` is not MIN..MAX or a number"));
    match s.split_once("..") {
        Some((a, b)) => Ok([parse(a)?, parse(b.trim_start_matches('='))?]),
        None => {
            let n = parse(s)?;
            Ok([n, n])
        }
    }
}

fn parse_transform(s: &str) -> Result<pedscan::tracks::Transform2, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>().map_err(|_| format!("`{s}`: `{t}` is not a number (want X,Y,YAW_DEG[,SCALE])")))
        .collect::<Result<_, _>>()?;
    if !(v.len() == 3 || v.len() == 4) || v.iter().any(|x| !x.is_finite()) {
        return Err(format!("`{s}`: want 3 or 4 finite numbers X,Y,YAW_DEG[,SCALE]"));
    }
    let scale = v.get(3).copied().unwrap_or(1.0);
    if scale <= 0.0 {
        return Err(format!("`{s}`: scale {scale} must be positive"));
    }
    Ok(pedscan::tracks::Transform2 { rotation_deg: v[2], translation_m: [v[0], v[1]], scale })
}

fn build_config(a: &GenerateArgs) -> pedscan::Result<Config> {
    let mut cfg = match &a.config {
        Some(p) => Config::from_file(p)?,
        None => Config::default(),
    };
    if let Some(v) = a.sequences {
        cfg.sequences = v;
    }
    if let Some(v) = a.first_sequence {
        cfg.first_sequence = v;
    }
    if let Some(v) = a.frames {
        cfg.frames = v;
    }
    if let Some(v) = a.humans {
        cfg.humans.count = v;
    }
    if let Some(v) = a.seed {
        cfg.seed = v;
    }
    if let Some(v) = &a.out {
        cfg.out = v.clone();
    }
    cfg.png |= a.png;
    if let Some(v) = &a.device {
        cfg.device = v.clone();
    }
    cfg.render.keep_holes |= a.keep_holes;
    if let Some(v) = &a.sensor {
        cfg.sensor = v.clone();
    }
    if let Some(v) = &a.background {
        cfg.scene.background = if v.as_os_str() == "none" { PathBuf::new() } else { v.clone() };
    }
    if let Some(v) = &a.poses {
        cfg.scene.poses = v.clone();
    }
    if let Some(v) = &a.tracks {
        cfg.humans.tracks = v.clone();
    }
    if let Some(v) = a.tracks_format {
        cfg.humans.tracks_format = v;
    }
    if let Some(v) = a.tracks_frame_period {
        cfg.humans.tracks_frame_period_s = v;
    }
    if let Some(v) = a.tracks_transform {
        cfg.humans.tracks_transform = v;
    }
    if let Some(v) = a.walk {
        cfg.humans.walk = v;
    }
    if !a.models.is_empty() {
        cfg.humans.models = a.models.clone();
    }
    if let Some(v) = a.motion {
        cfg.humans.motion = v;
    }
    if let Some(v) = a.backend {
        cfg.render.backend = v;
    }
    if let Some(v) = a.projection {
        cfg.render.projection = v;
    }
    if let Some(v) = a.refine {
        cfg.render.refine = v;
    }
    if let Some(v) = a.oversample {
        cfg.render.oversample = v;
    }
    if let Some(v) = a.velocity {
        cfg.output.velocity = v;
    }
    if let Some(v) = a.compression {
        cfg.output.compression = v;
    }
    if let Some(list) = &a.outputs {
        cfg.output.xyz = false;
        cfg.output.velocity_field = false;
        cfg.output.background = false;
        for o in list {
            match o.trim() {
                "range" | "label" | "instance" => {}
                "xyz" => cfg.output.xyz = true,
                "velocity" => cfg.output.velocity_field = true,
                "background" => cfg.output.background = true,
                other => {
                    return Err(pedscan::Error::input(
                        "--outputs",
                        format!("unknown output `{other}` (range, label, instance, xyz, velocity, background)"),
                    ))
                }
            }
        }
    }
    cfg.validate()?;
    Ok(cfg)
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Generate(args) => {
            let cfg = build_config(&args)?;
            let validation = args.validation || pedscan::gpu::validation_from_env();
            let summary = pedscan::run::generate(cfg, validation, true, args.export_geometry.clone())?;
            eprintln!("{summary}");
            if args.timings {
                eprintln!("{}", summary.timings);
            }
        }
        Command::Crosscheck { mut args, json, strip_png } => {
            // By default 4 sequences of 32 frames: over 100 frames.
            args.sequences = args.sequences.or(Some(4));
            let cfg = build_config(&args)?;
            let opts = pedscan::crosscheck::CrosscheckOptions {
                json,
                png: strip_png,
                export_geometry: args.export_geometry.clone(),
                validation: args.validation || pedscan::gpu::validation_from_env(),
            };
            let report = pedscan::crosscheck::crosscheck(cfg, &opts)?;
            println!("{report}");
        }
        Command::Bench { quick, config, json, markdown, plot, point, from_json } => {
            if let Some(src) = from_json {
                let text = std::fs::read_to_string(&src).with_context(|| src.display().to_string())?;
                let points: Vec<pedscan::bench::Point> = serde_json::from_str(&text)
                    .map_err(|e| pedscan::Error::input(src.display(), format!("not a bench JSON: {e}")))?;
                let table = pedscan::bench::markdown(&points);
                std::fs::write(&markdown, &table).with_context(|| markdown.display().to_string())?;
                pedscan::bench::plot(&points).save(&plot)?;
                print!("{table}");
                return Ok(());
            }
            let base = match &config {
                Some(p) => Config::from_file(p)?,
                None => Config::default(),
            };
            if let Some(spec) = point {
                let spec: pedscan::bench::PointSpec = serde_json::from_str(&spec).context("--point")?;
                let p = pedscan::bench::run_point(&base, &spec)?;
                println!("{}", serde_json::to_string(&p)?);
                return Ok(());
            }
            let exe = std::env::current_exe().context("locating the pedscan executable")?;
            let specs = pedscan::bench::sweep(quick);
            let n = specs.len();
            let points = pedscan::bench::run_sweep(&exe, config.as_deref(), &specs, |i, p| {
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
            let table = pedscan::bench::markdown(&points);
            std::fs::write(&markdown, &table).with_context(|| markdown.display().to_string())?;
            pedscan::bench::plot(&points).save(&plot)?;
            print!("{table}");
        }
        Command::Sheet { out, models, phases, validation } => {
            let models = if models.is_empty() { Config::default().humans.models } else { models };
            pedscan::sheet::write_contact_sheet(&models, &phases, &out, validation || pedscan::gpu::validation_from_env())?;
            eprintln!("wrote {}", out.display());
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
            let input = e.downcast_ref::<pedscan::Error>().is_some_and(|e| e.is_input());
            ExitCode::from(if input { 2 } else { 1 })
        }
    }
}
