//! Packs the FMU archive of one robot:
//! `modelDescription.xml`, `binaries/<platform>/QuadController.<so|dll|dylib>` (one per platform
//! given: `linux64`, `win64`, `darwin64`), `resources/robot/` (the robot config, its URDF and the
//! meshes the URDF names, see [`RobotFiles`]), `resources/controller.json` (the default tuning
//! scaled to the robot, [`ControllerConfig::for_robot`]), `documentation/index.html`. The
//! variable table, and so `modelDescription.xml`, is built from the same robot and tuning.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use quad_controller::{ControllerConfig, PackagePath, RobotModel};
use zip::write::SimpleFileOptions;

use crate::model_description::{documentation_html, model_description_xml};
use crate::resources::{CONFIG_FILE, ROBOT_CONFIG_FILE, ROBOT_DIR, URDF_FILE};
use crate::variables::VariableTable;
use crate::MODEL_IDENTIFIER;

/// Errors while bundling.
#[derive(Debug, thiserror::Error)]
pub enum BundleError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The zip writer failed.
    #[error("writing the archive {path}: {source}")]
    Zip {
        /// The archive.
        path: PathBuf,
        /// The zip error.
        source: zip::result::ZipError,
    },
    /// The default configuration could not be serialised.
    #[error("serialising the default controller configuration: {0}")]
    Json(#[from] serde_json::Error),
    /// No binary, two for one platform, or a file that is not a binary of its platform.
    #[error("{0}")]
    Binaries(String),
    /// The robot description cannot be bundled (bad config or URDF, missing mesh, a tuning
    /// that cannot stand it).
    #[error("{0}")]
    Robot(String),
}

/// An FMI 2.0 platform folder under `binaries/` (standard, section 2.1.9).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Platform {
    /// `linux64`: an x86-64 ELF shared object, `.so`.
    Linux64,
    /// `win64`: an x86-64 PE DLL, `.dll`.
    Win64,
    /// `darwin64`: an x86-64 Mach-O dynamic library, `.dylib`.
    Darwin64,
}

impl Platform {
    /// All platforms, in archive order.
    pub const ALL: [Platform; 3] = [Platform::Linux64, Platform::Win64, Platform::Darwin64];

    /// The folder name under `binaries/`.
    pub fn folder(self) -> &'static str {
        match self {
            Platform::Linux64 => "linux64",
            Platform::Win64 => "win64",
            Platform::Darwin64 => "darwin64",
        }
    }

    /// The file name FMI requires: `<modelIdentifier>.<extension>`.
    pub fn file_name(self) -> String {
        let extension = match self {
            Platform::Linux64 => "so",
            Platform::Win64 => "dll",
            Platform::Darwin64 => "dylib",
        };
        format!("{MODEL_IDENTIFIER}.{extension}")
    }

    /// The archive member of this platform's binary.
    pub fn member(self) -> String {
        format!("binaries/{}/{}", self.folder(), self.file_name())
    }

    /// Whether `bytes` start like an x86-64 binary of this platform (ELF class 64 with machine
    /// x86-64, a PE file, a 64-bit little-endian Mach-O for x86-64).
    pub fn looks_like_binary(self, bytes: &[u8]) -> bool {
        let u16_at = |at: usize| {
            bytes
                .get(at..at + 2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
        };
        let u32_at = |at: usize| {
            bytes
                .get(at..at + 4)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        };
        match self {
            Platform::Linux64 => bytes.starts_with(b"\x7fELF\x02\x01") && u16_at(18) == Some(62),
            Platform::Win64 => {
                let Some(pe) = u32_at(0x3c).and_then(|at| usize::try_from(at).ok()) else {
                    return false;
                };
                bytes.starts_with(b"MZ")
                    && bytes.get(pe..pe + 4) == Some(b"PE\0\0".as_slice())
                    && u16_at(pe + 4) == Some(0x8664)
            }
            Platform::Darwin64 => u32_at(0) == Some(0xfeed_facf) && u32_at(4) == Some(0x0100_0007),
        }
    }
}

impl std::fmt::Display for Platform {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.folder())
    }
}

impl std::str::FromStr for Platform {
    type Err = String;

    fn from_str(name: &str) -> Result<Self, Self::Err> {
        Platform::ALL
            .into_iter()
            .find(|p| p.folder() == name)
            .ok_or_else(|| {
                format!("unknown platform {name:?} (expected linux64, win64 or darwin64)")
            })
    }
}

