//! The history database: one SQLite file, WAL journal (readers keep reading while a run is
//! appended), each run appended in one transaction (a crash mid-write loses that run only, never
//! one committed before). The schema version is SQLite's `user_version`; a file from a newer
//! ident is refused before anything is written.

use std::path::{Path, PathBuf};
use std::time::Duration;

use rusqlite::{params, Connection, OpenFlags, OptionalExtension};

use crate::error::HistoryError;
use crate::record::{CharacteristicFit, Correlation, Covariate, ParameterRecord, RunRecord};

/// The schema this build writes and reads (2: Cramér-Rao correlations per run; 3: derived
/// quantities per run, the stable cutting depth). An older file is upgraded when opened for
/// writing, and read as it is.
pub const SCHEMA_VERSION: i64 = 3;

/// How long a writer waits for another writer before [`HistoryError::Locked`].
pub const BUSY_WAIT: Duration = Duration::from_secs(5);

const SCHEMA: &str = "
CREATE TABLE runs (
    id INTEGER PRIMARY KEY,
    run_id TEXT NOT NULL UNIQUE,
    time_utc TEXT NOT NULL,
    stand TEXT,
    model_hash TEXT NOT NULL,
    session TEXT,
    outcome TEXT NOT NULL,
    reduced_chi2 REAL
);
CREATE TABLE parameters (
    run INTEGER NOT NULL REFERENCES runs(id),
    variable TEXT NOT NULL,
    unit TEXT NOT NULL,
    unit_factor REAL NOT NULL,
    estimate REAL NOT NULL,
    std_error REAL,
    PRIMARY KEY (run, variable)
);
CREATE TABLE characteristics (
    run INTEGER NOT NULL REFERENCES runs(id),
    label TEXT NOT NULL,
    rms_relative_error REAL NOT NULL
);
CREATE TABLE effects (
    run INTEGER NOT NULL REFERENCES runs(id),
    effect TEXT NOT NULL
);
CREATE TABLE covariates (
    run INTEGER NOT NULL REFERENCES runs(id),
    name TEXT NOT NULL,
    unit TEXT NOT NULL,
    value REAL NOT NULL
);
CREATE INDEX runs_by_time ON runs(time_utc, id);
";

/// Version 1 → 2: the Cramér-Rao correlations of each run.
const SCHEMA_2: &str = "
CREATE TABLE correlations (
    run INTEGER NOT NULL REFERENCES runs(id),
    a TEXT NOT NULL,
    b TEXT NOT NULL,
    value REAL NOT NULL
);
";

/// Version 2 → 3: quantities derived from the final model and judged like the parameters (the
/// minimum critical depth of a cut), in the parameters' row shape.
const SCHEMA_3: &str = "
CREATE TABLE quantities (
    run INTEGER NOT NULL REFERENCES runs(id),
    name TEXT NOT NULL,
    unit TEXT NOT NULL,
    unit_factor REAL NOT NULL,
    value REAL NOT NULL,
    std_error REAL,
    PRIMARY KEY (run, name)
);
";

/// An open history database.
pub struct Store {
    conn: Connection,
    path: PathBuf,
}

impl Store {
    /// Opens `path` for appending, creating it (and its schema) when it does not exist.
    pub fn open(path: &Path) -> Result<Store, HistoryError> {
        let err = |e| HistoryError::from_sqlite(path, e);
        let conn = Connection::open_with_flags(
            path,
            OpenFlags::SQLITE_OPEN_READ_WRITE
                | OpenFlags::SQLITE_OPEN_CREATE
                | OpenFlags::SQLITE_OPEN_NO_MUTEX,
        )
        .map_err(err)?;
        conn.busy_timeout(BUSY_WAIT).map_err(err)?;
        let mut store = Store {
            conn,
            path: path.to_path_buf(),
        };
        store.check_version()?;
        // WAL: readers see the last committed run while a writer appends; FULL sync: a committed
        // run survives a power loss too.
        store
            .conn
            .pragma_update_and_check(None, "journal_mode", "WAL", |r| r.get::<_, String>(0))
            .map_err(err)?;
        store
            .conn
            .pragma_update(None, "synchronous", "FULL")
            .map_err(err)?;
        store
            .conn
            .pragma_update(None, "foreign_keys", true)
            .map_err(err)?;
        let version = store.version()?;
        if version < SCHEMA_VERSION {
            // Each step from the file's version up, in one transaction.
            let tx = store.conn.transaction().map_err(err)?;
            if version == 0 {
                tx.execute_batch(SCHEMA).map_err(err)?;
            }
            if version < 2 {
                tx.execute_batch(SCHEMA_2).map_err(err)?;
            }
            tx.execute_batch(SCHEMA_3).map_err(err)?;
            tx.pragma_update(None, "user_version", SCHEMA_VERSION)
                .map_err(err)?;
            tx.commit().map_err(err)?;
        }
        Ok(store)
    }

