//! Packs the FMU archive:
//! `modelDescription.xml`, `binaries/<platform>/QuadController.<so|dll|dylib>` (one per platform
//! given: `linux64`, `win64`, `darwin64`), `resources/quadruped.urdf`, `resources/controller.json`,
//! `documentation/index.html`.

use std::io::Write;
use std::path::{Path, PathBuf};

use quad_controller::ControllerConfig;
use zip::write::SimpleFileOptions;

use crate::model_description::{documentation_html, model_description_xml};
use crate::resources::{CONFIG_FILE, URDF_FILE};
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

/// What goes into the archive.
#[derive(Clone, Debug)]
pub struct BundleInputs {
    /// The FMU binaries (cdylibs built by cargo), at most one per platform, at least one.
    pub binaries: Vec<(Platform, PathBuf)>,
}

impl BundleInputs {
    /// Only a `linux64` binary (cargo's `libquad_controller_fmu.so`).
    pub fn linux64(shared_library: PathBuf) -> Self {
        BundleInputs {
            binaries: vec![(Platform::Linux64, shared_library)],
        }
    }
}

/// The default configuration as shipped in `resources/controller.json`.
pub fn default_config_json() -> Result<String, serde_json::Error> {
    serde_json::to_string_pretty(&ControllerConfig::default())
}

fn read(path: &Path) -> Result<Vec<u8>, BundleError> {
    std::fs::read(path).map_err(|source| BundleError::Io {
        path: path.to_owned(),
        source,
    })
}

/// Writes the `.fmu` archive to `output` (parent folders are created).
pub fn write_fmu(inputs: &BundleInputs, output: &Path) -> Result<(), BundleError> {
    let mut binaries = Vec::with_capacity(inputs.binaries.len());
    for (platform, path) in &inputs.binaries {
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
    if binaries.is_empty() {
        return Err(BundleError::Binaries("no FMU binary given".to_owned()));
    }
    binaries.sort_by_key(|(platform, _)| *platform);
    // The variable table (joint ranges, standing start values) is built from the compiled-in
    // robot, so the archive ships exactly that URDF: any other would contradict modelDescription.
    let urdf = crate::variables::ROBOT_URDF.as_bytes();
    let config = default_config_json()?;
    let model_description = model_description_xml();
    let documentation = documentation_html();
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
    entries.extend([
        (format!("resources/{URDF_FILE}"), urdf),
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

/// Where cargo put the cdylib next to an executable of the same build
/// (`target/<profile>/` for binaries, `target/<profile>/deps/` for tests and examples).
pub fn shared_library_next_to(executable: &Path) -> Option<PathBuf> {
    let name = "libquad_controller_fmu.so";
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
        write_fmu(
            &BundleInputs {
                binaries: binaries.clone(),
            },
            &out,
        )
        .unwrap();
        let archive = zip::ZipArchive::new(std::fs::File::open(&out).unwrap()).unwrap();
        let names: Vec<&str> = archive.file_names().collect();
        for platform in Platform::ALL {
            assert!(names.contains(&platform.member().as_str()), "{names:?}");
        }

        let refused = |binaries: Vec<(Platform, PathBuf)>, needle: &str| {
            let err = write_fmu(&BundleInputs { binaries }, &dir.path().join("bad.fmu"))
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
}