/// Where the FMU binaries come from.
#[derive(Clone, Debug)]
pub enum BinarySource {
    /// Files (cdylibs built by cargo), at most one per platform, at least one.
    Files(Vec<(Platform, PathBuf)>),
    /// The `binaries/` of an existing FMU archive of this model (e.g. the FMU of another robot):
    /// a robot needs no new build.
    Archive(PathBuf),
}

/// What goes into the archive.
#[derive(Clone, Debug)]
pub struct BundleInputs {
    /// The FMU binaries.
    pub binaries: BinarySource,
    /// The robot config (TOML) of the robot the FMU controls.
    pub robot_config: PathBuf,
    /// Where `package://` references of the config and the URDF resolve.
    pub packages: PackagePath,
}

impl BundleInputs {
    /// Our own robot (`robot/quadruped.toml`) and only a `linux64` binary (cargo's
    /// [`SHARED_LIBRARY_FILE`]).
    pub fn linux64(shared_library: PathBuf) -> Self {
        BundleInputs {
            binaries: BinarySource::Files(vec![(Platform::Linux64, shared_library)]),
            robot_config: default_robot_config(),
            packages: PackagePath::from_env(),
        }
    }
}

/// The repository's own robot config, `robot/quadruped.toml`.
pub fn default_robot_config() -> PathBuf {
    repo_root().join("robot").join("quadruped.toml")
}

/// A robot description as an FMU carries it under `resources/robot/`: the config with its `urdf`
/// key naming the bundled URDF, the URDF with every mesh reference rewritten to the bundled copy
/// (`meshes/NAME/PATH` for `package://NAME/PATH`, `meshes/file/<n>-<file name>` for a path), and
/// the meshes. The FMU reads only the config and the URDF; the meshes travel with them so that
/// an importer (or a simulator) finds the complete robot in the FMU.
#[derive(Clone, Debug)]
pub struct RobotFiles {
    /// `robot.toml`.
    pub config_toml: String,
    /// `robot.urdf`.
    pub urdf: String,
    /// `(path relative to resources/robot/, contents)` of every mesh, in URDF order, once each.
    pub meshes: Vec<(String, Vec<u8>)>,
}

impl RobotFiles {
    /// Reads the config at `config_path`, its URDF and every mesh the URDF names.
    pub fn collect(config_path: &Path, packages: &PackagePath) -> Result<Self, BundleError> {
        let config_text = String::from_utf8(read(config_path)?).map_err(|_| {
            BundleError::Robot(format!("{}: not UTF-8 text", config_path.display()))
        })?;
        let config = quad_controller::RobotConfig::from_toml_str(
            &config_text,
            &config_path.display().to_string(),
        )
        .map_err(|e| BundleError::Robot(e.to_string()))?;
        let urdf_path = config
            .urdf_path(config_path, packages)
            .map_err(|e| BundleError::Robot(e.to_string()))?;
        let urdf_text = String::from_utf8(read(&urdf_path)?)
            .map_err(|_| BundleError::Robot(format!("{}: not UTF-8 text", urdf_path.display())))?;
        // Checked as the user's files first, so that an error names them, not the copies.
        RobotModel::from_named_texts(
            &config_text,
            &config_path.display().to_string(),
            &urdf_text,
            &urdf_path.display().to_string(),
        )
        .map_err(|e| BundleError::Robot(e.to_string()))?;
        let robot = urdf_rs::read_from_string(&urdf_text)
            .map_err(|e| BundleError::Robot(format!("{}: {e}", urdf_path.display())))?;
        let urdf_dir = urdf_path.parent().unwrap_or_else(|| Path::new("."));
        let mut urdf = urdf_text.clone();
        let mut meshes: Vec<(String, Vec<u8>)> = Vec::new();
        let mut seen: Vec<String> = Vec::new();
        for link in &robot.links {
            let geometries = link
                .visual
                .iter()
                .map(|v| &v.geometry)
                .chain(link.collision.iter().map(|c| &c.geometry));
            for geometry in geometries {
                let urdf_rs::Geometry::Mesh { filename, .. } = geometry else {
                    continue;
                };
                if seen.contains(filename) {
                    continue;
                }
                seen.push(filename.clone());
                let local = filename.strip_prefix("file://").unwrap_or(filename);
                let source = packages.resolve(local, urdf_dir).map_err(|reason| {
                    BundleError::Robot(format!(
                        "{}: mesh of link `{}`: {reason}",
                        urdf_path.display(),
                        link.name
                    ))
                })?;
                let member = match local.strip_prefix("package://") {
                    Some(inner) => format!("meshes/{inner}"),
                    None => format!(
                        "meshes/file/{}-{}",
                        meshes.len(),
                        source
                            .file_name()
                            .map(|n| n.to_string_lossy().into_owned())
                            .unwrap_or_default()
                    ),
                };
                for quote in ['"', '\''] {
                    urdf = urdf.replace(
                        &format!("filename={quote}{filename}{quote}"),
                        &format!("filename={quote}{member}{quote}"),
                    );
                }
                meshes.push((member, read(&source)?));
            }
        }
        let mut table: toml::Table = toml::from_str(&config_text)
            .map_err(|e| BundleError::Robot(format!("{}: {e}", config_path.display())))?;
        table.insert("urdf".to_owned(), toml::Value::String(URDF_FILE.to_owned()));
        let body = toml::to_string(&table)
            .map_err(|e| BundleError::Robot(format!("{}: {e}", config_path.display())))?;
        let config_name = config_path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let config_toml = format!(
            "# The robot config {config_name} as bundled by bundle-fmu: `urdf` names the bundled copy of\n\
             # {}, whose mesh references point at the copies under meshes/.\n{body}",
            config.urdf
        );
        Ok(RobotFiles {
            config_toml,
            urdf,
            meshes,
        })
    }