    /// Opens an existing database for reading only (`ident history`): never creates or changes
    /// the file.
    pub fn open_read_only(path: &Path) -> Result<Store, HistoryError> {
        let err = |e| HistoryError::from_sqlite(path, e);
        if !path.is_file() {
            return Err(HistoryError::Sqlite {
                path: path.to_path_buf(),
                source: rusqlite::Error::InvalidPath(path.to_path_buf()),
            });
        }
        let conn = Connection::open_with_flags(
            path,
            OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
        )
        .map_err(err)?;
        conn.busy_timeout(BUSY_WAIT).map_err(err)?;
        let store = Store {
            conn,
            path: path.to_path_buf(),
        };
        store.check_version()?;
        if store.version()? == 0 {
            return Err(HistoryError::Corrupt {
                path: path.to_path_buf(),
                detail: "it has no history schema".into(),
            });
        }
        Ok(store)
    }

    /// The database file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn version(&self) -> Result<i64, HistoryError> {
        self.conn
            .pragma_query_value(None, "user_version", |r| r.get(0))
            .map_err(|e| HistoryError::from_sqlite(&self.path, e))
    }

    /// Refuses a newer schema, and a SQLite file that holds other tables than a history.
    fn check_version(&self) -> Result<(), HistoryError> {
        let v = self.version()?;
        if v > SCHEMA_VERSION {
            return Err(HistoryError::NewerVersion {
                path: self.path.clone(),
                found: v,
                supported: SCHEMA_VERSION,
            });
        }
        if v == 0 {
            let tables: i64 = self
                .conn
                .query_row(
                    "SELECT count(*) FROM sqlite_master WHERE type = 'table'",
                    [],
                    |r| r.get(0),
                )
                .map_err(|e| HistoryError::from_sqlite(&self.path, e))?;
            if tables > 0 {
                return Err(HistoryError::Corrupt {
                    path: self.path.clone(),
                    detail: format!("a SQLite file with {tables} tables but no history schema"),
                });
            }
        }
        Ok(())
    }

    /// Whether a run named `run_id` is stored.
    pub fn contains(&self, run_id: &str) -> Result<bool, HistoryError> {
        self.conn
            .query_row("SELECT 1 FROM runs WHERE run_id = ?1", [run_id], |_| Ok(()))
            .optional()
            .map(|r| r.is_some())
            .map_err(|e| HistoryError::from_sqlite(&self.path, e))
    }

    /// Appends one run in one transaction (all its rows or none). A run id already stored is an
    /// error (nothing is overwritten).
    pub fn append(&mut self, run: &RunRecord) -> Result<(), HistoryError> {
        let path = self.path.clone();
        let err = |e| HistoryError::from_sqlite(&path, e);
        let tx = self.conn.transaction().map_err(err)?;
        tx.execute(
            "INSERT INTO runs (run_id, time_utc, stand, model_hash, session, outcome, reduced_chi2)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
            params![
                run.run_id,
                run.time_utc,
                run.stand,
                run.model_hash,
                run.session,
                run.outcome,
                run.reduced_chi2
            ],
        )
        .map_err(err)?;
        let id = tx.last_insert_rowid();
        for p in &run.parameters {
            tx.execute(
                "INSERT INTO parameters (run, variable, unit, unit_factor, estimate, std_error)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
                params![
                    id,
                    p.variable,
                    p.unit,
                    p.unit_factor,
                    p.estimate,
                    p.std_error
                ],
            )
            .map_err(err)?;
        }
        for c in &run.characteristics {
            tx.execute(
                "INSERT INTO characteristics (run, label, rms_relative_error) VALUES (?1, ?2, ?3)",
                params![id, c.label, c.rms_relative_error],
            )
            .map_err(err)?;
        }
        for e in &run.effects {
            tx.execute(
                "INSERT INTO effects (run, effect) VALUES (?1, ?2)",
                params![id, e],
            )
            .map_err(err)?;
        }
        for c in &run.covariates {
            tx.execute(
                "INSERT INTO covariates (run, name, unit, value) VALUES (?1, ?2, ?3, ?4)",
                params![id, c.name, c.unit, c.value],
            )
            .map_err(err)?;
        }
        for q in &run.quantities {
            tx.execute(
                "INSERT INTO quantities (run, name, unit, unit_factor, value, std_error)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
                params![
                    id,
                    q.variable,
                    q.unit,
                    q.unit_factor,
                    q.estimate,
                    q.std_error
                ],
            )
            .map_err(err)?;
        }
        for c in run.correlations.iter().filter(|c| c.value.is_finite()) {
            tx.execute(
                "INSERT INTO correlations (run, a, b, value) VALUES (?1, ?2, ?3, ?4)",
                params![id, c.a, c.b, c.value],
            )
            .map_err(err)?;
        }
        tx.commit().map_err(err)
    }

    /// Every stored run, oldest first (by time, then by order of appending).
    pub fn runs(&self) -> Result<Vec<RunRecord>, HistoryError> {
        let err = |e| HistoryError::from_sqlite(&self.path, e);
        let mut stmt = self
            .conn
            .prepare(
                "SELECT id, run_id, time_utc, stand, model_hash, session, outcome, reduced_chi2
                 FROM runs ORDER BY time_utc, id",
            )
            .map_err(err)?;
        let heads = stmt
            .query_map([], |r| {
                Ok((
                    r.get::<_, i64>(0)?,
                    RunRecord {
                        run_id: r.get(1)?,
                        time_utc: r.get(2)?,
                        stand: r.get(3)?,
                        model_hash: r.get(4)?,
                        session: r.get(5)?,
                        outcome: r.get(6)?,
                        reduced_chi2: r.get(7)?,
                        parameters: Vec::new(),
                        characteristics: Vec::new(),
                        effects: Vec::new(),
                        covariates: Vec::new(),
                        correlations: Vec::new(),
                        quantities: Vec::new(),
                    },
                ))
            })
            .map_err(err)?
            .collect::<Result<Vec<_>, _>>()
            .map_err(err)?;
        let mut p = self
            .conn
            .prepare("SELECT variable, unit, unit_factor, estimate, std_error FROM parameters WHERE run = ?1 ORDER BY rowid")
            .map_err(err)?;
        let mut c = self
            .conn
            .prepare("SELECT label, rms_relative_error FROM characteristics WHERE run = ?1 ORDER BY rowid")
            .map_err(err)?;
        let mut e = self
            .conn
            .prepare("SELECT effect FROM effects WHERE run = ?1 ORDER BY rowid")
            .map_err(err)?;
        let mut v = self
            .conn
            .prepare("SELECT name, unit, value FROM covariates WHERE run = ?1 ORDER BY rowid")
            .map_err(err)?;
        // A version-1 file (read only, not upgraded) has no correlations.
        let mut k = if self.version()? >= 2 {
            Some(
                self.conn
                    .prepare("SELECT a, b, value FROM correlations WHERE run = ?1 ORDER BY rowid")
                    .map_err(err)?,
            )
        } else {
            None
        };
        // A file older than version 3 (read only, not upgraded) has no quantities.
        let mut q = if self.version()? >= 3 {
            Some(
                self.conn
                    .prepare("SELECT name, unit, unit_factor, value, std_error FROM quantities WHERE run = ?1 ORDER BY rowid")
                    .map_err(err)?,
            )
        } else {
            None
        };
        let mut out = Vec::with_capacity(heads.len());
        for (id, mut run) in heads {
            run.parameters = p
                .query_map([id], parameter_record)
                .and_then(|rows| rows.collect())
                .map_err(err)?;
            run.characteristics = c
                .query_map([id], |r| {
                    Ok(CharacteristicFit {
                        label: r.get(0)?,
                        rms_relative_error: r.get(1)?,
                    })
                })
                .and_then(|rows| rows.collect())
                .map_err(err)?;
            run.effects = e
                .query_map([id], |r| r.get(0))
                .and_then(|rows| rows.collect())
                .map_err(err)?;
            run.covariates = v
                .query_map([id], |r| {
                    Ok(Covariate {
                        name: r.get(0)?,
                        unit: r.get(1)?,
                        value: r.get(2)?,
                    })
                })
                .and_then(|rows| rows.collect())
                .map_err(err)?;
            if let Some(k) = k.as_mut() {
                run.correlations = k
                    .query_map([id], |r| {
                        Ok(Correlation {
                            a: r.get(0)?,
                            b: r.get(1)?,
                            value: r.get(2)?,
                        })
                    })
                    .and_then(|rows| rows.collect())
                    .map_err(err)?;
            }
            if let Some(q) = q.as_mut() {
                run.quantities = q
                    .query_map([id], parameter_record)
                    .and_then(|rows| rows.collect())
                    .map_err(err)?;
            }
            out.push(run);
        }
        Ok(out)
    }
}

/// A `parameters` or `quantities` row (variable or name, unit, unit factor, value, standard
/// error) as the record both tables store.
fn parameter_record(r: &rusqlite::Row) -> rusqlite::Result<ParameterRecord> {
    Ok(ParameterRecord {
        variable: r.get(0)?,
        unit: r.get(1)?,
        unit_factor: r.get(2)?,
        estimate: r.get(3)?,
        std_error: r.get(4)?,
    })
}
