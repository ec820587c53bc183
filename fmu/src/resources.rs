//! The FMU's `resources/` folder: locating it from `fmuResourceLocation` and loading the robot
//! model and the controller configuration it carries.
//!
//! The URI is parsed the same way on every host into a path in the conventions of a chosen OS
//! ([`PathStyle`]), so the Windows rules are unit-tested on Linux too; only the last step, bytes
//! to [`PathBuf`], depends on the host.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use quad_controller::{ControllerConfig, RobotModel};

use crate::variables::VariableTable;
use crate::FmuError;

/// Folder inside `resources/` that holds the robot: [`ROBOT_CONFIG_FILE`], [`URDF_FILE`] and the
/// meshes the URDF names (under `meshes/`, referenced relative to the URDF).
pub const ROBOT_DIR: &str = "robot";
/// The robot config inside [`ROBOT_DIR`]; its `urdf` key names [`URDF_FILE`].
pub const ROBOT_CONFIG_FILE: &str = "robot.toml";
/// The robot's URDF inside [`ROBOT_DIR`].
pub const URDF_FILE: &str = "robot.urdf";
/// File name of the default controller configuration inside `resources/` (JSON of
/// `ControllerConfig`); parameters set by the importer override it.
pub const CONFIG_FILE: &str = "controller.json";

/// The path conventions a resource URI is turned into.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathStyle {
    /// `/abs/path`: any bytes but NUL; a URI host other than `localhost` is refused.
    Unix,
    /// `C:\dir` or `\\server\share\dir`: UTF-8 text with `\` separators.
    Windows,
}

impl PathStyle {
    /// The conventions of the OS this library was compiled for.
    pub const HOST: PathStyle = if cfg!(windows) {
        PathStyle::Windows
    } else {
        PathStyle::Unix
    };
}

/// Converts `fmuResourceLocation` to a local directory path of this host; the accepted forms are
/// those of [`resource_path_from_uri`] with [`PathStyle::HOST`].
pub fn resource_dir_from_uri(location: &str) -> Result<PathBuf, FmuError> {
    resource_path_from_uri(location, PathStyle::HOST).and_then(|bytes| {
        host_path(bytes).map_err(|reason| FmuError::ResourceLocation {
            location: location.to_owned(),
            reason,
        })
    })
}

#[cfg(unix)]
fn host_path(bytes: Vec<u8>) -> Result<PathBuf, String> {
    use std::os::unix::ffi::OsStringExt;
    Ok(PathBuf::from(std::ffi::OsString::from_vec(bytes)))
}

#[cfg(not(unix))]
fn host_path(bytes: Vec<u8>) -> Result<PathBuf, String> {
    String::from_utf8(bytes)
        .map(PathBuf::from)
        .map_err(|_| "the decoded path is not valid UTF-8".to_owned())
}

/// Converts `fmuResourceLocation` to the bytes of a local directory path in `style`.
///
/// FMI 2.0 passes a URI (RFC 3986; RFC 8089 for `file:`), e.g. `file:///C:/temp/MyFMU/resources`
/// or `file:/C:/temp/MyFMU/resources`. Accepted, with the scheme in any case, `%XX` escapes
/// decoded (a malformed escape is an error) and a query or fragment dropped:
/// * [`PathStyle::Unix`]: `file:///abs/path`, `file://localhost/abs/path`, `file:/abs/path`; any
///   other host is refused (no network paths);
/// * [`PathStyle::Windows`]: a drive, as in `file:///C:/dir/`, `file:/C:/dir`,
///   `file://localhost/C:/dir`, the legacy `file:///C|/dir` and the malformed but common
///   `file://C:/dir`, gives `C:\dir\`; a host, as in `file://server/share/dir` or
///   `file:////server/share/dir`, gives the UNC path `\\server\share\dir`; a path with neither is
///   refused;
/// * leniently, a plain absolute path of the style: `/abs/path`; `C:\dir`, `C:/dir`,
///   `\\server\share\dir`.
///
/// A trailing slash is kept. The result is never empty and holds no NUL byte.
pub fn resource_path_from_uri(location: &str, style: PathStyle) -> Result<Vec<u8>, FmuError> {
    parse_location(location, style).map_err(|reason| FmuError::ResourceLocation {
        location: location.to_owned(),
        reason,
    })
}

fn parse_location(location: &str, style: PathStyle) -> Result<Vec<u8>, String> {
    let path = match strip_prefix_ignore_case(location, "file:") {
        Some(rest) => from_file_uri(rest, style)?,
        None => plain_path(location, style).ok_or("expected a file:// URI")?,
    };
    if path.contains(&0) {
        return Err("the path contains a NUL byte".to_owned());
    }
    Ok(path)
}

