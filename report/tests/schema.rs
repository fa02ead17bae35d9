//! docs/report.schema.json is generated from the report type, docs/stability.schema.json from
//! the stability section's type (`ident stability --json`, the report's `stability`): these
//! tests fail when a file differs from its generated schema. Rewrite them with
//! `IDENT_BLESS=1 cargo test --workspace --test schema`.

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

#[test]
fn the_stability_schema_file_is_the_generated_schema() {
    let file = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../docs/stability.schema.json");
    let generated =
        serde_json::to_string_pretty(&stability::section::json_schema()).unwrap() + "\n";
    if std::env::var_os("IDENT_BLESS").is_some() {
        std::fs::write(&file, &generated).unwrap();
    }
    let on_disk = std::fs::read_to_string(&file).unwrap_or_default();
    assert!(
        on_disk == generated,
        "docs/stability.schema.json differs from the schema generated from stability::section::Stability: run `IDENT_BLESS=1 cargo test --workspace --test schema` and commit the file"
    );
    // The report's section is the same type: its schema is the one the report's schema holds.
    let report = report::document::json_schema();
    let defs = report["$defs"].as_object().unwrap();
    assert!(
        defs.contains_key("Stability") && defs.contains_key("LimitingMode"),
        "the report schema holds the stability section's definitions"
    );
}