    /// The controller's model of the bundled robot (what the FMU will load).
    pub fn model(&self) -> Result<RobotModel, BundleError> {
        RobotModel::from_named_texts(
            &self.config_toml,
            &format!("{ROBOT_DIR}/{ROBOT_CONFIG_FILE}"),
            &self.urdf,
            &format!("{ROBOT_DIR}/{URDF_FILE}"),
        )
        .map_err(|e| BundleError::Robot(e.to_string()))
    }

    /// `(archive member, contents)` of every file, under `resources/robot/`.
    pub fn members(&self) -> Vec<(String, &[u8])> {
        let mut members = vec![
            (
                format!("resources/{ROBOT_DIR}/{ROBOT_CONFIG_FILE}"),
                self.config_toml.as_bytes(),
            ),
            (
                format!("resources/{ROBOT_DIR}/{URDF_FILE}"),
                self.urdf.as_bytes(),
            ),
        ];
        members.extend(
            self.meshes
                .iter()
                .map(|(path, bytes)| (format!("resources/{ROBOT_DIR}/{path}"), bytes.as_slice())),
        );
        members
    }

    /// Writes the files into a `resources/` folder (tests, unpacked FMUs).
    pub fn write_resources(&self, resources: &Path) -> Result<(), BundleError> {
        for (member, bytes) in self.members() {
            let relative = member.strip_prefix("resources/").unwrap_or(&member);
            let path = resources.join(relative);
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent).map_err(|source| BundleError::Io {
                    path: parent.to_owned(),
                    source,
                })?;
            }
            std::fs::write(&path, bytes).map_err(|source| BundleError::Io { path, source })?;
        }
        Ok(())
    }
}

/// Writes what `resources/` of the FMU of `robot_config` holds into the folder `resources` (an
/// unpacked FMU without the archive; tests instantiate from it).
pub fn write_resources(
    robot_config: &Path,
    packages: &PackagePath,
    resources: &Path,
) -> Result<(), BundleError> {
    let robot = RobotFiles::collect(robot_config, packages)?;
    robot.write_resources(resources)?;
    let config = serde_json::to_string_pretty(&ControllerConfig::for_robot(&robot.model()?))?;
    let path = resources.join(CONFIG_FILE);
    std::fs::write(&path, config).map_err(|source| BundleError::Io { path, source })
}

/// The resources of the repository's own robot, written into `dir` (tests build FMU instances on them).
#[cfg(test)]
pub(crate) fn write_default_resources(dir: &Path) {
    write_resources(
        &default_robot_config(),
        &quad_controller::PackagePath::default(),
        dir,
    )
    .expect("the repository's robot writes its resources");
}

/// The `binaries/` members of the FMU archive at `path`, by platform.
fn binaries_of_archive(path: &Path) -> Result<Vec<(Platform, Vec<u8>)>, BundleError> {
    let zip_error = |source| BundleError::Zip {
        path: path.to_owned(),
        source,
    };
    let file = std::fs::File::open(path).map_err(|source| BundleError::Io {
        path: path.to_owned(),
        source,
    })?;
    let mut archive = zip::ZipArchive::new(file).map_err(zip_error)?;
    let mut binaries = Vec::new();
    for platform in Platform::ALL {
        let mut entry = match archive.by_name(&platform.member()) {
            Ok(entry) => entry,
            Err(zip::result::ZipError::FileNotFound) => continue,
            Err(e) => return Err(zip_error(e)),
        };
        let mut bytes = Vec::new();
        entry
            .read_to_end(&mut bytes)
            .map_err(|source| BundleError::Io {
                path: path.to_owned(),
                source,
            })?;
        binaries.push((platform, bytes));
    }
    Ok(binaries)
}