/// `rest`: what follows `file:`.
fn from_file_uri(rest: &str, style: PathStyle) -> Result<Vec<u8>, String> {
    let rest = rest.split(['?', '#']).next().unwrap_or(rest);
    let (host, encoded_path) = if let Some(after) = rest.strip_prefix("//") {
        let slash = after.find('/').unwrap_or(after.len());
        after.split_at(slash)
    } else if rest.starts_with('/') {
        ("", rest)
    } else {
        return Err("a file URI needs an absolute path".to_owned());
    };
    let path = percent_decode(encoded_path)?;
    let local = host.is_empty() || host.eq_ignore_ascii_case("localhost");
    match style {
        PathStyle::Unix if !local => {
            Err("only local files are supported (host must be empty or localhost)".to_owned())
        }
        PathStyle::Unix if path.is_empty() => Err("the URI has no path".to_owned()),
        PathStyle::Unix => Ok(path),
        PathStyle::Windows => {
            let host = utf8(percent_decode(host)?)?;
            windows_path(&host, local, &utf8(path)?).map(String::into_bytes)
        }
    }
}

/// The Windows path of a decoded URI authority and path (`/` separators still).
fn windows_path(host: &str, local: bool, path: &str) -> Result<String, String> {
    let text = if local {
        if let Some(drive_path) = path.strip_prefix('/').filter(|p| starts_with_drive(p)) {
            drive_path.to_owned()
        } else if let Some(unc) = path.strip_prefix("//") {
            // `file:////server/share` (RFC 8089 E.3.2) and the five-slash variant.
            unc_path(unc.trim_start_matches('/'))?
        } else {
            return Err(
                "a Windows file URI needs a drive (file:///C:/...) or a host (file://server/share/...)"
                    .to_owned(),
            );
        }
    } else if host.len() == 2 && starts_with_drive(host) {
        // `file://C:/dir`: the drive ended up in the authority.
        format!("{host}{path}")
    } else {
        unc_path(&format!("{host}{path}"))?
    };
    Ok(windows_separators(&text))
}

/// `server/share[/dir]` as `//server/share[/dir]`; both a host and a share are required.
fn unc_path(unc: &str) -> Result<String, String> {
    match unc.split_once('/') {
        Some((host, share)) if !host.is_empty() && !share.trim_matches('/').is_empty() => {
            Ok(format!("//{unc}"))
        }
        _ => Err("a UNC path needs a host and a share (//server/share)".to_owned()),
    }
}

/// `C:`, `c|` followed by the end or a separator.
fn starts_with_drive(path: &str) -> bool {
    let bytes = path.as_bytes();
    bytes.len() >= 2
        && bytes[0].is_ascii_alphabetic()
        && matches!(bytes[1], b':' | b'|')
        && matches!(bytes.get(2), None | Some(b'/' | b'\\'))
}

/// `/` to `\`, a legacy `C|` to `C:`, and a bare `C:` to the drive's root `C:\`.
fn windows_separators(path: &str) -> String {
    let mut text = path.replace('/', "\\");
    if starts_with_drive(&text) {
        text.replace_range(1..2, ":");
        if text.len() == 2 {
            text.push('\\');
        }
    }
    text
}

/// A location given as a plain absolute path instead of a URI.
fn plain_path(location: &str, style: PathStyle) -> Option<Vec<u8>> {
    let absolute = match style {
        PathStyle::Unix => location.starts_with('/'),
        PathStyle::Windows => {
            (starts_with_drive(location) && location.len() > 2)
                || location.starts_with("\\\\")
                || location.starts_with("//")
        }
    };
    absolute.then(|| match style {
        PathStyle::Unix => location.as_bytes().to_vec(),
        PathStyle::Windows => windows_separators(location).into_bytes(),
    })
}

fn utf8(bytes: Vec<u8>) -> Result<String, String> {
    String::from_utf8(bytes).map_err(|_| "the decoded path is not valid UTF-8".to_owned())
}

fn strip_prefix_ignore_case<'a>(text: &'a str, prefix: &str) -> Option<&'a str> {
    let head = text.get(..prefix.len())?;
    head.eq_ignore_ascii_case(prefix)
        .then(|| &text[prefix.len()..])
}

/// Decodes `%XX` escapes; a `%` not followed by two hex digits is an error (the decoder of the
/// `percent-encoding` crate would pass it through).
fn percent_decode(text: &str) -> Result<Vec<u8>, String> {
    let bytes = text.as_bytes();
    if let Some(at) = (0..bytes.len()).find(|&i| {
        bytes[i] == b'%'
            && !bytes
                .get(i + 1..i + 3)
                .is_some_and(|pair| pair.iter().all(u8::is_ascii_hexdigit))
    }) {
        return Err(format!("invalid percent escape at byte {at}"));
    }
    Ok(percent_encoding::percent_decode(bytes).collect())
}

