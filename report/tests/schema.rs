//! docs/report.schema.json is generated from the report type: this test fails when the file
//! differs from `report::document::json_schema()`. Rewrite it with
//! `IDENT_BLESS=1 cargo test -p report --test schema`.

#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

fn schema_file() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../docs/report.schema.json")
}

#[test]
fn the_schema_file_is_the_generated_schema() {
    let generated = serde_json::to_string_pretty(&report::document::json_schema()).unwrap() + "\n";
    if std::env::var_os("IDENT_BLESS").is_some() {
        std::fs::write(schema_file(), &generated).unwrap();
    }
    let on_disk = std::fs::read_to_string(schema_file()).unwrap();
    assert!(
        on_disk == generated,
        "docs/report.schema.json differs from the schema generated from report::document::Report: run `IDENT_BLESS=1 cargo test -p report --test schema` and commit the file"
    );
}
