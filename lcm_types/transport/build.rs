//! Links, statically, the patched liblcm that `scripts/build_liblcm.sh` builds into
//! `build/lcm/lib` (Debian's liblcm 1.3.1 lets one UDP packet write out of bounds:
//! docs/liblcm-fix.md). Static linking puts the patched code into every binary of the workspace,
//! so no loader path can substitute the system's library. A missing build is an error, never a
//! silent fallback to the system library.
use std::path::PathBuf;

fn main() {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    let lib_dir = std::env::var_os("PFNAV_LCM_LIB_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest.join("../../build/lcm/lib"));
    let archive = lib_dir.join("liblcm.a");
    if !archive.is_file() {
        panic!(
            "{} not found: run `bash scripts/setup.sh` (or `bash scripts/build_liblcm.sh .venv/bin/python`) \
             to build the patched liblcm, or set PFNAV_LCM_LIB_DIR",
            archive.display()
        );
    }
    let lib_dir = lib_dir.canonicalize().unwrap_or(lib_dir);
    println!("cargo:rustc-link-search=native={}", lib_dir.display());
    println!("cargo:rustc-link-lib=static=lcm");
    // liblcm's own dependencies (Debian's libglib2.0).
    println!("cargo:rustc-link-lib=dylib=gthread-2.0");
    println!("cargo:rustc-link-lib=dylib=glib-2.0");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed={}", archive.display());
    println!("cargo:rerun-if-env-changed=PFNAV_LCM_LIB_DIR");
}
