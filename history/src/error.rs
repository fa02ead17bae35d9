//! What can go wrong with a history database, each case naming the file and the fix.

use std::path::PathBuf;

/// A history database could not be opened, read or written.
#[derive(Debug, thiserror::Error)]
pub enum HistoryError {
    /// Another process holds a write lock longer than the wait.
    #[error("the history database {path} is locked by another process (a nightly or an `ident history` still running?); nothing was written: retry when it has finished")]
    Locked {
        /// The database file.
        path: PathBuf,
    },
    /// The file is not a SQLite database, or is damaged.
    #[error("the history database {path} is damaged or not a history database ({detail}); nothing was written: move it aside and re-create it with `ident history import`, or restore a backup")]
    Corrupt {
        /// The database file.
        path: PathBuf,
        /// What SQLite said.
        detail: String,
    },
    /// Written by a newer ident.
    #[error("the history database {path} has schema version {found}, newer than this ident's {supported}; nothing was written: use the newer ident, or give another file")]
    NewerVersion {
        /// The database file.
        path: PathBuf,
        /// Its `schema_version`.
        found: i64,
        /// The newest this build reads.
        supported: i64,
    },
    /// Any other SQLite failure (disk full, permissions).
    #[error("the history database {path}: {source}")]
    Sqlite {
        /// The database file.
        path: PathBuf,
        /// SQLite's error.
        source: rusqlite::Error,
    },
    /// The `[drift] baseline` run named is not among the earlier runs.
    #[error("baseline run \"{name}\" is not among the {runs} earlier reports; set `baseline` to one of their folder names or \"first\"")]
    NoSuchBaseline {
        /// The name asked for.
        name: String,
        /// Earlier runs there are.
        runs: usize,
    },
    /// A report folder could not be imported.
    #[error("cannot import {path}: {detail}")]
    Import {
        /// The report file.
        path: PathBuf,
        /// Why.
        detail: String,
    },
}

impl HistoryError {
    /// Classifies a SQLite error on `path`: busy/locked and corrupt/not-a-database get their own
    /// cases.
    pub(crate) fn from_sqlite(path: &std::path::Path, e: rusqlite::Error) -> HistoryError {
        use rusqlite::ErrorCode as C;
        match e.sqlite_error_code() {
            Some(C::DatabaseBusy | C::DatabaseLocked) => HistoryError::Locked {
                path: path.to_path_buf(),
            },
            Some(C::NotADatabase | C::DatabaseCorrupt) => HistoryError::Corrupt {
                path: path.to_path_buf(),
                detail: e.to_string(),
            },
            _ => HistoryError::Sqlite {
                path: path.to_path_buf(),
                source: e,
            },
        }
    }
}
