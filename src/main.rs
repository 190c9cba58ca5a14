//! The `crease` command line: parses arguments and calls the library.

use clap::{Args, CommandFactory, Parser, Subcommand, ValueEnum};
use crease::synth::{self, Sampling, SynthOptions};
use crease::Error;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "crease",
    version,
    about = "Extracts sharp feature curves from laser scans larger than memory",
    after_help = "Exit codes: 0 done; 1 an output could not be written; 2 usage (a bad command line or value, a job that differs from its run directory's, a run directory in use); 65 bad input data (an input file missing, unreadable or malformed, a damaged run directory file); 70 internal error; 130 interrupted (the same command resumes)."
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Args, Clone)]
struct FilterArgs {
    /// Keep only these ASPRS classes (comma-separated, e.g. 2,6).
    #[arg(long, value_delimiter = ',')]
    classes: Option<Vec<u8>>,
    /// Keep withheld points and noise classes 7 and 18 (dropped by default).
    #[arg(long)]
    keep_noise: bool,
    /// Text clouds (.xyz, .pts, .csv, .txt): the columns of x, y, z and optionally the class,
    /// numbered from 0 (default: from a header line naming them, else the first three).
    #[arg(long, value_name = "X,Y,Z[,CLASS]")]
    columns: Option<String>,
    /// Text clouds: lines to skip before the first point (with --columns).
    #[arg(long, default_value_t = 0, requires = "columns")]
    skip_lines: usize,
    /// Keep only the points inside this box, faces included, in the inputs' units (4 values:
    /// any height). A COPC file decompresses only the octree nodes that meet it.
    #[arg(long, value_name = "XMIN,YMIN,[ZMIN,]XMAX,YMAX[,ZMAX]", value_delimiter = ',', allow_negative_numbers = true)]
    bounds: Option<Vec<f64>>,
}

impl FilterArgs {
    fn filter(&self) -> Result<crease::io::Filter, Error> {
        let text = self
            .columns
            .as_deref()
            .map(|c| crease::io::TextColumns::parse(c, self.skip_lines).map_err(|e| Error::Usage(format!("--columns {e}"))))
            .transpose()?;
        let bounds = self.bounds.as_deref().map(crease::points::Bounds::from_list).transpose().map_err(|e| Error::Usage(format!("--bounds {e}")))?;
        Ok(crease::io::Filter { classes: self.classes.clone(), keep_noise: self.keep_noise, text, bounds })
    }
}

/// Method parameters; lengths in model units, the input CRS's horizontal unit (`crease info`
/// names it; defaults are multiples of the spacing kappa).
#[derive(Args, Clone)]
struct ParamArgs {
    /// Point spacing kappa, in model units (default: median nearest-neighbour distance).
    #[arg(long)]
    kappa: Option<f64>,
    /// Candidate fit radius (default 6 kappa).
    #[arg(long)]
    fit_radius: Option<f64>,
    /// Robust projection radius (default 9 kappa).
    #[arg(long)]
    rmls_radius: Option<f64>,
    /// Residual threshold tau (default: mean residual).
    #[arg(long)]
    tau: Option<f64>,
    /// Polyline step s_max (default 4.5 kappa).
    #[arg(long)]
    step: Option<f64>,
    /// Largest turn while growing, degrees.
    #[arg(long)]
    max_turn: Option<f64>,
    /// Gentlest crease kept: degrees between the two surface normals (default 28).
    #[arg(long)]
    min_angle: Option<f64>,
    /// Random seed of the robust fits.
    #[arg(long)]
    seed: Option<u64>,
    /// Evaluate the candidate test and projection at about N points of each fit's
    /// neighbourhood instead of at every point (the fits still use every point): on noisy
    /// clouds, whose neighbourhoods hold up to 150 points, several times faster, at some
    /// recall where features are weak or thin (README: "Troubleshooting and tuning"). A clean cloud's
    /// neighbourhood holds about 25.
    #[arg(long, value_name = "N")]
    evaluate_per_fit: Option<f64>,
    /// How the projection searches for the surfaces meeting at a candidate: `balls`, one
    /// search per candidate; `cells`, one per cell of nearby candidates, shared (faster under
    /// noise, at a little recall and precision); `patches`, surfaces first: each candidate's
    /// ball split into the pieces of surface that the band of candidates separates, each
    /// searched on its own (experimental).
    #[arg(long, value_name = "MODEL", value_parser = parse_model)]
    model: Option<crease::extract::Model>,
}