fn read(path: &Path) -> Result<Vec<u8>, BundleError> {
    std::fs::read(path).map_err(|source| BundleError::Io {
        path: path.to_owned(),
        source,
    })
}

/// Writes the `.fmu` archive to `output` (parent folders are created).
pub fn write_fmu(inputs: &BundleInputs, output: &Path) -> Result<(), BundleError> {
    let mut binaries: Vec<(Platform, Vec<u8>)> = Vec::new();
    match &inputs.binaries {
        BinarySource::Files(files) => {
            for (platform, path) in files {
                if binaries.iter().any(|(p, _)| p == platform) {
                    return Err(BundleError::Binaries(format!(
                        "two binaries given for {platform}"
                    )));
                }
                let bytes = read(path)?;
                if !platform.looks_like_binary(&bytes) {
                    return Err(BundleError::Binaries(format!(
                        "{} is not an x86-64 {platform} binary",
                        path.display()
                    )));
                }
                binaries.push((*platform, bytes));
            }
        }
        BinarySource::Archive(path) => {
            binaries = binaries_of_archive(path)?;
            if let Some((platform, _)) = binaries
                .iter()
                .find(|(platform, bytes)| !platform.looks_like_binary(bytes))
            {
                return Err(BundleError::Binaries(format!(
                    "{}: {} is not an x86-64 {platform} binary",
                    path.display(),
                    platform.member()
                )));
            }
        }
    }
    if binaries.is_empty() {
        return Err(BundleError::Binaries("no FMU binary given".to_owned()));
    }
    binaries.sort_by_key(|(platform, _)| *platform);
    let robot = RobotFiles::collect(&inputs.robot_config, &inputs.packages)?;
    let model = robot.model()?;
    let config = ControllerConfig::for_robot(&model);
    let table = VariableTable::new(&model, &config)
        .map_err(|e| BundleError::Robot(format!("{}: {e}", inputs.robot_config.display())))?;
    let config = serde_json::to_string_pretty(&config)?;
    let model_description = model_description_xml(&table);
    let documentation = documentation_html(&table);
    let io_error = |path: &Path| {
        let path = path.to_owned();
        move |source| BundleError::Io { path, source }
    };
    if let Some(parent) = output.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(io_error(parent))?;
    }
    // Write to a temporary name first so that a failed run never leaves a truncated .fmu.
    let partial = output.with_extension("fmu.partial");
    let file = std::fs::File::create(&partial).map_err(io_error(&partial))?;
    let mut zip = zip::ZipWriter::new(file);
    let options = SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .unix_permissions(0o644);
    let mut entries: Vec<(String, &[u8])> = vec![(
        "modelDescription.xml".to_owned(),
        model_description.as_bytes(),
    )];
    entries.extend(
        binaries
            .iter()
            .map(|(platform, bytes)| (platform.member(), bytes.as_slice())),
    );
    entries.extend(robot.members());
    entries.extend([
        (format!("resources/{CONFIG_FILE}"), config.as_bytes()),
        (
            "documentation/index.html".to_owned(),
            documentation.as_bytes(),
        ),
    ]);
    let zip_error = |source| BundleError::Zip {
        path: output.to_owned(),
        source,
    };
    for (name, bytes) in entries {
        zip.start_file(name, options).map_err(zip_error)?;
        zip.write_all(bytes).map_err(io_error(&partial))?;
    }
    zip.finish().map_err(zip_error)?;
    std::fs::rename(&partial, output).map_err(io_error(output))?;
    Ok(())
}

/// The repository root this crate was built from (`fmu/..`).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

/// The file name cargo gives the FMU's shared library on Linux (crate `quad-controller-fmu-binary`).
pub const SHARED_LIBRARY_FILE: &str = "libquad_controller_fmu_binary.so";

