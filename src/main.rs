//! The `crease` command line: parses arguments and calls the library.

use clap::{Parser, Subcommand};
use crease::Error;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "crease", version, about = "Extracts sharp feature curves from laser scans larger than memory")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Prints format, point count, bounds, CRS and a spacing estimate for each input file.
    Info {
        /// Files or directories (all .las, .laz, .ply inside, sorted).
        #[arg(required = true)]
        paths: Vec<PathBuf>,
        /// Machine-readable JSON output.
        #[arg(long)]
        json: bool,
    },
    /// Extracts feature curves (not implemented yet).
    Extract {
        /// Input files or directories.
        paths: Vec<PathBuf>,
    },
    /// Scores extracted curves against ground truth (not implemented yet).
    Eval,
    /// Generates test clouds with ground-truth curves (not implemented yet).
    Synth,
}

fn run(cli: Cli) -> Result<(), Error> {
    match cli.cmd {
        Cmd::Info { paths, json } => {
            let files = crease::io::expand_inputs(&paths)?;
            let infos = files.iter().map(|f| crease::info::file_info(f)).collect::<Result<Vec<_>, _>>()?;
            if json {
                println!("{}", serde_json::to_string_pretty(&infos).expect("info serialises"));
            } else {
                print!("{}", crease::info::render_text(&infos));
            }
            Ok(())
        }
        Cmd::Extract { .. } | Cmd::Eval | Cmd::Synth => Err(Error::Usage("not implemented yet".into())),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("crease: error: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}