fn parse_model(s: &str) -> Result<crease::extract::Model, String> {
    crease::extract::Model::parse(s).ok_or_else(|| format!("'{s}' is not a model: balls, cells or patches"))
}

impl ParamArgs {
    fn params(&self) -> Result<crease::extract::Params, Error> {
        let p = crease::extract::Params {
            kappa: self.kappa,
            fit_radius: self.fit_radius,
            rmls_radius: self.rmls_radius,
            tau: self.tau,
            step: self.step,
            max_turn_deg: self.max_turn,
            min_angle_deg: self.min_angle,
            seed: self.seed,
            evaluate_per_fit: self.evaluate_per_fit,
            model: self.model,
        };
        p.validate()?;
        Ok(p)
    }
}

#[derive(Subcommand)]
// (Parsed once per process: the size of its largest variant costs nothing.)
#[allow(clippy::large_enum_variant)]
enum Cmd {
    /// Prints format, point count, bounds, CRS and a spacing estimate for each input file.
    Info {
        /// Files or directories (all point files inside, sorted).
        #[arg(required = true)]
        paths: Vec<PathBuf>,
        /// Search directories' subdirectories too.
        #[arg(long, short)]
        recursive: bool,
        /// Machine-readable JSON output.
        #[arg(long)]
        json: bool,
    },
    /// Reads every point: true counts and bounds after filtering, read speed and peak memory.
    Scan {
        /// Files or directories.
        #[arg(required = true)]
        paths: Vec<PathBuf>,
        /// Search directories' subdirectories too.
        #[arg(long, short)]
        recursive: bool,
        #[command(flatten)]
        filter: FilterArgs,
        /// Machine-readable JSON output.
        #[arg(long)]
        json: bool,
    },
    /// Extracts feature curves; writes curves.obj, curves.ply and curves.geojson (or the --format asked for), preview.png and report.json.
    Extract(ExtractArgs),
    /// Writes RUN/slurm/: an extraction as a chain of Slurm jobs (plan and bucketing, one
    /// array job per tile pass, one growing the curves' blocks, then the stitching and
    /// outputs), each after the one before, over a run
    /// directory on a file system every node shares; with --submit, submits it. Takes the
    /// arguments of extract; those after -- become #SBATCH options of every job.
    Slurm(SlurmArgs),
    /// Tells what a run directory has done and what is left.
    Status {
        /// The run directory.
        dir: PathBuf,
        /// Machine-readable JSON output.
        #[arg(long)]
        json: bool,
    },
    /// Scores extracted curves against ground truth.
    Eval {
        /// Ground-truth curves (OBJ polylines).
        #[arg(long)]
        truth: PathBuf,
        /// Extracted curves (OBJ or crease PLY).
        #[arg(long)]
        curves: PathBuf,
        /// Length unit dB (default: the truth's bounding-box diagonal).
        #[arg(long)]
        diag: Option<f64>,
        /// Match tolerance in dB units.
        #[arg(long, default_value_t = 0.01)]
        tol: f64,
        /// Also score recall over the resolvable truth only: the truth farther than this
        /// separation (dB units) from any other, non-adjacent feature.
        #[arg(long)]
        resolvable: Option<f64>,
        /// Machine-readable JSON output.
        #[arg(long)]
        json: bool,
    },
    /// Writes RUN/view.html: the curves over a sample of the points, to turn and zoom in a
    /// browser (self-contained: WebGL, no network access).
    View {
        /// A finished run directory.
        dir: PathBuf,
    },
    /// Prints a shell completion script to stdout (e.g. `crease completions bash >
    /// ~/.local/share/bash-completion/completions/crease`).
    Completions {
        /// The shell.
        shell: clap_complete::Shell,
    },
    /// Prints a man page (roff) to stdout: crease(1), or with a subcommand its own page,
    /// crease-SUBCOMMAND(1) (e.g. `crease man extract > crease-extract.1; man ./crease-extract.1`);
    /// with --dir DIR, writes every page into DIR.
    Man {
        /// The subcommand whose page to print (default: the top page).
        subcommand: Option<String>,
        /// Write crease.1 and every crease-SUBCOMMAND.1 into this directory instead.
        #[arg(long, value_name = "DIR", conflicts_with = "subcommand")]
        dir: Option<PathBuf>,
    },
    /// Generates test clouds with ground-truth curves (OUT and OUT.truth.obj).
    Synth {
        #[command(subcommand)]
        what: SynthCmd,
    },
}

