//! Generates the Rust codec from the wire contract `lcm_types/*.lcm` (and, for this crate's
//! own tests, from the codegen test schemas) into OUT_DIR.

use std::path::{Path, PathBuf};

use lcm_codegen::RustOptions;

fn lcm_files(dir: &Path) -> Result<Vec<PathBuf>, String> {
    let entries =
        std::fs::read_dir(dir).map_err(|e| format!("cannot list {}: {e}", dir.display()))?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry
            .map_err(|e| format!("cannot list {}: {e}", dir.display()))?
            .path();
        if path.extension().is_some_and(|ext| ext == "lcm") {
            files.push(path);
        }
    }
    // read_dir order is unspecified; sorting keeps the output deterministic.
    files.sort();
    if files.is_empty() {
        return Err(format!("no .lcm files in {}", dir.display()));
    }
    Ok(files)
}

fn generate(dir: &Path, options: &RustOptions, out: &Path) -> Result<(), String> {
    let files = lcm_files(dir)?;
    println!("cargo:rerun-if-changed={}", dir.display());
    for f in &files {
        println!("cargo:rerun-if-changed={}", f.display());
    }
    let code = lcm_codegen::generate_from_files(&files, options).map_err(|e| e.to_string())?;
    std::fs::write(out, code).map_err(|e| format!("cannot write {}: {e}", out.display()))
}

fn main() {
    let manifest_dir = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    let out_dir = PathBuf::from(std::env::var_os("OUT_DIR").unwrap_or_default());
    let jobs = [
        (
            manifest_dir.clone(),
            RustOptions {
                runtime_path: "crate::codec".to_string(),
                serde: true,
            },
            out_dir.join("pfnav_types.rs"),
        ),
        (
            manifest_dir.join("codegen/tests/data"),
            RustOptions {
                runtime_path: "::lcm_types::codec".to_string(),
                serde: true,
            },
            out_dir.join("codegen_test_types.rs"),
        ),
    ];
    for (dir, options, out) in jobs {
        if let Err(message) = generate(&dir, &options, &out) {
            // A build script reports failure by panicking; the message names the .lcm problem.
            panic!("lcm-types code generation failed: {message}");
        }
    }
}
