//! The identification set-up of a workflow: the model to identify (never the truth) and its
//! decision variables, with the model file's text for writing the estimates back.

use std::path::Path;

use identify::{variables, Variables};
use rfe::Model;

use crate::error::PipelineError;
use crate::note::Note;

/// The identification set-up: the model to identify (never the truth) and its decision variables.
#[derive(Debug, Clone)]
pub struct Setup {
    /// Model file (for messages and the report).
    pub model_file: String,
    /// Its text, for writing the identified values back (TOML models only).
    pub model_text: Option<String>,
    /// The model.
    pub model: Model,
    /// Variables file.
    pub vars_file: String,
    /// The decision variables.
    pub vars: Variables,
}

impl Setup {
    /// Loads a model (TOML or resolved JSON) and a variables file; the model file's warnings
    /// go to `note`.
    pub fn load(
        model: &Path,
        vars: &Path,
        note: &mut dyn FnMut(Note),
    ) -> Result<Setup, PipelineError> {
        let loaded = rfe::modelfile::load(model)?;
        for w in &loaded.warnings {
            note(Note::Model(w.to_string()));
        }
        let m = loaded.model;
        let v = variables::load(vars, &m)?;
        let text = std::fs::read_to_string(model)
            .ok()
            .filter(|_| model.extension().is_some_and(|e| e == "toml"));
        Ok(Setup {
            model_file: model.display().to_string(),
            model_text: text,
            model: m,
            vars_file: vars.display().to_string(),
            vars: v,
        })
    }

    /// The model's name for reports: its file name without extension.
    pub fn model_name(&self) -> String {
        Path::new(&self.model_file)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| self.model_file.clone())
    }
}