#[derive(Clone, Copy, ValueEnum)]
enum SamplingArg {
    Uniform,
    Scanlines,
    Nonuniform,
}

#[derive(Args)]
struct SampleArgs {
    /// Number of points.
    #[arg(short, default_value_t = 500_000)]
    n: usize,
    /// Noise level: points move by up to this many bounding-box diagonals.
    #[arg(long, default_value_t = 0.0)]
    noise: f64,
    /// Noise level in point spacings: points move by up to this many times the clean cloud's
    /// spacing kappa (scanner-like noise; instead of --noise).
    #[arg(long, default_value_t = 0.0, conflicts_with = "noise")]
    noise_spacing: f64,
    /// Share of points replaced by uniform outliers.
    #[arg(long, default_value_t = 0.0)]
    outliers: f64,
    /// Sampling pattern.
    #[arg(long, value_enum, default_value = "uniform")]
    sampling: SamplingArg,
    /// For scan-line sampling: line separation over along-line spacing.
    #[arg(long, default_value_t = 4.0)]
    anisotropy: f64,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output cloud (.las or .ply); truth goes to OUT.truth.obj.
    #[arg(short)]
    o: PathBuf,
}

impl SampleArgs {
    fn options(&self) -> Result<SynthOptions, Error> {
        let at_least = |x: f64, lo: f64| x >= lo;
        if !(0.0..=1.0).contains(&self.outliers) || !at_least(self.noise, 0.0) || !at_least(self.noise_spacing, 0.0) || !at_least(self.anisotropy, 1.0) {
            return Err(Error::Usage("--noise and --noise-spacing must be >= 0, --outliers in [0, 1], --anisotropy >= 1".into()));
        }
        let sampling = match self.sampling {
            SamplingArg::Uniform => Sampling::Uniform,
            SamplingArg::Scanlines => Sampling::ScanLines { anisotropy: self.anisotropy },
            SamplingArg::Nonuniform => Sampling::NonUniform,
        };
        Ok(SynthOptions { n: self.n, noise: self.noise, noise_spacing: self.noise_spacing, outliers: self.outliers, sampling, seed: self.seed })
    }
}

#[derive(Subcommand)]
enum SynthCmd {
    /// A CAD-like shape with analytic edges: cube, chamfer, holecube, cylinder, step,
    /// octahedron, fandisk, wedge (two planes at --angle degrees).
    Shape {
        /// Shape name.
        name: String,
        /// Dihedral angle of the wedge, in degrees.
        #[arg(long, default_value_t = 90.0)]
        angle: f64,
        #[command(flatten)]
        sample: SampleArgs,
    },
    /// Area-weighted sampling of a triangle mesh (.off or .obj); truth = sharp mesh edges.
    Mesh {
        /// The mesh.
        file: PathBuf,
        /// Edges whose face normals differ by more than this (degrees) are sharp.
        #[arg(long, default_value_t = 30.0)]
        angle: f64,
        #[command(flatten)]
        sample: SampleArgs,
    },
    /// A large outdoor scene (streets, curbs, buildings) streamed to LAS with constant memory.
    Scene {
        /// Number of points.
        #[arg(short, default_value_t = 10_000_000)]
        n: u64,
        /// Noise radius in metres.
        #[arg(long, default_value_t = 0.005)]
        noise: f64,
        /// Random seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Add clutter: a tree by the road of every block (volumetric scatter), a strip of rough
        /// grass, and recessed windows (whose edges are truth; trees and grass have none).
        #[arg(long)]
        clutter: bool,
        /// Output LAS file; truth goes to OUT.truth.obj.
        #[arg(short)]
        o: PathBuf,
    },
}

