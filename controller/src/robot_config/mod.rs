//! Robot description as data: which URDF joints and links make each leg, how the knees bend, the
//! nominal stand height and optional limit overrides. One TOML file next to any 12-DOF quadruped
//! URDF; the key table is in `robot/README.md`. Deserialisation refuses unknown keys, so a typo
//! is an error rather than a silently ignored setting.

pub mod check;
pub mod describe;
pub mod foot_mesh;
mod package_path;
pub mod srdf;

pub use package_path::{PackagePath, PACKAGE_PATH_ENV};

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::api::{Leg, ModelError};

/// A config value the model cannot be built with: the key it sits under, when there is one, and
/// a message that names it. Tools such as `pf-robot check` act on the key, never on the text.
#[derive(Clone, Debug, PartialEq)]
pub struct KeyProblem {
    /// The key (`stand_height`, `legs.FR.crouch`, `tuning`, …), `None` for a problem of the whole
    /// config (two legs naming one joint).
    pub key: Option<String>,
    /// What is wrong, in words that name the key.
    pub reason: String,
}

impl KeyProblem {
    /// A problem of the value under `key`.
    pub(crate) fn of(key: impl Into<String>, reason: String) -> Self {
        Self {
            key: Some(key.into()),
            reason,
        }
    }

    /// The error of the config read from `file`.
    pub(crate) fn in_file(self, file: &str) -> ModelError {
        ModelError::Config {
            file: file.to_string(),
            key: self.key,
            reason: self.reason,
        }
    }
}

/// Where the knee joint sits relative to the hip–foot line when the leg is bent. The inverse
/// kinematics picks the matching branch, so the stand pose of a robot whose front and rear knees
/// bend differently comes out right.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KneeDirection {
    /// Knee behind the hip–foot line (the usual bend of front legs).
    Backward,
    /// Knee in front of the hip–foot line (e.g. the rear legs of an X-shaped leg layout).
    Forward,
}

/// A fixed-size array that refuses extra elements (serde's array impl stops reading after `N`, so a
/// leg listing four joints would otherwise lose one silently).
fn exactly<'de, D, T, const N: usize>(deserializer: D) -> Result<[T; N], D::Error>
where
    D: serde::Deserializer<'de>,
    T: Deserialize<'de>,
{
    let values = Vec::<T>::deserialize(deserializer)?;
    let found = values.len();
    values.try_into().map_err(|_| {
        serde::de::Error::custom(format!("expected exactly {N} values, found {found}"))
    })
}

fn optional_exactly<'de, D, T, const N: usize>(deserializer: D) -> Result<Option<[T; N]>, D::Error>
where
    D: serde::Deserializer<'de>,
    T: Deserialize<'de>,
{
    exactly(deserializer).map(Some)
}

/// One leg: the URDF's own names.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LegConfig {
    /// Actuated revolute joints from the base outwards: abduction, hip flexion, knee.
    #[serde(deserialize_with = "exactly")]
    pub joints: [String; 3],
    /// Link that carries the foot point.
    pub foot_link: String,
    /// Foot point (sphere centre) in `foot_link`'s frame, m; the link origin when absent.
    #[serde(default, deserialize_with = "optional_exactly")]
    pub foot_offset: Option<[f64; 3]>,
    /// Knee bending direction.
    pub knee_points: KneeDirection,
    /// Joint angles (abduction, hip, knee), rad, of the crouch a simulation places the robot in
    /// before its stand-up; inside the joint limits. The controller itself does not read it.
    #[serde(default, deserialize_with = "optional_exactly")]
    pub crouch: Option<[f64; 3]>,
}

/// The four legs under the controller's leg names.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(non_snake_case)] // the TOML table names are the controller's leg names
pub struct LegsConfig {
    /// Front right.
    pub FR: LegConfig,
    /// Front left.
    pub FL: LegConfig,
    /// Rear right.
    pub RR: LegConfig,
    /// Rear left.
    pub RL: LegConfig,
}

impl LegsConfig {
    /// The configuration of `leg`.
    pub fn get(&self, leg: Leg) -> &LegConfig {
        match leg {
            Leg::FR => &self.FR,
            Leg::FL => &self.FL,
            Leg::RR => &self.RR,
            Leg::RL => &self.RL,
        }
    }
}

/// Per-joint-role overrides of the URDF `<limit>` values, applied to all four legs, in the order
/// abduction, hip flexion, knee.
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LimitOverrides {
    /// Effort (torque) limits, N·m.
    #[serde(default, deserialize_with = "optional_exactly")]
    pub effort: Option<[f64; 3]>,
    /// Velocity limits, rad/s.
    #[serde(default, deserialize_with = "optional_exactly")]
    pub velocity: Option<[f64; 3]>,
}

