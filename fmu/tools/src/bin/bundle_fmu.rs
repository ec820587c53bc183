//! Builds `target/fmu/QuadController.fmu` from the FMU's shared library of the same cargo build
//! (crate `quad-controller-fmu-binary`; `scripts/build_fmu_portable.sh` links the shipped one).
//!
//! ```sh
//! cargo run --release -p fmu-tools --bin bundle-fmu            # -> <repo>/target/fmu/QuadController.fmu
//! cargo run --release -p fmu-tools --bin bundle-fmu -- --out /tmp/x.fmu
//! ```
//! Options: `--out PATH` (archive), `--lib PATH` (the linux64 cdylib; default: next to this
//! executable, so `CARGO_TARGET_DIR` and the profile are respected), `--binary PLATFORM=PATH`
//! (repeatable: `linux64`, `win64`, `darwin64`; e.g. `--binary win64=…/quad_controller_fmu_binary.dll`,
//! stored as `binaries/win64/QuadController.dll`), `--binaries-from FMU` (take the binaries of an
//! existing QuadController FMU instead: another robot needs no build), `--robot CONFIG` (the robot
//! config, default `robot/quadruped.toml`; `package://` resolves through `PFNAV_PACKAGE_PATH`).
//! The variable table's ranges and start values and the shipped tuning come from the robot.
//! `PFNAV_FMU_OUT` overrides the default output path.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Parser;
use quad_controller::PackagePath;
use quad_controller_fmu::bundle::{
    default_robot_config, repo_root, shared_library_next_to, write_fmu, BinarySource, BundleInputs,
    Platform, SHARED_LIBRARY_FILE,
};
use quad_controller_fmu::MODEL_IDENTIFIER;

/// Bundle the controller FMU (modelDescription.xml, the cdylib, the URDF and the default
/// configuration) into one .fmu archive.
#[derive(Parser)]
#[command(name = "bundle-fmu")]
struct Args {
    /// The archive to write [default: $PFNAV_FMU_OUT, else <repo>/target/fmu/QuadController.fmu].
    #[arg(long)]
    out: Option<PathBuf>,
    /// The cdylib to bundle [default: the libquad_controller_fmu_binary.so next to this executable, so
    /// CARGO_TARGET_DIR and the profile are respected].
    #[arg(long)]
    lib: Option<PathBuf>,
    /// A binary for one FMI platform, PLATFORM=PATH with PLATFORM linux64, win64 or darwin64
    /// (repeatable; linux64 here replaces --lib).
    #[arg(long, value_name = "PLATFORM=PATH", value_parser = parse_binary)]
    binary: Vec<(Platform, PathBuf)>,
    /// Take the binaries of this existing QuadController FMU (instead of --lib/--binary).
    #[arg(long, value_name = "FMU", conflicts_with_all = ["lib", "binary"])]
    binaries_from: Option<PathBuf>,
    /// The robot config (TOML) of the robot the FMU controls [default: <repo>/robot/quadruped.toml].
    #[arg(long, value_name = "CONFIG")]
    robot: Option<PathBuf>,
}

fn parse_binary(text: &str) -> Result<(Platform, PathBuf), String> {
    let (platform, path) = text
        .split_once('=')
        .ok_or_else(|| format!("expected PLATFORM=PATH, got {text:?}"))?;
    if path.is_empty() {
        return Err(format!("no path after {platform}="));
    }
    Ok((platform.parse()?, PathBuf::from(path)))
}

fn main() -> Result<()> {
    tracing_subscriber::fmt().with_target(false).init();
    let Args {
        out,
        lib,
        mut binary,
        binaries_from,
        robot,
    } = Args::parse();
    let out = out
        .or_else(|| std::env::var_os("PFNAV_FMU_OUT").map(PathBuf::from))
        .unwrap_or_else(|| {
            repo_root()
                .join("target")
                .join("fmu")
                .join(format!("{MODEL_IDENTIFIER}.fmu"))
        });
    let binaries = match binaries_from {
        Some(fmu) => BinarySource::Archive(fmu),
        None => {
            let linux64_given = binary.iter().any(|(p, _)| *p == Platform::Linux64);
            if linux64_given && lib.is_some() {
                bail!("--lib and --binary linux64=… both name the linux64 binary: give one");
            }
            if !linux64_given {
                let shared_library = match lib {
                    Some(lib) => lib,
                    None => {
                        let exe = std::env::current_exe().context("locating this executable")?;
                        shared_library_next_to(&exe).with_context(|| {
                            format!(
                                "no {SHARED_LIBRARY_FILE} next to {}; build it with `cargo build --release -p quad-controller-fmu-binary` or pass --lib",
                                exe.display()
                            )
                        })?
                    }
                };
                binary.insert(0, (Platform::Linux64, shared_library));
            }
            BinarySource::Files(binary)
        }
    };
    let inputs = BundleInputs {
        binaries,
        robot_config: robot.unwrap_or_else(default_robot_config),
        packages: PackagePath::from_env(),
    };
    write_fmu(&inputs, &out).with_context(|| format!("bundling {}", out.display()))?;
    tracing::info!(
        "{}: robot {}, binaries {:?}",
        out.display(),
        inputs.robot_config.display(),
        inputs.binaries
    );
    println!("{}", out.display());
    Ok(())
}
