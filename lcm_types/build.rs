//! Generates the Rust codec from the wire contract `lcm_types/*.lcm` (and, for this crate's
//! own tests, from the codegen test schemas), and the channel names and default URL of
//! `lcm_types/channels.toml`, into OUT_DIR.

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
    let channels = manifest_dir.join("channels.toml");
    println!("cargo:rerun-if-changed={}", channels.display());
    if let Err(message) = generate_channels(&channels, &out_dir.join("channels.rs")) {
        panic!("lcm-types: {}: {message}", channels.display());
    }
}

/// `channels.toml` as Rust constants: `DEFAULT_URL`, `DEFAULT_PREFIX` and a module per table
/// with one `&str` constant per channel, its message type and meaning as the doc comment.
fn generate_channels(path: &Path, out: &Path) -> Result<(), String> {
    let text = std::fs::read_to_string(path).map_err(|e| e.to_string())?;
    let table: toml::Table = text.parse().map_err(|e: toml::de::Error| e.to_string())?;
    let string = |key: &str| -> Result<String, String> {
        table
            .get(key)
            .and_then(toml::Value::as_str)
            .map(str::to_owned)
            .ok_or_else(|| format!("`{key}` must be a string"))
    };
    let receive_thread_priority = table
        .get("receive_thread_priority")
        .and_then(toml::Value::as_integer)
        .filter(|priority| (1..=99).contains(priority))
        .ok_or("`receive_thread_priority` must be a SCHED_FIFO priority, 1..=99")?;
    let mut code = format!(
        "/// The bus used when neither a flag nor `$LCM_DEFAULT_URL` names one.\n\
         pub const DEFAULT_URL: &str = {:?};\n\
         /// Prefix of every planner channel (`pf-planner-service --channel-prefix` changes it).\n\
         pub const DEFAULT_PREFIX: &str = {:?};\n\
         /// SCHED_FIFO priority of liblcm's receive thread in the real-time processes.\n\
         pub const RECEIVE_THREAD_PRIORITY: i32 = {receive_thread_priority};\n",
        string("default_url")?,
        string("default_prefix")?
    );
    for (group, entries) in &table {
        let Some(entries) = entries.as_table() else {
            continue;
        };
        code.push_str(&format!(
            "/// `[{group}]` of channels.toml.\npub mod {group} {{\n"
        ));
        for (name, entry) in entries {
            let fields: Option<Vec<&str>> = entry
                .as_array()
                .map(|items| items.iter().filter_map(toml::Value::as_str).collect());
            let [channel, message, meaning] = fields.as_deref().unwrap_or_default() else {
                return Err(format!(
                    "[{group}] {name} must be [channel, message type, meaning]"
                ));
            };
            code.push_str(&format!(
                "    /// `{message}`, {meaning}.\n    pub const {}: &str = {channel:?};\n",
                name.to_uppercase()
            ));
        }
        code.push_str("}\n");
    }
    std::fs::write(out, code).map_err(|e| format!("cannot write {}: {e}", out.display()))
}