/// What `fmi2Instantiate` needs from `resources/`.
#[derive(Clone, Debug)]
pub struct Resources {
    /// The robot model of `robot/robot.toml` and `robot/robot.urdf`.
    pub model: RobotModel,
    /// The configuration from `controller.json`.
    pub config: ControllerConfig,
    /// The variable table of this robot and configuration.
    pub table: Arc<VariableTable>,
    /// CRC-32 of the robot config and URDF texts (saved FMU states name the robot they were
    /// taken with).
    pub robot_crc: u32,
    /// The FMU's GUID, derived from the table ([`VariableTable::guid`]).
    pub guid: String,
}

/// CRC-32 that identifies a robot description: its config text, a NUL, its URDF text.
pub fn robot_crc(config_toml: &str, urdf_xml: &str) -> u32 {
    let mut hasher = crc32fast::Hasher::new();
    hasher.update(config_toml.as_bytes());
    hasher.update(&[0]);
    hasher.update(urdf_xml.as_bytes());
    hasher.finalize()
}

/// Loads and checks the robot (`robot/robot.toml`, `robot/robot.urdf`) and `controller.json` from
/// `dir`, and builds their variable table.
pub fn load(dir: &Path) -> Result<Resources, FmuError> {
    if !dir.is_dir() {
        return Err(FmuError::Resources(format!(
            "resources folder {} does not exist",
            dir.display()
        )));
    }
    let read = |path: PathBuf| {
        std::fs::read_to_string(&path)
            .map_err(|e| FmuError::Resources(format!("cannot read {}: {e}", path.display())))
    };
    let robot_dir = dir.join(ROBOT_DIR);
    let config_toml = read(robot_dir.join(ROBOT_CONFIG_FILE))?;
    let urdf = read(robot_dir.join(URDF_FILE))?;
    let model = RobotModel::from_named_texts(
        &config_toml,
        &format!("{ROBOT_DIR}/{ROBOT_CONFIG_FILE}"),
        &urdf,
        &format!("{ROBOT_DIR}/{URDF_FILE}"),
    )
    .map_err(|e| FmuError::Resources(e.to_string()))?;
    let config: ControllerConfig = serde_json::from_str(&read(dir.join(CONFIG_FILE))?)
        .map_err(|e| FmuError::Resources(format!("{CONFIG_FILE}: {e}")))?;
    let table = VariableTable::new(&model, &config)
        .map_err(|e| FmuError::Resources(format!("{CONFIG_FILE}: {e}")))?;
    Ok(Resources {
        model,
        config,
        guid: table.guid(),
        table: Arc::new(table),
        robot_crc: robot_crc(&config_toml, &urdf),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unix(uri: &str) -> Result<Vec<u8>, FmuError> {
        resource_path_from_uri(uri, PathStyle::Unix)
    }

    fn windows(uri: &str) -> Result<String, FmuError> {
        resource_path_from_uri(uri, PathStyle::Windows)
            .map(|bytes| String::from_utf8(bytes).expect("Windows paths are UTF-8"))
    }

    #[test]
    fn unix_file_uris_are_decoded() {
        let cases: [(&str, &[u8]); 9] = [
            ("file:///tmp/a%20b/resources", b"/tmp/a b/resources"),
            ("file:///tmp/x/resources/", b"/tmp/x/resources/"),
            ("FILE://localhost/opt/r%C3%A9s", "/opt/rés".as_bytes()),
            ("file:/tmp/single", b"/tmp/single"),
            ("/plain/path", b"/plain/path"),
            ("file:///tmp/q?x=1", b"/tmp/q"),
            ("file:///tmp/f#frag", b"/tmp/f"),
            // Not UTF-8: a Unix path is bytes.
            ("file:///tmp/%FF", b"/tmp/\xff"),
            // A Windows URI on Unix is an odd but valid Unix path, as before.
            ("file:///C:/dir", b"/C:/dir"),
        ];
        for (uri, path) in cases {
            assert_eq!(unix(uri).unwrap(), path, "{uri}");
        }
    }

    #[test]
    fn windows_file_uris_are_decoded() {
        let cases = [
            // The two forms the FMI 2.0 standard shows.
            (
                "file:///C:/temp/MyFMU/resources",
                r"C:\temp\MyFMU\resources",
            ),
            ("file:/C:/temp/MyFMU/resources", r"C:\temp\MyFMU\resources"),
            ("file:///C:/dir/", r"C:\dir\"),
            ("file://localhost/d:/x", r"d:\x"),
            (
                "FILE:///C:/Program%20Files/r%C3%A9s",
                r"C:\Program Files\rés",
            ),
            ("file:///C|/legacy", r"C:\legacy"),
            ("file:///C:", r"C:\"),
            ("file://C:/authority/drive", r"C:\authority\drive"),
            ("file:///C:/q?x=1#f", r"C:\q"),
            ("file://server/share/dir/", r"\\server\share\dir\"),
            ("file://server/share", r"\\server\share"),
            ("file:////server/share/dir", r"\\server\share\dir"),
            ("file://///server/share/dir", r"\\server\share\dir"),
            ("file://ser%20ver/sh%20are", r"\\ser ver\sh are"),
            (r"C:\plain\dir", r"C:\plain\dir"),
            ("C:/plain/dir", r"C:\plain\dir"),
            (r"\\server\share", r"\\server\share"),
        ];
        for (uri, path) in cases {
            assert_eq!(windows(uri).unwrap(), path, "{uri}");
        }
    }

    #[test]
    fn bad_uris_are_rejected_with_a_reason() {
        let both = [
            "http://example.com/resources",
            "file:relative/path",
            "file:C:/no/slash",
            "file:///tmp/%zz",
            "file:///tmp/%4",
            "file:///tmp/%",
            "file:///tmp/a%00b",
            "relative/path",
            "",
        ];
        let unix_only = ["file://server/share", "file://", "file://localhost"];
        let windows_only = [
            "file:///no/drive",
            "file:/no/drive",
            "file://localhost/no/drive",
            "file://server",
            "file://server/",
            "file:////server",
            "file:///C:/%FF",
            "file:///CC:/x",
            "file://",
            "/unix/path",
            "C:",
            "C:relative",
        ];
        for uri in both.iter().chain(&unix_only) {
            let err = unix(uri).unwrap_err().to_string();
            assert!(err.contains("fmuResourceLocation"), "{uri}: {err}");
        }
        for uri in both.iter().chain(&windows_only) {
            let err = windows(uri).unwrap_err().to_string();
            assert!(err.contains("fmuResourceLocation"), "{uri}: {err}");
        }
        let err = windows("file:///no/drive").unwrap_err().to_string();
        assert!(err.contains("needs a drive"), "{err}");
        let err = unix("file:///tmp/%zz").unwrap_err().to_string();
        assert!(err.contains("invalid percent escape at byte 5"), "{err}");
    }

    #[test]
    fn the_host_path_follows_the_host_style() {
        let (uri, expected) = if cfg!(windows) {
            ("file:///C:/a%20b/resources/", r"C:\a b\resources\")
        } else {
            ("file:///tmp/a%20b/resources/", "/tmp/a b/resources/")
        };
        assert_eq!(resource_dir_from_uri(uri).unwrap(), PathBuf::from(expected));
    }

    #[test]
    fn a_shipped_configuration_outside_the_ranges_is_refused() {
        let dir = our_resources();
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

    fn our_resources() -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        crate::bundle::write_default_resources(dir.path());
        dir
    }

    #[test]
    fn a_bad_robot_in_the_resources_is_named_by_its_file() {
        let dir = our_resources();
        let robot = dir.path().join(ROBOT_DIR);
        let loaded = load(dir.path()).unwrap();
        assert_eq!(loaded.table.robot_name(), loaded.model.name());
        let urdf = std::fs::read_to_string(robot.join(URDF_FILE)).unwrap();
        // A 16-DOF robot: one more movable joint than the legs' twelve.
        let extra = urdf.replace(
            "</robot>",
            "<link name=\"tail\"/><joint name=\"tail_joint\" type=\"revolute\"><parent link=\"base\"/>\
             <child link=\"tail\"/><axis xyz=\"0 1 0\"/><limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint></robot>",
        );
        std::fs::write(robot.join(URDF_FILE), extra).unwrap();
        let err = load(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains("robot/robot.urdf") && err.contains("tail_joint"),
            "{err}"
        );
        std::fs::write(robot.join(URDF_FILE), &urdf).unwrap();
        let config = std::fs::read_to_string(robot.join(ROBOT_CONFIG_FILE)).unwrap();
        std::fs::write(
            robot.join(ROBOT_CONFIG_FILE),
            config.replace("FL_knee_joint", "FL_elbow_joint"),
        )
        .unwrap();
        let err = load(dir.path()).unwrap_err().to_string();
        assert!(err.contains("FL_elbow_joint"), "{err}");
        std::fs::remove_file(robot.join(ROBOT_CONFIG_FILE)).unwrap();
        let err = load(dir.path()).unwrap_err().to_string();
        assert!(err.contains("robot/robot.toml"), "{err}");
    }

    #[test]
    fn missing_folder_is_reported() {
        let err = load(Path::new("/nonexistent/fmu/resources")).unwrap_err();
        assert!(err.to_string().contains("does not exist"), "{err}");
    }
}
