//! Golden tests: the Rust codec against lcm-gen's own Python bindings, generated live.
//!
//! For every type of the wire contract (lcm_types/*.lcm) and of the codegen test schemas
//! (lcm_types/codegen/tests/data/*.lcm), the test runs `lcm-gen --python` into a temporary
//! directory, lets `golden_messages.py` build a default and random messages with the generated
//! classes and encode them, then checks that
//! - lcm-gen's fingerprint equals the generated `FINGERPRINT`,
//! - the Rust encoding of the same values is byte-identical to lcm-gen's,
//! - the Rust decoder reads lcm-gen's bytes back to the same values.
//!
//! lcm-gen and Python come from the repo's venv (`.venv`, set up by scripts/setup.sh: lcm-gen
//! 1.5.3 extracted from the PyPI `lcm` wheel) or else from PATH; the script needs the class metadata
//! that lcm-gen >= 1.4 writes (Debian's 1.3.1 does not).

use std::collections::BTreeMap;
use std::fmt::Debug;
use std::path::{Path, PathBuf};
use std::process::Command;

use serde::de::DeserializeOwned;
use serde_json::Value;

use crate::test_types;

const RANDOM_MESSAGES_PER_TYPE: usize = 25;

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("lcm_types lives inside the repo")
        .to_path_buf()
}

fn tool(name: &str) -> PathBuf {
    let venv = repo_root().join(".venv/bin").join(name);
    if venv.exists() {
        return venv;
    }
    let on_path = std::env::var_os("PATH")
        .map(|p| {
            std::env::split_paths(&p)
                .map(|d| d.join(name))
                .find(|c| c.exists())
        })
        .unwrap_or_default();
    on_path.unwrap_or_else(|| panic!("{name} not found in .venv/bin or PATH: run scripts/setup.sh"))
}

fn lcm_files(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("schema directory is readable")
        .map(|e| e.expect("directory entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "lcm"))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no .lcm files in {}", dir.display());
    files
}

/// Runs lcm-gen --python and golden_messages.py; returns the JSON lines.
fn lcm_gen_golden(label: &str, schema_dir: &Path, type_names: &[&str], seed: u64) -> Vec<Value> {
    let ppath = std::env::temp_dir().join(format!("lcm-golden-{}-{label}", std::process::id()));
    let _ = std::fs::remove_dir_all(&ppath);
    std::fs::create_dir_all(&ppath).expect("temp dir");
    let status = Command::new(tool("lcm-gen"))
        .arg("--python")
        .arg("--ppath")
        .arg(&ppath)
        .args(lcm_files(schema_dir))
        .status()
        .expect("lcm-gen runs");
    assert!(status.success(), "lcm-gen failed: {status}");
    let output = Command::new(tool("python3"))
        .arg(repo_root().join("lcm_types/tests/golden_messages.py"))
        .arg(&ppath)
        .arg(seed.to_string())
        .arg(RANDOM_MESSAGES_PER_TYPE.to_string())
        .args(type_names)
        .output()
        .expect("python runs");
    let _ = std::fs::remove_dir_all(&ppath);
    assert!(
        output.status.success(),
        "golden_messages.py failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let text = String::from_utf8(output.stdout).expect("utf-8 output");
    let lines: Vec<Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).expect("valid JSON line"))
        .collect();
    assert_eq!(
        lines.len(),
        type_names.len() * (RANDOM_MESSAGES_PER_TYPE + 1)
    );
    lines
}

fn hex_decode(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).expect("hex"))
        .collect()
}

/// Checks every golden line against the Rust codec of one schema.
fn check_schema<M, D, E>(lines: &[Value], fingerprints: &[(&str, u64)], decode: D, encode: E)
where
    M: DeserializeOwned + PartialEq + Debug,
    D: Fn(&[u8]) -> Result<M, String>,
    E: Fn(&M) -> Result<Vec<u8>, String>,
{
    let rust: BTreeMap<&str, u64> = fingerprints.iter().copied().collect();
    let mut python: BTreeMap<String, u64> = BTreeMap::new();
    for line in lines {
        let type_name = line["type"].as_str().expect("type").to_string();
        let fingerprint =
            u64::from_str_radix(line["fingerprint"].as_str().expect("fp"), 16).expect("hex fp");
        python.insert(type_name.clone(), fingerprint);
        assert_eq!(
            rust.get(type_name.as_str()),
            Some(&fingerprint),
            "fingerprint of {type_name}"
        );

        let golden = hex_decode(line["hex"].as_str().expect("hex"));
        let tagged = serde_json::json!({ "type": type_name, "value": line["value"] });
        let message: M = serde_json::from_value(tagged)
            .unwrap_or_else(|e| panic!("{type_name}: JSON does not fit the Rust type: {e}"));
        let encoded = encode(&message).unwrap_or_else(|e| panic!("{type_name}: encode: {e}"));
        assert_eq!(
            encoded, golden,
            "{type_name}: Rust and lcm-gen encodings differ for {}",
            line["value"]
        );
        let decoded = decode(&golden).unwrap_or_else(|e| panic!("{type_name}: decode: {e}"));
        assert_eq!(decoded, message, "{type_name}: decoding lcm-gen's bytes");
    }
    let rust_names: Vec<&str> = rust.keys().copied().collect();
    let python_names: Vec<&str> = python.keys().map(String::as_str).collect();
    assert_eq!(rust_names, python_names, "both sides cover the same types");
}

#[test]
fn wire_contract_matches_lcm_gen_for_every_type() {
    let lines = lcm_gen_golden(
        "pfnav",
        &repo_root().join("lcm_types"),
        lcm_types::TYPE_NAMES,
        11,
    );
    check_schema(
        &lines,
        lcm_types::FINGERPRINTS,
        |b| lcm_types::AnyMessage::decode(b).map_err(|e| e.to_string()),
        |m| m.encode().map_err(|e| e.to_string()),
    );
}

#[test]
fn codegen_test_schemas_match_lcm_gen_for_every_type() {
    let lines = lcm_gen_golden(
        "codegen",
        &repo_root().join("lcm_types/codegen/tests/data"),
        test_types::TYPE_NAMES,
        12,
    );
    check_schema(
        &lines,
        test_types::FINGERPRINTS,
        |b| test_types::AnyMessage::decode(b).map_err(|e| e.to_string()),
        |m| m.encode().map_err(|e| e.to_string()),
    );
}