fn read_curves(path: &std::path::Path) -> Result<Vec<crease::curves::Polyline>, Error> {
    match path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).as_deref() {
        Some("ply") => crease::curves::read_ply(path),
        _ => crease::curves::read_obj(path),
    }
}

fn parse_crs(s: &str) -> Result<Box<crease::crs::Crs>, String> {
    crease::crs::Crs::parse_user(s).map(Box::new).map_err(|e| e.to_string())
}

fn warn(msg: &str) {
    eprintln!("crease: warning: {msg}");
}

/// The point files `paths` name (directories expanded), with a warning for what was passed over.
fn input_files(paths: &[PathBuf], recursive: bool) -> Result<Vec<PathBuf>, Error> {
    let inputs = crease::io::expand_inputs(paths, recursive)?;
    inputs.warnings(|_| false).iter().for_each(|w| warn(w));
    Ok(inputs.files)
}

fn run(cli: Cli) -> Result<(), Error> {
    match cli.cmd {
        Cmd::Info { paths, recursive, json } => {
            let files = input_files(&paths, recursive)?;
            let infos = files.iter().map(|f| crease::info::file_info(f)).collect::<Result<Vec<_>, _>>()?;
            if json {
                println!("{}", serde_json::to_string_pretty(&infos).expect("info serialises"));
            } else {
                print!("{}", crease::info::render_text(&infos));
            }
        }
        Cmd::Scan { paths, recursive, filter, json } => {
            let files = input_files(&paths, recursive)?;
            let t = Instant::now();
            let mut report = vec![];
            let mut total = 0u64;
            for f in &files {
                let s = crease::io::scan(f, &filter.filter()?)?;
                total += s.records;
                report.push(s);
            }
            let secs = t.elapsed().as_secs_f64();
            let rate = total as f64 / secs.max(1e-9);
            let peak = crease::mem::peak_rss();
            if json {
                let v = serde_json::json!({"files": report, "records": total, "seconds": secs, "points_per_second": rate, "peak_rss_bytes": peak});
                println!("{}", serde_json::to_string_pretty(&v).expect("serialises"));
            } else {
                for s in &report {
                    println!("{}: {} records, {} kept, min {:?} max {:?}", s.path.display(), s.records, s.kept, s.bounds.min, s.bounds.max);
                }
                println!("{total} records in {secs:.3} s: {:.1} M points/s, peak RSS {:.1} MB", rate / 1e6, peak as f64 / 1e6);
            }
        }
        Cmd::Eval { truth, curves, diag, tol, resolvable, json } => {
            let t = read_curves(&truth)?;
            let c = read_curves(&curves)?;
            let s = crease::eval::evaluate(&t, &c, &crease::eval::EvalOptions { diag, tol, resolvable, ..Default::default() });
            if json {
                println!("{}", serde_json::to_string_pretty(&s).expect("scores serialise"));
            } else {
                print!("{}", crease::eval::render_text(&s));
            }
        }
        Cmd::Synth { what } => synth_cmd(what)?,
        Cmd::Completions { shell } => clap_complete::generate(shell, &mut Cli::command(), "crease", &mut std::io::stdout()),
        Cmd::View { dir } => {
            let page = crease::run::write_view(&dir)?;
            let cleaned = crease::run::status(&dir).is_ok_and(|s| s.cleaned);
            eprintln!("wrote {}{}", page.display(), if cleaned { " (the curves alone: the run's points were removed with --clean)" } else { "" });
        }
        Cmd::Man { subcommand, dir } => man_cmd(subcommand.as_deref(), dir.as_deref())?,
        Cmd::Extract(args) => extract_cmd(args)?,
        Cmd::Slurm(args) => slurm_cmd(args)?,
        Cmd::Status { dir, json } => {
            let s = crease::run::status(&dir)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&s).expect("status serialises"));
            } else {
                print!("{}", crease::run::render_status(&s));
            }
        }
    }
    Ok(())
}

