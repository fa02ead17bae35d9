//! The operator workflows as library calls, shared by `ident demo`, `ident replay`,
//! `ident nightly`, `ident sweep` and the report folders of `ident identify|diagnose --out`:
//!
//! ```text
//! sweep (stand → session.mcap) → process (session → characteristics) → identify → diagnose → report
//! ```
//!
//! - [`measure`]: a stepped-sine or broadband measurement of a stand into a new session file,
//!   the simulated stand serving its `"sim"` ports; the file is completed whatever happens.
//! - [`analysis`]: everything after the measurement, read from the session file alone
//!   ([`analyse`]: `acquire::analysis` → `identify::request::Problem` → `diagnose::request`), so
//!   a replay of a recording recomputes the live run's results bit for bit.
//! - [`sessions`]: the newest finished session in a folder (for a workflow that does not measure).
//! - [`folder`]: the report of a run ([`build_report`]) and its dated report folder
//!   ([`write_report`]: HTML, JSON, the identification's table and models, the final model).
//!
//! What the steps did that an operator should know comes back as [`Note`]s (the caller prints
//! them); failures are [`PipelineError`]s naming the file and the fix.
//!
//! ```no_run
//! use std::path::Path;
//! let setup = pipeline::Setup::load(
//!     Path::new("configs/models/fwd32j-no-actuator.toml"),
//!     Path::new("configs/identification/fwd32j-no-actuator.toml"),
//!     &mut |note| eprintln!("{note}"),
//! )?;
//! let a = pipeline::analyse(Path::new("session.mcap"), &setup, &pipeline::identification_options())?;
//! print!("{}", pipeline::summary_text(&a));
//! # Ok::<(), pipeline::PipelineError>(())
//! ```

// No panic on anything from a file, a device or a user.
#![warn(clippy::expect_used)]

pub mod analysis;
mod error;
pub mod folder;
pub mod measure;
mod note;
pub mod sessions;
mod setup;

pub use analysis::{analyse, identification_options, summary_text, Analysis};
pub use error::PipelineError;
pub use folder::{build_report, dated_folder, final_files, write_report, ReportContext};
pub use measure::{
    broadband_sweep, runtime, sweep, BroadbandSwept, MeasureError, SweepOptions, Swept,
};
pub use note::Note;
pub use setup::Setup;
