//! Builds `target/fmu/QuadController.fmu` from the cdylib of the same cargo build.
//!
//! ```sh
//! cargo run --release -p quad-controller-fmu --bin bundle-fmu            # -> <repo>/target/fmu/QuadController.fmu
//! cargo run --release -p quad-controller-fmu --bin bundle-fmu -- --out /tmp/x.fmu
//! ```
//! Options: `--out PATH` (archive), `--lib PATH` (cdylib; default: next to this executable, so
//! `CARGO_TARGET_DIR` and the profile are respected), `--urdf PATH` (default `robot/quadruped.urdf`).
//! `PFNAV_FMU_OUT` overrides the default output path.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use quad_controller_fmu::bundle::{repo_root, shared_library_next_to, write_fmu, BundleInputs};
use quad_controller_fmu::MODEL_IDENTIFIER;

fn main() -> Result<()> {
    tracing_subscriber::fmt().with_target(false).init();
    let mut out = std::env::var_os("PFNAV_FMU_OUT")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            repo_root()
                .join("target")
                .join("fmu")
                .join(format!("{MODEL_IDENTIFIER}.fmu"))
        });
    let mut lib = None;
    let mut urdf = repo_root().join("robot").join("quadruped.urdf");
    let mut args = std::env::args_os().skip(1);
    while let Some(arg) = args.next() {
        let mut value = || {
            args.next()
                .map(PathBuf::from)
                .with_context(|| format!("{} needs a value", arg.to_string_lossy()))
        };
        match arg.to_str() {
            Some("--out") => out = value()?,
            Some("--lib") => lib = Some(value()?),
            Some("--urdf") => urdf = value()?,
            Some("-h" | "--help") => {
                println!("usage: bundle-fmu [--out FMU] [--lib libquad_controller_fmu.so] [--urdf quadruped.urdf]");
                return Ok(());
            }
            _ => bail!("unknown argument {:?} (see --help)", arg),
        }
    }
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
            urdf: urdf.clone(),
        },
        &out,
    )
    .with_context(|| format!("bundling {}", out.display()))?;
    tracing::info!(
        "wrote {} (binary {}, robot {})",
        out.display(),
        shared_library.display(),
        urdf.display()
    );
    println!("{}", out.display());
    Ok(())
}