/// `crease man`: the top page, one subcommand's page (named crease-SUBCOMMAND, as the top
/// page's SEE ALSO names it), or all of them written into a directory.
fn man_cmd(subcommand: Option<&str>, dir: Option<&Path>) -> Result<(), Error> {
    let top = Cli::command();
    let page = |cmd: clap::Command, name: String| clap_mangen::Man::new(cmd.name(name.clone()).bin_name(name.replace('-', " ")));
    if let Some(dir) = dir {
        std::fs::create_dir_all(dir).map_err(|e| Error::output(dir, e))?;
        let mut pages = vec![("crease".to_string(), top.clone())];
        pages.extend(top.get_subcommands().filter(|c| c.get_name() != "help").map(|c| (format!("crease-{}", c.get_name()), c.clone())));
        for (name, cmd) in pages {
            let path = dir.join(format!("{name}.1"));
            let mut out = Vec::new();
            page(cmd, name).render(&mut out).map_err(|e| Error::output(&path, e))?;
            std::fs::write(&path, out).map_err(|e| Error::output(&path, e))?;
        }
        return Ok(());
    }
    let man = match subcommand {
        None => clap_mangen::Man::new(top),
        Some(name) => {
            let Some(cmd) = top.find_subcommand(name).filter(|c| c.get_name() != "help") else {
                let names: Vec<&str> = top.get_subcommands().map(|c| c.get_name()).filter(|&n| n != "help").collect();
                return Err(Error::Usage(format!("crease man: no subcommand '{name}' (one of {})", names.join(", "))));
            };
            page(cmd.clone(), format!("crease-{}", cmd.get_name()))
        }
    };
    man.render(&mut std::io::stdout()).map_err(|e| Error::output("stdout", e))
}

