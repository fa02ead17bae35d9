//! `ident mcap recover SESSION.mcap`: rewrite a truncated session (a crash, `kill -9`, a full disk)
//! into a valid MCAP file with a summary, keeping every message of every complete chunk.

use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `ident mcap`.
#[derive(clap::Args)]
pub struct McapArgs {
    #[command(subcommand)]
    action: Action,
}

#[derive(clap::Subcommand)]
enum Action {
    /// Rewrite a truncated session file into a valid one (the input is never modified).
    Recover {
        /// The session file.
        input: PathBuf,
        /// Output file (default: INPUT with `.recovered.mcap`); never overwritten.
        #[arg(long, short)]
        output: Option<PathBuf>,
    },
}

/// Runs `ident mcap`.
pub fn run(args: McapArgs) -> anyhow::Result<ExitCode> {
    match args.action {
        Action::Recover { input, output } => {
            let output = output.unwrap_or_else(|| acquire::session::recovered_path(&input));
            let r = acquire::session::recover(&input, &output)?;
            println!(
                "{}: {} messages recovered into {}",
                r.input, r.messages, r.output
            );
            match r.truncated {
                Some(why) => println!("the input was truncated: {why}; everything after the last complete chunk is lost"),
                None => println!("the input was complete"),
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}
