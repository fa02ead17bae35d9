//! CSV as every CSV file of the project is written and read: RFC 4180 through the `csv` crate (a
//! field is quoted when it holds a comma, a quote or a line break, and a quote inside it is
//! doubled), `\n` line ends, whole-line `#` comments (which carry declarations such as
//! `# unit = g/N` before the header) and blank lines skipped, cells trimmed.

/// A CSV text being written, row by row, into memory.
#[derive(Debug, Default)]
pub struct CsvText {
    out: Vec<u8>,
}

impl CsvText {
    /// An empty text.
    pub fn new() -> CsvText {
        CsvText::default()
    }

    /// Appends a `# text` comment line (line breaks in `text` become spaces).
    pub fn comment(&mut self, text: &str) {
        self.out.extend_from_slice(b"# ");
        self.out
            .extend_from_slice(text.replace(['\r', '\n'], " ").as_bytes());
        self.out.push(b'\n');
    }

    /// Appends one row, each field quoted where it needs to be.
    pub fn row<I, F>(&mut self, fields: I)
    where
        I: IntoIterator<Item = F>,
        F: AsRef<[u8]>,
    {
        let mut writer = csv::WriterBuilder::new()
            .terminator(csv::Terminator::Any(b'\n'))
            .buffer_capacity(256)
            .from_writer(&mut self.out);
        // Writing into memory has no I/O to fail, and one record per writer leaves no
        // equal-length check to fail, so neither call returns an error here.
        let _ = writer.write_record(fields);
        let _ = writer.flush();
    }

    /// The text.
    pub fn finish(self) -> String {
        // Every field came in as UTF-8 text, so the bytes are UTF-8.
        String::from_utf8_lossy(&self.out).into_owned()
    }
}

/// One row read: its 1-based line in the text and its cells, trimmed.
#[derive(Debug, Clone, PartialEq)]
pub struct CsvRow {
    /// Line the row starts on (1-based).
    pub line: usize,
    /// Cells, trimmed of surrounding white space, quotes removed.
    pub cells: Vec<String>,
}

/// A text that is not CSV: the line where reading stopped and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {line}: {message}")]
pub struct CsvError {
    /// Line (1-based).
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

/// The rows of a CSV text, header included, without comment lines (`#` first after any white
/// space) and blank lines. Each row is one line (a quoted field does not span lines, which keeps
/// every row's line number exact). Rows may differ in length: the caller checks them against
/// its header.
pub fn rows(text: &str) -> Result<Vec<CsvRow>, CsvError> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .trim(csv::Trim::All)
            .buffer_capacity(line.len().max(64))
            .from_reader(line.as_bytes());
        let mut record = csv::StringRecord::new();
        reader.read_record(&mut record).map_err(|e| CsvError {
            line: i + 1,
            message: e.to_string(),
        })?;
        out.push(CsvRow {
            line: i + 1,
            cells: record.iter().map(str::to_string).collect(),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn fields_are_quoted_only_where_needed_and_read_back() {
        let mut t = CsvText::new();
        t.comment("source: a\nb");
        t.row(["body", "note"]);
        t.row(["table", "plain"]);
        t.row(["head, left", "say \"hi\""]);
        t.row(["", "2"]);
        let text = t.finish();
        assert_eq!(
            text,
            "# source: a b\nbody,note\ntable,plain\n\"head, left\",\"say \"\"hi\"\"\"\n,2\n"
        );
        let rows = rows(&text).unwrap();
        let cells: Vec<Vec<&str>> = rows
            .iter()
            .map(|r| r.cells.iter().map(String::as_str).collect())
            .collect();
        assert_eq!(
            cells,
            vec![
                vec!["body", "note"],
                vec!["table", "plain"],
                vec!["head, left", "say \"hi\""],
                vec!["", "2"],
            ]
        );
        assert_eq!(
            rows.iter().map(|r| r.line).collect::<Vec<_>>(),
            [2, 3, 4, 5]
        );
    }

    #[test]
    fn comments_blank_lines_and_crlf_are_skipped_with_lines_kept() {
        let text = "# unit = g/N\r\n\r\n  # a note, \"with an odd quote\r\nbody , dof\r\n   \r\ntable, u1\r\n";
        let rows = rows(text).unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(
            (rows[0].line, rows[0].cells.clone()),
            (4, vec!["body".to_string(), "dof".into()])
        );
        assert_eq!(
            (rows[1].line, rows[1].cells.clone()),
            (6, vec!["table".to_string(), "u1".into()])
        );
    }
}