/// The arguments of `crease extract`.
#[derive(Args)]
struct ExtractArgs {
    /// Input files or directories (a directory is one cloud made of all its point files).
    #[arg(required = true)]
    paths: Vec<PathBuf>,
    /// Search directories' subdirectories too.
    #[arg(long, short)]
    recursive: bool,
    /// The curve files to write (comma-separated; preview.png and report.json always are).
    #[arg(long, value_delimiter = ',', default_values = ["obj", "ply", "geojson"])]
    format: Vec<crease::curves::Format>,
    /// Print a JSON summary of each run on stdout (its outputs and report).
    #[arg(long)]
    json: bool,
    /// Output directory.
    #[arg(short, long)]
    out: PathBuf,
    #[command(flatten)]
    filter: FilterArgs,
    #[command(flatten)]
    params: ParamArgs,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Memory budget, e.g. 1G or 512M (default: half of the machine's memory); sets the
    /// tile size (at most about 2 M points a tile).
    #[arg(long, value_parser = crease::mem::parse_size)]
    memory: Option<u64>,
    /// Tile edge length in model units (overrides the size derived from --memory).
    #[arg(long)]
    tile_size: Option<f64>,
    /// Start over, whatever the output directory holds (without it, a run continues the same
    /// job and refuses a different one).
    #[arg(long)]
    force: bool,
    /// Process each input file on its own, with outputs in OUT/<file stem>/.
    #[arg(long)]
    per_file: bool,
    /// Keep the working data (the tile store and per-tile results, about the size of a LAS
    /// input, more for noisy clouds) in this directory instead of the output directory's `work/`, e.g.
    /// on a scratch disk (with --per-file, in a subdirectory per file). A resumed run keeps
    /// the one it started with.
    #[arg(long, value_name = "DIR")]
    work_dir: Option<PathBuf>,
    /// Do the share of worker I of N processes working on the run side by side (on one
    /// machine, or over a cluster's shared file system, as a job array:
    /// `--worker $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT`): the tiles whose number modulo
    /// N is I, pass after pass, as far as the other workers' shares allow; worker 0 also plans,
    /// buckets and writes the outputs. Run again, a worker goes on where it stopped.
    #[arg(long, value_name = "I/N")]
    worker: Option<crease::run::Worker>,
    /// Remove the working data once the outputs are written. The run then cannot be resumed,
    /// given other output filters, or viewed over its points (`crease view` draws the curves
    /// alone).
    #[arg(long)]
    clean: bool,
    /// Print nothing but errors.
    #[arg(long, short)]
    quiet: bool,
    /// Side of the curve stage's growth blocks, in polyline steps (for tests and
    /// measurements of the stitcher).
    #[arg(long, hide = true, default_value_t = crease::extract::BASE_STEPS)]
    block_steps: f64,
    /// Write the intermediate point sets (candidates per tile, edge cloud, smoothed edge
    /// cloud, corners, grown polylines) to this directory as OBJ files (also taken from
    /// the environment variable CREASE_DEBUG_DIR).
    #[arg(long)]
    debug_dir: Option<PathBuf>,
    /// Leave out curves whose confidence (0 to 1, written to every output) is below this:
    /// higher trades recall for precision. Changing it on a finished run rewrites the
    /// outputs without recomputing the tiles.
    #[arg(long, default_value_t = crease::extract::DEFAULT_MIN_CONFIDENCE)]
    min_confidence: f64,
    /// Leave out curves shorter than this, in model units.
    #[arg(long, default_value_t = 0.0)]
    min_length: f64,
    /// The outputs' CRS, whatever the inputs say: EPSG:N or a WKT (an output setting, as
    /// --min-confidence; no reprojection).
    #[arg(long, value_name = "EPSG:N|WKT", value_parser = parse_crs)]
    a_srs: Option<Box<crease::crs::Crs>>,
    /// Where the scanners saw the surfaces from, which tells convex curves from concave ones
    /// (each curve's `shape`): `up` for airborne lidar and ground seen from above, scanner
    /// positions X,Y,Z (several separated by `;`; each vertex takes the nearest), or
    /// `unknown`. Default: the scan positions of E57 inputs, else unknown. An output setting,
    /// as --min-confidence.
    #[arg(long, value_name = "up|X,Y,Z[;X,Y,Z]|unknown", value_parser = crease::curves::Outside::parse)]
    outside: Option<crease::curves::Outside>,
    /// Also write a copy of each input file's points, in order and with all their fields, with
    /// three more: edge_distance (to the nearest curve), curve_id (that curve's id, -1 beyond
    /// the halo) and edge (1 within the typed curves' tolerance), to OUT/labels/<file stem>.laz
    /// (LAS 1.4 extra bytes; .ply with three more vertex properties for a PLY input). An
    /// output setting, as --min-confidence.
    #[arg(long)]
    label_points: bool,
}

#[derive(Args)]
struct SlurmArgs {
    /// Number of workers: the tasks of each array job.
    #[arg(long, default_value_t = 4)]
    tasks: u32,
    /// Submit the chain (sbatch must be on the path) and print its job ids.
    #[arg(long)]
    submit: bool,
    #[command(flatten)]
    extract: ExtractArgs,
    /// #SBATCH options for every job (after --), e.g. -- --partition=long --time=4:00:00.
    #[arg(last = true)]
    sbatch: Vec<String>,
}

fn slurm_cmd(a: SlurmArgs) -> Result<(), Error> {
    let e = &a.extract;
    for (given, flag) in [(e.worker.is_some(), "--worker"), (e.force, "--force"), (e.per_file, "--per-file")] {
        if given {
            return Err(Error::Usage(format!(
                "crease slurm: {flag} is not for a job chain (the chain gives each job its worker; remove or start a run over by hand)"
            )));
        }
    }
    // (The jobs run extract with the arguments given here, verbatim, but for slurm's own.)
    // (std::env::args panics on an argument that is not UTF-8; the scripts are text.)
    let raw: Vec<String> = std::env::args_os()
        .map(|x| x.into_string().map_err(|x| Error::Usage(format!("crease slurm: {} is not UTF-8, and the batch scripts are text", x.to_string_lossy()))))
        .collect::<Result<Vec<_>, _>>()?;
    let raw: Vec<String> = raw.into_iter().skip_while(|x| x != "slurm").skip(1).take_while(|x| x != "--").collect();
    let mut extract_args = vec![];
    let mut it = raw.into_iter();
    while let Some(x) = it.next() {
        match x.as_str() {
            "--tasks" => {
                it.next();
            }
            "--submit" => {}
            _ if x.starts_with("--tasks=") => {}
            _ => extract_args.push(x),
        }
    }
    let exe = std::env::current_exe().and_then(|p| p.canonicalize()).map_err(|err| Error::output("the crease binary", err))?;
    let workdir = std::env::current_dir().map_err(|err| Error::output(".", err))?;
    let run = workdir.join(&e.out);
    let chain = crease::slurm::Chain { exe, workdir, run: run.clone(), extract_args, tasks: a.tasks, sbatch_args: a.sbatch.clone() };
    let scripts = crease::slurm::write_chain(&chain)?;
    if a.submit {
        print!("{}", crease::slurm::submit(&run)?);
    } else {
        for s in &scripts {
            println!("{}", s.display());
        }
        eprintln!("submit with: bash {}", run.join("slurm").join("submit.sh").display());
    }
    Ok(())
}

fn extract_cmd(a: ExtractArgs) -> Result<(), Error> {
    if let Some(n) = a.threads {
        set_threads(n)?;
    }
    if a.out.as_os_str() == "-" {
        return Err(Error::Usage(
            "-o -: crease writes a run directory of several files, not a stream; name a directory (use --json for a summary on stdout)".into(),
        ));
    }
    let opts = run_options(&a);
    opts.validate()?;
    let params = a.params.params()?;
    let mut summaries = vec![];
    for (inputs, dir, work_dir) in extract_jobs(&a)? {
        let opts = crease::run::RunOptions { work_dir, ..opts.clone() };
        let r = match a.worker {
            None => crease::run::run_extract(&inputs, &dir, &params, &a.filter.filter()?, &opts)?,
            Some(w) => match crease::run::run_worker(&inputs, &dir, &params, &a.filter.filter()?, &opts, w)? {
                crease::run::WorkerStep::Finished(r) => *r,
                crease::run::WorkerStep::Waiting(what) => {
                    summaries.extend(worker_stopped(&a, &dir, w, Some(what)));
                    continue;
                }
                crease::run::WorkerStep::AlreadyFinished => {
                    summaries.extend(worker_stopped(&a, &dir, w, None));
                    continue;
                }
            },
        };
        if a.json {
            let mut outputs: Vec<PathBuf> = crease::run::OUTPUTS.iter().map(|f| dir.join(f)).filter(|f| f.is_file()).collect();
            outputs.extend(r.labels.iter().cloned());
            summaries.push(serde_json::json!({"dir": dir, "outputs": outputs, "report": r}));
        }
        if !a.quiet {
            eprintln!("{}", run_summary(&r, &dir));
        }
    }
    if a.json {
        // One object for one run; an array with --per-file.
        let v = if a.per_file { serde_json::Value::Array(summaries) } else { summaries.pop().unwrap_or_default() };
        println!("{}", serde_json::to_string_pretty(&v).expect("summary serialises"));
    }
    Ok(())
}

/// `--threads n`: the size of rayon's global pool, at most
/// [`crease::run::MAX_THREADS_PER_CORE`] a core.
fn set_threads(n: usize) -> Result<(), Error> {
    crease::run::check_threads(n)?;
    rayon::ThreadPoolBuilder::new().num_threads(n.max(1)).build_global().map_err(|e| Error::Usage(e.to_string()))
}

/// The run options `crease extract` gives, with Ctrl-C (and SIGTERM) cancelling the run.
fn run_options(a: &ExtractArgs) -> crease::run::RunOptions {
    let cancel = crease::cancel::Cancel::default();
    let _ = ctrlc::set_handler({
        let cancel = cancel.clone();
        move || cancel.set()
    });
    let defaults = crease::run::RunOptions::default();
    crease::run::RunOptions {
        memory: a.memory.unwrap_or(defaults.memory),
        tile_size: a.tile_size,
        force: a.force,
        progress: if a.quiet { crease::progress::Mode::Quiet } else { crease::progress::Mode::Auto },
        watch: None,
        cancel,
        debug: crease::debug::DebugDump::new(a.debug_dir.clone().or_else(|| std::env::var_os("CREASE_DEBUG_DIR").map(PathBuf::from))),
        min_confidence: a.min_confidence,
        min_length: a.min_length,
        warn,
        assign_crs: a.a_srs.as_deref().cloned(),
        outside: a.outside.clone(),
        recursive: a.recursive,
        formats: a.format.clone(),
        label_points: a.label_points,
        work_dir: None,
        clean: a.clean,
        block_steps: a.block_steps,
    }
}

/// One run of `crease extract`: its inputs, its run directory and its work directory, if any.
type ExtractJob = (Vec<PathBuf>, PathBuf, Option<PathBuf>);

/// The runs `crease extract` makes: one, or one a file with `--per-file`.
fn extract_jobs(a: &ExtractArgs) -> Result<Vec<ExtractJob>, Error> {
    if !a.per_file {
        return Ok(vec![(a.paths.clone(), a.out.clone(), a.work_dir.clone())]);
    }
    Ok(input_files(&a.paths, a.recursive)?
        .into_iter()
        .map(|f| {
            let stem = f.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            let work = a.work_dir.as_ref().map(|w| w.join(&stem));
            (vec![f], a.out.join(stem), work)
        })
        .collect())
}

/// What a worker that did not write the outputs says, `waiting` for what it waits for or None
/// if the run had finished: on stderr unless quiet, and as the JSON summary of its run with
/// `--json`.
fn worker_stopped(a: &ExtractArgs, dir: &Path, w: crease::run::Worker, waiting: Option<String>) -> Option<serde_json::Value> {
    let worker = format!("{}/{}", w.index, w.count);
    let (said, summary) = match waiting {
        Some(what) => (
            format!("worker {worker}: its share is done as far as it goes; waiting for {what}: run it again to go on ({})", dir.display()),
            serde_json::json!({"dir": dir, "worker": worker, "waiting": what}),
        ),
        None => (
            format!("worker {worker}: the run is finished; its outputs are in {}", dir.display()),
            serde_json::json!({"dir": dir, "worker": worker, "finished": true}),
        ),
    };
    if !a.quiet {
        eprintln!("{said}");
    }
    a.json.then_some(summary)
}

/// The line `crease extract` prints for a finished run.
fn run_summary(r: &crease::run::Report, dir: &Path) -> String {
    let shapes = match r.outside {
        crease::curves::Outside::Unknown => String::new(),
        _ => format!(" ({} convex, {} concave)", r.shapes.convex, r.shapes.concave),
    };
    format!(
        "{} curves{shapes} from {} points in {:.2} s ({} tiles{}; kappa {:.4}, tau {:.4}, {} candidates, {} edge points, {} corners); outputs in {}",
        r.counts.curves,
        r.counts.points,
        r.total_seconds,
        r.tiles,
        if r.resumed { ", resumed" } else { "" },
        r.params.kappa,
        r.tau,
        r.counts.candidates,
        r.counts.edge_points,
        r.counts.corners,
        dir.display()
    )
}

fn synth_cmd(what: SynthCmd) -> Result<(), Error> {
    let t = Instant::now();
    let (out, n) = match what {
        SynthCmd::Shape { name, angle, sample } => {
            let shape = synth::shape(&name, angle).ok_or_else(|| Error::Usage(format!("unknown shape '{name}' (one of: {})", synth::SHAPES.join(", "))))?;
            let n = synth::write_sampled(&shape, &sample.options()?, &sample.o)?;
            (sample.o, n as u64)
        }
        SynthCmd::Mesh { file, angle, sample } => {
            let mesh = synth::read_mesh(&file)?;
            let n = synth::write_sampled(&mesh.to_shape(angle), &sample.options()?, &sample.o)?;
            (sample.o, n as u64)
        }
        SynthCmd::Scene { n, noise, seed, clutter, o } => {
            let n = synth::write_scene(&synth::SceneOptions { n, noise, seed, clutter }, &o)?;
            (o, n)
        }
    };
    eprintln!(
        "wrote {n} points to {} and truth to {} in {:.1} s (peak RSS {:.0} MB)",
        out.display(),
        synth::truth_path(&out).display(),
        t.elapsed().as_secs_f64(),
        crease::mem::peak_rss() as f64 / 1e6
    );
    Ok(())
}

fn main() -> ExitCode {
    // A reader that closes the pipe early (`crease info --json | head`) ends crease as it ends
    // any Unix tool, quietly, rather than with a panic on the failed write. (A run stopped this
    // way resumes like any other.)
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of one signal, before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    crease::mem::map_large_blocks_apart();
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("crease: error: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}