/// Where cargo put the cdylib next to an executable of the same build
/// (`target/<profile>/` for binaries, `target/<profile>/deps/` for tests and examples).
pub fn shared_library_next_to(executable: &Path) -> Option<PathBuf> {
    let name = SHARED_LIBRARY_FILE;
    let dir = executable.parent()?;
    [
        dir.join(name),
        dir.parent()?.join(name),
        dir.join("deps").join(name),
    ]
    .into_iter()
    .find(|p| p.is_file())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first bytes of an x86-64 binary of `platform`, enough for `looks_like_binary`.
    fn fake_binary(platform: Platform) -> Vec<u8> {
        let mut bytes = vec![0u8; 0x90];
        match platform {
            Platform::Linux64 => {
                bytes[..6].copy_from_slice(b"\x7fELF\x02\x01");
                bytes[18..20].copy_from_slice(&62u16.to_le_bytes());
            }
            Platform::Win64 => {
                bytes[..2].copy_from_slice(b"MZ");
                bytes[0x3c..0x40].copy_from_slice(&0x80u32.to_le_bytes());
                bytes[0x80..0x84].copy_from_slice(b"PE\0\0");
                bytes[0x84..0x86].copy_from_slice(&0x8664u16.to_le_bytes());
            }
            Platform::Darwin64 => {
                bytes[..4].copy_from_slice(&0xfeed_facfu32.to_le_bytes());
                bytes[4..8].copy_from_slice(&0x0100_0007u32.to_le_bytes());
            }
        }
        bytes
    }

    #[test]
    fn platforms_name_their_folder_and_file() {
        let members: Vec<String> = Platform::ALL.iter().map(|p| p.member()).collect();
        assert_eq!(
            members,
            [
                "binaries/linux64/QuadController.so",
                "binaries/win64/QuadController.dll",
                "binaries/darwin64/QuadController.dylib",
            ]
        );
        for platform in Platform::ALL {
            assert_eq!(platform.to_string().parse::<Platform>(), Ok(platform));
            for other in Platform::ALL {
                assert_eq!(
                    platform.looks_like_binary(&fake_binary(other)),
                    platform == other,
                    "{platform} vs a {other} header"
                );
            }
            assert!(!platform.looks_like_binary(b""));
        }
        assert!("win32".parse::<Platform>().is_err());
    }

    #[test]
    fn every_given_platform_is_bundled_and_mistakes_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut binaries = Vec::new();
        for platform in [Platform::Darwin64, Platform::Linux64, Platform::Win64] {
            let path = dir.path().join(platform.file_name());
            std::fs::write(&path, fake_binary(platform)).unwrap();
            binaries.push((platform, path));
        }
        let out = dir.path().join("all.fmu");
        let inputs = |binaries: BinarySource| BundleInputs {
            binaries,
            robot_config: default_robot_config(),
            packages: PackagePath::default(),
        };
        write_fmu(&inputs(BinarySource::Files(binaries.clone())), &out).unwrap();
        let archive = zip::ZipArchive::new(std::fs::File::open(&out).unwrap()).unwrap();
        let names: Vec<&str> = archive.file_names().collect();
        for platform in Platform::ALL {
            assert!(names.contains(&platform.member().as_str()), "{names:?}");
        }

        // Another FMU's binaries, taken as they are.
        let again = dir.path().join("again.fmu");
        write_fmu(&inputs(BinarySource::Archive(out.clone())), &again).unwrap();
        let copied = zip::ZipArchive::new(std::fs::File::open(&again).unwrap()).unwrap();
        for platform in Platform::ALL {
            assert!(copied.index_for_name(&platform.member()).is_some());
        }

        let refused = |binaries: Vec<(Platform, PathBuf)>, needle: &str| {
            let err = write_fmu(
                &inputs(BinarySource::Files(binaries)),
                &dir.path().join("bad.fmu"),
            )
            .unwrap_err()
            .to_string();
            assert!(err.contains(needle), "{err}");
            assert!(!dir.path().join("bad.fmu").exists());
        };
        refused(Vec::new(), "no FMU binary");
        refused(
            vec![binaries[1].clone(), binaries[1].clone()],
            "two binaries given for linux64",
        );
        refused(
            vec![(Platform::Win64, binaries[1].1.clone())],
            "is not an x86-64 win64 binary",
        );
    }

    /// Our robot with a visual mesh on the base from a package and one given by a relative path.
    fn robot_with_meshes(dir: &Path) -> (PathBuf, PackagePath) {
        let repo = repo_root().join("robot");
        let urdf = std::fs::read_to_string(repo.join("quadruped.urdf")).unwrap();
        let foot = urdf.find("<link name=\"FR_foot\">").unwrap();
        let (before_foot, from_foot) = urdf.split_at(foot);
        let with_meshes = before_foot.replacen(
            "<box size=\"0.267 0.194 0.114\"/></geometry></visual>",
            "<mesh filename=\"package://shapes/meshes/body.stl\"/></geometry></visual>",
            1,
        ) + &from_foot.replacen(
            "<sphere radius=\"0.02\"/></geometry></visual>",
            "<mesh filename='../parts/foot.dae'/></geometry></visual>",
            1,
        );
        assert_ne!(with_meshes, urdf, "the test URDF has the links it edits");
        std::fs::create_dir_all(dir.join("roots/shapes/meshes")).unwrap();
        std::fs::create_dir_all(dir.join("robot/urdf")).unwrap();
        std::fs::create_dir_all(dir.join("robot/parts")).unwrap();
        std::fs::write(dir.join("roots/shapes/meshes/body.stl"), b"solid body").unwrap();
        std::fs::write(dir.join("robot/parts/foot.dae"), b"<COLLADA/>").unwrap();
        std::fs::write(dir.join("robot/urdf/r.urdf"), with_meshes).unwrap();
        let config = std::fs::read_to_string(repo.join("quadruped.toml"))
            .unwrap()
            .replace("urdf = \"quadruped.urdf\"", "urdf = \"urdf/r.urdf\"");
        let config_path = dir.join("robot/r.toml");
        std::fs::write(&config_path, config).unwrap();
        (config_path, PackagePath::new(vec![dir.join("roots")]))
    }

    #[test]
    fn the_robot_travels_with_its_meshes_and_names_the_bundled_copies() {
        let dir = tempfile::tempdir().unwrap();
        let (config_path, packages) = robot_with_meshes(dir.path());
        let robot = RobotFiles::collect(&config_path, &packages).unwrap();
        let members: Vec<(String, Vec<u8>)> = robot
            .members()
            .into_iter()
            .map(|(name, bytes)| (name, bytes.to_vec()))
            .collect();
        let names: Vec<&str> = members.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(
            names,
            [
                "resources/robot/robot.toml",
                "resources/robot/robot.urdf",
                "resources/robot/meshes/shapes/meshes/body.stl",
                "resources/robot/meshes/file/1-foot.dae",
            ]
        );
        assert_eq!(members[2].1, b"solid body");
        assert_eq!(members[3].1, b"<COLLADA/>");
        assert!(robot
            .urdf
            .contains("filename=\"meshes/shapes/meshes/body.stl\""));
        assert!(robot.urdf.contains("filename='meshes/file/1-foot.dae'"));
        assert!(!robot.urdf.contains("package://"));
        assert!(robot.config_toml.contains("urdf = \"robot.urdf\""));
        // The bundled copies load on their own, as the FMU loads them, and the robot is the same.
        let model = robot.model().unwrap();
        let original = RobotModel::from_config_file_with(&config_path, &packages).unwrap();
        assert_eq!(model.total_mass(), original.total_mass());
        assert_eq!(
            model
                .stand_joint_positions(quad_controller::tuning::TUNED_STAND_HEIGHT)
                .unwrap(),
            original
                .stand_joint_positions(quad_controller::tuning::TUNED_STAND_HEIGHT)
                .unwrap()
        );
        // Unpacked into a resources folder, the FMU's loader reads it.
        robot
            .write_resources(&dir.path().join("resources"))
            .unwrap();
        std::fs::write(
            dir.path().join("resources").join(CONFIG_FILE),
            serde_json::to_string(&ControllerConfig::for_robot(&model)).unwrap(),
        )
        .unwrap();
        crate::resources::load(&dir.path().join("resources")).unwrap();
    }

    #[test]
    fn a_missing_mesh_or_package_is_named_with_its_link_and_file() {
        let dir = tempfile::tempdir().unwrap();
        let (config_path, packages) = robot_with_meshes(dir.path());
        std::fs::remove_file(dir.path().join("robot/parts/foot.dae")).unwrap();
        let err = RobotFiles::collect(&config_path, &packages)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("r.urdf") && err.contains("`FR_foot`") && err.contains("foot.dae"),
            "{err}"
        );
        let err = RobotFiles::collect(&config_path, &PackagePath::default())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("`base`") && err.contains("package `shapes`"),
            "{err}"
        );
        let err = RobotFiles::collect(&dir.path().join("robot/none.toml"), &packages)
            .unwrap_err()
            .to_string();
        assert!(err.contains("none.toml"), "{err}");
    }
}
