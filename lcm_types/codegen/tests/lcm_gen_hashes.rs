//! The parser and fingerprint code against lcm-gen itself: for every struct of the wire
//! contract and of the test schemas, the per-type hash must equal the constant lcm-gen writes
//! into its C binding (`__<type>_get_hash`, i.e. `lcm_struct_hash`). Uses lcm-gen from the
//! repo's venv or from PATH (Debian's liblcm-bin 1.3.1 computes the same hashes).

use std::path::{Path, PathBuf};
use std::process::Command;

use lcm_codegen::fingerprint::base_hash;

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .expect("repo root")
}

fn lcm_gen() -> PathBuf {
    let venv = repo_root().join(".venv/bin/lcm-gen");
    if venv.exists() {
        return venv;
    }
    std::env::var_os("PATH")
        .and_then(|p| {
            std::env::split_paths(&p)
                .map(|d| d.join("lcm-gen"))
                .find(|c| c.exists())
        })
        .expect("lcm-gen not found in .venv/bin or PATH: run scripts/setup.sh")
}

fn lcm_files(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("readable")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "lcm"))
        .collect();
    files.sort();
    files
}

/// The base hash lcm-gen's C output states for `<package>_<name>` (dots become underscores).
fn c_base_hash(dir: &Path, c_name: &str) -> u64 {
    let source = std::fs::read_to_string(dir.join(format!("{c_name}.c")))
        .unwrap_or_else(|e| panic!("{c_name}.c: {e}"));
    let marker = "uint64_t hash = (uint64_t)0x";
    let start = source
        .find(marker)
        .unwrap_or_else(|| panic!("no hash in {c_name}.c"))
        + marker.len();
    u64::from_str_radix(&source[start..start + 16], 16).expect("hex hash")
}

fn check(label: &str, schema_dir: &Path) -> usize {
    let files = lcm_files(schema_dir);
    let schema = lcm_codegen::schema_from_files(&files).expect("schema parses");
    let out = std::env::temp_dir().join(format!("lcm-gen-c-{}-{label}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).expect("temp dir");
    let status = Command::new(lcm_gen())
        .arg("-c")
        .arg("--c-cpath")
        .arg(&out)
        .arg("--c-hpath")
        .arg(&out)
        .args(&files)
        .status()
        .expect("lcm-gen runs");
    assert!(status.success());
    let mut checked = 0;
    for def in schema.structs() {
        let c_name = format!("{}_{}", def.name.package.replace('.', "_"), def.name.name);
        assert_eq!(
            base_hash(def),
            c_base_hash(&out, &c_name),
            "base hash of {}",
            def.name
        );
        checked += 1;
    }
    let _ = std::fs::remove_dir_all(&out);
    checked
}

#[test]
fn base_hashes_match_lcm_gen_for_the_wire_contract() {
    assert_eq!(check("pfnav", &repo_root().join("lcm_types")), 15);
}

#[test]
fn base_hashes_match_lcm_gen_for_the_test_schemas() {
    assert_eq!(
        check("data", &repo_root().join("lcm_types/codegen/tests/data")),
        6
    );
}
