//! The FMU's `resources/` folder: locating it from `fmuResourceLocation` and loading the robot
//! model and the controller configuration it carries.

use std::ffi::OsString;
use std::os::unix::ffi::OsStringExt;
use std::path::{Path, PathBuf};

use quad_controller::{ControllerConfig, RobotModel};

use crate::FmuError;

/// File name of the robot model inside `resources/` (a copy of `robot/quadruped.urdf`).
pub const URDF_FILE: &str = "quadruped.urdf";
/// File name of the default controller configuration inside `resources/` (JSON of
/// `ControllerConfig`); parameters set by the importer override it.
pub const CONFIG_FILE: &str = "controller.json";

/// Converts `fmuResourceLocation` to a local directory path.
///
/// Accepts `file:///abs/path`, `file://localhost/abs/path` and `file:/abs/path` (RFC 8089, with
/// percent-decoding) and, leniently, a plain absolute path. A trailing slash is allowed.
pub fn resource_dir_from_uri(location: &str) -> Result<PathBuf, FmuError> {
    let bad = |reason: &str| FmuError::ResourceLocation {
        location: location.to_owned(),
        reason: reason.to_owned(),
    };
    let encoded_path = if let Some(rest) = strip_prefix_ignore_case(location, "file:") {
        if let Some(after_authority) = rest.strip_prefix("//") {
            let slash = after_authority
                .find('/')
                .ok_or_else(|| bad("the URI has no path after the authority"))?;
            let host = &after_authority[..slash];
            if !(host.is_empty() || host.eq_ignore_ascii_case("localhost")) {
                return Err(bad(
                    "only local files are supported (host must be empty or localhost)",
                ));
            }
            &after_authority[slash..]
        } else if rest.starts_with('/') {
            rest
        } else {
            return Err(bad("a file URI needs an absolute path"));
        }
    } else if location.starts_with('/') {
        return Ok(PathBuf::from(location));
    } else {
        return Err(bad("expected a file:// URI"));
    };
    let encoded_path = encoded_path
        .split(['?', '#'])
        .next()
        .unwrap_or(encoded_path);
    let bytes = percent_decode(encoded_path).map_err(|reason| bad(&reason))?;
    Ok(PathBuf::from(OsString::from_vec(bytes)))
}

fn strip_prefix_ignore_case<'a>(text: &'a str, prefix: &str) -> Option<&'a str> {
    let head = text.get(..prefix.len())?;
    head.eq_ignore_ascii_case(prefix)
        .then(|| &text[prefix.len()..])
}

/// Decodes `%XX` escapes; a `%` not followed by two hex digits is an error.
fn percent_decode(text: &str) -> Result<Vec<u8>, String> {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = bytes
                .get(i + 1..i + 3)
                .and_then(|pair| std::str::from_utf8(pair).ok())
                .and_then(|pair| u8::from_str_radix(pair, 16).ok())
                .ok_or_else(|| format!("invalid percent escape at byte {i}"))?;
            out.push(hex);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    Ok(out)
}

/// What `fmi2Instantiate` needs from `resources/`.
#[derive(Clone, Debug)]
pub struct Resources {
    /// The robot model parsed from `quadruped.urdf`.
    pub model: RobotModel,
    /// The configuration from `controller.json`.
    pub config: ControllerConfig,
}

/// Loads and checks `quadruped.urdf` and `controller.json` from `dir`.
pub fn load(dir: &Path) -> Result<Resources, FmuError> {
    if !dir.is_dir() {
        return Err(FmuError::Resources(format!(
            "resources folder {} does not exist",
            dir.display()
        )));
    }
    let read = |name: &str| {
        let path = dir.join(name);
        std::fs::read_to_string(&path)
            .map_err(|e| FmuError::Resources(format!("cannot read {}: {e}", path.display())))
    };
    let urdf = read(URDF_FILE)?;
    let model = RobotModel::from_urdf_str(&urdf)
        .map_err(|e| FmuError::Resources(format!("{URDF_FILE}: {e}")))?;
    let config: ControllerConfig = serde_json::from_str(&read(CONFIG_FILE)?)
        .map_err(|e| FmuError::Resources(format!("{CONFIG_FILE}: {e}")))?;
    crate::variables::check_parameters(&config)
        .map_err(|e| FmuError::Resources(format!("{CONFIG_FILE}: {e}")))?;
    Ok(Resources { model, config })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_uris_are_decoded() {
        let cases = [
            ("file:///tmp/a%20b/resources", "/tmp/a b/resources"),
            ("file:///tmp/x/resources/", "/tmp/x/resources/"),
            ("FILE://localhost/opt/r%C3%A9s", "/opt/rés"),
            ("file:/tmp/single", "/tmp/single"),
            ("/plain/path", "/plain/path"),
            ("file:///tmp/q?x=1", "/tmp/q"),
        ];
        for (uri, path) in cases {
            assert_eq!(
                resource_dir_from_uri(uri).unwrap(),
                PathBuf::from(path),
                "{uri}"
            );
        }
    }

    #[test]
    fn bad_uris_are_rejected_with_a_reason() {
        for uri in [
            "http://example.com/resources",
            "file://server/share",
            "file:relative/path",
            "file:///tmp/%zz",
            "file:///tmp/%4",
            "relative/path",
            "",
        ] {
            let err = resource_dir_from_uri(uri).unwrap_err().to_string();
            assert!(err.contains("fmuResourceLocation"), "{uri}: {err}");
        }
    }

    #[test]
    fn a_shipped_configuration_outside_the_ranges_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let urdf = crate::bundle::repo_root()
            .join("robot")
            .join("quadruped.urdf");
        std::fs::copy(urdf, dir.path().join(URDF_FILE)).unwrap();
        let write = |config: &ControllerConfig| {
            std::fs::write(
                dir.path().join(CONFIG_FILE),
                serde_json::to_string(config).unwrap(),
            )
            .unwrap()
        };
        write(&ControllerConfig::default());
        assert!(load(dir.path()).is_ok());
        // The first hang of the issue: a 1e-12 s tick made the first 1 ms doStep run 10⁹ ticks.
        write(&ControllerConfig {
            control_dt: 1e-12,
            ..ControllerConfig::default()
        });
        let err = load(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains("controller.json: invalid value for control.dt"),
            "{err}"
        );
        write(&ControllerConfig {
            mpc_every_ticks: usize::MAX,
            ..ControllerConfig::default()
        });
        let err = load(dir.path()).unwrap_err().to_string();
        assert!(err.contains("mpc.everyTicks"), "{err}");
    }

    #[test]
    fn missing_folder_is_reported() {
        let err = load(Path::new("/nonexistent/fmu/resources")).unwrap_err();
        assert!(err.to_string().contains("does not exist"), "{err}");
    }
}
