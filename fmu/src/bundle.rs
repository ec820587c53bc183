//! Packs the FMU archive:
//! `modelDescription.xml`, `binaries/linux64/QuadController.so`, `resources/quadruped.urdf`,
//! `resources/controller.json`, `documentation/index.html`.

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
}

/// What goes into the archive.
#[derive(Clone, Debug)]
pub struct BundleInputs {
    /// The cdylib built by cargo (`libquad_controller_fmu.so`).
    pub shared_library: PathBuf,
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
    let library = read(&inputs.shared_library)?;
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
    let entries: [(String, &[u8]); 5] = [
        (
            "modelDescription.xml".to_owned(),
            model_description.as_bytes(),
        ),
        (format!("binaries/linux64/{MODEL_IDENTIFIER}.so"), &library),
        (format!("resources/{URDF_FILE}"), urdf),
        (format!("resources/{CONFIG_FILE}"), config.as_bytes()),
        (
            "documentation/index.html".to_owned(),
            documentation.as_bytes(),
        ),
    ];
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
