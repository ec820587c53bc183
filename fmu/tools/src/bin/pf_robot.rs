//! Checks a robot config before anything runs on it, and describes it to the simulation harness.
//!
//! ```sh
//! pf-robot check robot/third_party/hyq.toml
//! pf-robot check myrobot.toml --srdf myrobot_description/srdf/myrobot.srdf
//! pf-robot describe robot/third_party/go1.toml
//! ```
//! `check` prints every problem found (each with the config line that fixes it), the values proposed
//! from the SRDF `standing` pose next to the URDF (stand height, knee branches, crouch) and how
//! the default tuning carries over to the robot. `package://` resolves through
//! `PFNAV_PACKAGE_PATH`. Exit status: 0 no problem, 1 problems found. `describe` prints the config
//! as the controller's loader resolves it, as JSON (the simulation harness builds its robot from
//! it); exit status 2 with the loader's error on stderr when the config cannot be loaded.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use quad_controller::robot_config::check::{check_robot_config, RobotCheck};
use quad_controller::robot_config::describe::describe_robot_config;
use quad_controller::PackagePath;

/// Tools for robot configs.
#[derive(Parser)]
#[command(name = "pf-robot")]
struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Every problem of a robot config at once, with fixes and proposals from the SRDF.
    Check {
        /// The robot config (TOML).
        config: PathBuf,
        /// The SRDF whose `standing` pose the proposals come from [default: the first SRDF with
        /// one in the `srdf/` folder beside the URDF's].
        #[arg(long)]
        srdf: Option<PathBuf>,
    },
    /// The config as the controller's loader resolves it (URDF and mesh paths, foot radius,
    /// massless links, legs), as JSON on stdout.
    Describe {
        /// The robot config (TOML).
        config: PathBuf,
    },
}

/// Exit status of `describe` for a config the loader refuses.
const CONFIG_REFUSED: u8 = 2;

/// The check's report as printed (written in one go by `main`, so that a reader that went away
/// is an error message, not a panic).
fn report(config: &std::path::Path, check: &RobotCheck) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    // Writing into a String cannot fail.
    macro_rules! say {
        ($($arg:tt)*) => {
            let _ = writeln!(out, $($arg)*);
        };
    }
    say!("pf-robot check {}", config.display());
    if let Some(model) = &check.model {
        say!(
            "  robot `{}`: {:.3} kg, stand height {:.3} m, foot radius {:.4} m",
            model.name(),
            model.total_mass(),
            model.stand_height(),
            model.foot_radius()
        );
    }
    if check.findings.is_empty() {
        say!("  no problems");
    } else {
        say!("  {} problem(s):", check.findings.len());
        for (i, finding) in check.findings.iter().enumerate() {
            say!("  {}. `{}`: {}", i + 1, finding.key, finding.problem);
            if let Some(fix) = &finding.fix {
                say!("     fix: {fix}");
            }
        }
    }
    if let Some(srdf) = &check.srdf {
        say!("  proposed from the `standing` pose of {}:", srdf.display());
        if let Some(height) = check.stand_height {
            say!("    stand_height = {height:.3}");
        }
        for leg in &check.legs {
            say!(
                "    [legs.{}] knee_points = \"{}\", crouch = [{:.3}, {:.3}, {:.3}]",
                leg.leg.name(),
                match leg.knee_points {
                    quad_controller::robot_config::KneeDirection::Backward => "backward",
                    quad_controller::robot_config::KneeDirection::Forward => "forward",
                },
                leg.crouch[0],
                leg.crouch[1],
                leg.crouch[2]
            );
        }
    }
    for note in &check.notes {
        say!("  note: {note}");
    }
    out
}

fn main() -> ExitCode {
    let Args { command } = Args::parse();
    match command {
        Command::Check { config, srdf } => {
            let check = check_robot_config(&config, &PackagePath::from_env(), srdf.as_deref());
            if let Err(e) = std::io::stdout()
                .lock()
                .write_all(report(&config, &check).as_bytes())
            {
                eprintln!("cannot write the report: {e}");
                return ExitCode::FAILURE;
            }
            if check.findings.is_empty() {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            }
        }
        Command::Describe { config } => {
            match describe_robot_config(&config, &PackagePath::from_env()) {
                Ok(description) => {
                    let written =
                        serde_json::to_writer_pretty(std::io::stdout().lock(), &description);
                    match written {
                        Ok(()) => ExitCode::SUCCESS,
                        // A reader that went away (a closed pipe) is not worth a panic.
                        Err(e) => {
                            eprintln!("cannot write the description: {e}");
                            ExitCode::FAILURE
                        }
                    }
                }
                Err(e) => {
                    eprintln!("{e}");
                    ExitCode::from(CONFIG_REFUSED)
                }
            }
        }
    }
}