/// A robot config (TOML), see `robot/README.md`.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotConfig {
    /// URDF location: relative to the config file, absolute, or `package://NAME/PATH` resolved
    /// through a [`PackagePath`].
    pub urdf: String,
    /// Root link of the URDF tree, the controller's base frame.
    pub base_link: String,
    /// Nominal height of the base origin above flat ground when standing, m.
    pub stand_height: f64,
    /// Foot sphere radius, m, for URDFs without a sphere collision at the foot point.
    #[serde(default)]
    pub foot_radius: Option<f64>,
    /// Links whose `<inertial>` is a placeholder (e.g. a near-zero, singular inertia on a frame
    /// link): treated as massless frames instead of being refused.
    #[serde(default)]
    pub massless_links: Vec<String>,
    /// Limit overrides.
    #[serde(default)]
    pub limits: LimitOverrides,
    /// Controller tuning overrides, by the controller config's field names (`kp_stand = [...]`,
    /// `gait_period = 0.4`): applied over the default tuning scaled to the robot
    /// ([`crate::ControllerConfig::for_robot`]) and checked against the robot's ranges when the
    /// model is built.
    #[serde(default)]
    pub tuning: toml::Table,
    /// The legs.
    pub legs: LegsConfig,
}

impl RobotConfig {
    /// Parse a config; `origin` names the text in error messages (a file path or a label).
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ModelError> {
        let config: RobotConfig = toml::from_str(text).map_err(|e| ModelError::Config {
            file: origin.to_string(),
            key: None,
            reason: e.to_string().trim_end().to_string(),
        })?;
        config.check().map_err(|problem| problem.in_file(origin))?;
        Ok(config)
    }

    /// Read and parse a config file.
    pub fn from_file(path: &Path) -> Result<Self, ModelError> {
        let text = std::fs::read_to_string(path).map_err(|e| ModelError::Io {
            path: path.display().to_string(),
            reason: e.to_string(),
        })?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// The URDF file this config names, for a config read from `config_path`.
    pub fn urdf_path(
        &self,
        config_path: &Path,
        packages: &PackagePath,
    ) -> Result<PathBuf, ModelError> {
        let config_dir = config_path.parent().unwrap_or_else(|| Path::new("."));
        packages.resolve(&self.urdf, config_dir).map_err(|reason| {
            KeyProblem::of("urdf", format!("key `urdf`: {reason}"))
                .in_file(&config_path.display().to_string())
        })
    }

    /// Value checks serde cannot express; the message names the key.
    fn check(&self) -> Result<(), KeyProblem> {
        if !(self.stand_height.is_finite() && self.stand_height > 0.0) {
            return Err(KeyProblem::of(
                "stand_height",
                format!(
                    "key `stand_height` must be a positive length in m, is {}",
                    self.stand_height
                ),
            ));
        }
        if let Some(radius) = self.foot_radius {
            if !(radius.is_finite() && radius > 0.0) {
                return Err(KeyProblem::of(
                    "foot_radius",
                    format!("key `foot_radius` must be a positive length in m, is {radius}"),
                ));
            }
        }
        for (key, values) in [
            ("limits.effort", self.limits.effort),
            ("limits.velocity", self.limits.velocity),
        ] {
            if let Some(values) = values {
                if values.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
                    return Err(KeyProblem::of(
                        key,
                        format!("key `{key}` must hold three positive values, is {values:?}"),
                    ));
                }
            }
        }
        for leg in Leg::ALL {
            let config = self.legs.get(leg);
            for (key, values) in [
                ("foot_offset", config.foot_offset),
                ("crouch", config.crouch),
            ] {
                if let Some(values) = values {
                    if values.iter().any(|v| !v.is_finite()) {
                        let key = format!("legs.{}.{key}", leg.name());
                        return Err(KeyProblem {
                            reason: format!("key `{key}` is not finite: {values:?}"),
                            key: Some(key),
                        });
                    }
                }
            }
        }
        let mut joints: Vec<&str> = Leg::ALL
            .iter()
            .flat_map(|leg| self.legs.get(*leg).joints.iter().map(String::as_str))
            .collect();
        joints.sort_unstable();
        if let Some(pair) = joints.windows(2).find(|pair| pair[0] == pair[1]) {
            return Err(KeyProblem {
                key: None,
                reason: format!("joint `{}` is named by two legs", pair[0]),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
