//! The layout id of serialized FMU states (`saved_state::STATE_LAYOUT`): a CRC-32 of the source
//! of every type an FMU state holds, i.e. all of this crate's and the controller's source. A state
//! serialized by a build whose sources differ in any way is refused with the reason, instead of
//! being decoded into types that may have changed; nobody has to remember to bump a version.

use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) -> std::io::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        if path.is_dir() {
            rust_files(&path, out)?;
        } else if path.extension().is_some_and(|ext| ext == "rs") {
            out.push(path);
        }
    }
    Ok(())
}

fn main() -> std::io::Result<()> {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    let mut hasher = crc32fast::Hasher::new();
    for root in [manifest.join("src"), manifest.join("../controller/src")] {
        println!("cargo:rerun-if-changed={}", root.display());
        let mut files = Vec::new();
        rust_files(&root, &mut files)?;
        // read_dir order is unspecified; sorted, the id depends on the contents only.
        files.sort();
        for file in files {
            let relative = file.strip_prefix(&manifest).unwrap_or(&file);
            hasher.update(relative.to_string_lossy().as_bytes());
            hasher.update(&std::fs::read(&file)?);
        }
    }
    let out =
        PathBuf::from(std::env::var_os("OUT_DIR").unwrap_or_default()).join("state_layout.rs");
    std::fs::write(
        out,
        format!(
            "/// Layout id of serialized states: CRC-32 of the state types' source (build.rs).\npub const STATE_LAYOUT: u32 = {:#010x};\n",
            hasher.finalize()
        ),
    )
}
