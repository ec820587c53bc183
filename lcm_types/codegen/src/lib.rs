//! Parser of `.lcm` schema files and generator of Rust codec source (used by lcm-types' build script).
//!
//! The pipeline is [`parse::parse_str`] (syntax, one file) → [`schema::Schema::new`] (semantic
//! checks across files, type resolution) → [`rust::generate`] (Rust source). Fingerprints are
//! computed exactly as `lcm-gen` computes them ([`fingerprint`]), so the generated encoders are
//! byte-compatible with every other LCM language binding.

pub mod fingerprint;
pub mod parse;
pub mod rust;
pub mod schema;

use std::path::{Path, PathBuf};

pub use parse::{ParseError, ParsedFile};
pub use rust::{GenerateError, RustOptions};
pub use schema::{Schema, SchemaError};

/// Any failure of [`generate_from_files`].
#[derive(Debug, thiserror::Error)]
pub enum CodegenError {
    #[error("cannot read {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Parse(#[from] ParseError),
    #[error(transparent)]
    Schema(#[from] SchemaError),
    #[error(transparent)]
    Generate(#[from] GenerateError),
}

/// Parses every file, checks them together and returns the generated Rust source.
pub fn generate_from_files<P: AsRef<Path>>(
    paths: &[P],
    options: &RustOptions,
) -> Result<String, CodegenError> {
    let schema = schema_from_files(paths)?;
    Ok(rust::generate(&schema, options)?)
}

/// Parses every file and checks them together.
pub fn schema_from_files<P: AsRef<Path>>(paths: &[P]) -> Result<Schema, CodegenError> {
    let mut files = Vec::with_capacity(paths.len());
    for path in paths {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| CodegenError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        files.push(parse::parse_str(&text, &path.display().to_string())?);
    }
    Ok(Schema::new(files)?)
}
