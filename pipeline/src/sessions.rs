//! The session a workflow analyses when it does not measure: the newest finished session file
//! in a folder. A session whose writer did not finish it (a sweep killed mid-way, power lost, or
//! one still being written) lacks the MCAP end magic and is skipped with a [`Note`]: a partial
//! session is never identified as if complete (`ident mcap recover` makes a readable copy).

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use crate::error::PipelineError;
use crate::note::Note;

/// Whether a session file was finished by its writer: it ends with the MCAP magic (MCAP
/// specification), which a killed writer never wrote.
pub fn finished(path: &Path) -> std::io::Result<bool> {
    let magic = mcap::MAGIC;
    let mut f = File::open(path)?;
    let len = f.metadata()?.len();
    // A finished file holds the magic at both ends.
    if len < 2 * magic.len() as u64 {
        return Ok(false);
    }
    f.seek(SeekFrom::Start(len - magic.len() as u64))?;
    let mut tail = vec![0u8; magic.len()];
    f.read_exact(&mut tail)?;
    Ok(tail == magic)
}

/// The newest finished `*.mcap` in `dir` by modification time. Newer unfinished or unreadable
/// sessions are skipped, each with a [`Note::SkippedSession`] saying why.
pub fn newest_finished(dir: &Path, note: &mut dyn FnMut(Note)) -> Result<PathBuf, PipelineError> {
    let entries = std::fs::read_dir(dir).map_err(|source| PipelineError::SessionFolder {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut all: Vec<(std::time::SystemTime, PathBuf)> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
        .map(|p| {
            let t = std::fs::metadata(&p)
                .and_then(|m| m.modified())
                .unwrap_or(std::time::UNIX_EPOCH);
            (t, p)
        })
        .collect();
    all.sort();
    let any = !all.is_empty();
    while let Some((_, p)) = all.pop() {
        match finished(&p) {
            Ok(true) => return Ok(p),
            Ok(false) => note(Note::SkippedSession {
                path: p,
                unreadable: None,
            }),
            Err(e) => note(Note::SkippedSession {
                path: p,
                unreadable: Some(e.to_string()),
            }),
        }
    }
    Err(PipelineError::NoSession {
        dir: dir.to_path_buf(),
        unfinished: any,
    })
}
