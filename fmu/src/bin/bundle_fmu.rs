//! Builds `target/fmu/QuadController.fmu` from the cdylib of the same cargo build.
//!
//! ```sh
//! cargo run --release -p quad-controller-fmu --bin bundle-fmu            # -> <repo>/target/fmu/QuadController.fmu
//! cargo run --release -p quad-controller-fmu --bin bundle-fmu -- --out /tmp/x.fmu
//! ```
//! Options: `--out PATH` (archive), `--lib PATH` (cdylib; default: next to this executable, so
//! `CARGO_TARGET_DIR` and the profile are respected). The robot is the compiled-in
//! `robot/quadruped.urdf` (the variable table's ranges and start values come from it).
//! `PFNAV_FMU_OUT` overrides the default output path.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Parser;
use quad_controller_fmu::bundle::{repo_root, shared_library_next_to, write_fmu, BundleInputs};
use quad_controller_fmu::MODEL_IDENTIFIER;

/// Bundle the controller FMU (modelDescription.xml, the cdylib, the URDF and the default
/// configuration) into one .fmu archive.
#[derive(Parser)]
#[command(name = "bundle-fmu")]
struct Args {
    /// The archive to write [default: $PFNAV_FMU_OUT, else <repo>/target/fmu/QuadController.fmu].
    #[arg(long)]
    out: Option<PathBuf>,
    /// The cdylib to bundle [default: the libquad_controller_fmu.so next to this executable, so
    /// CARGO_TARGET_DIR and the profile are respected].
    #[arg(long)]
    lib: Option<PathBuf>,
}

fn main() -> Result<()> {
    tracing_subscriber::fmt().with_target(false).init();
    let Args { out, lib } = Args::parse();
    let out = out
        .or_else(|| std::env::var_os("PFNAV_FMU_OUT").map(PathBuf::from))
        .unwrap_or_else(|| {
            repo_root()
                .join("target")
                .join("fmu")
                .join(format!("{MODEL_IDENTIFIER}.fmu"))
        });
    let shared_library = match lib {
        Some(lib) => lib,
        None => {
            let exe = std::env::current_exe().context("locating this executable")?;
            shared_library_next_to(&exe).with_context(|| {
                format!(
                    "no libquad_controller_fmu.so next to {}; build it with `cargo build -p quad-controller-fmu` or pass --lib",
                    exe.display()
                )
            })?
        }
    };
    write_fmu(
        &BundleInputs {
            shared_library: shared_library.clone(),
        },
        &out,
    )
    .with_context(|| format!("bundling {}", out.display()))?;
    tracing::info!(
        "wrote {} (binary {})",
        out.display(),
        shared_library.display()
    );
    println!("{}", out.display());
    Ok(())
}
