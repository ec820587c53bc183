//! Resolving the file names in a robot config: relative paths are taken from the config's folder,
//! `package://NAME/PATH` from a search path of package roots (the ROS convention: the package
//! `NAME` is the folder `ROOT/NAME` of the first root that has one). URDFs installed by a Python
//! package (e.g. in `site-packages/cmeel.prefix/share`) are named this way, so a config does not
//! depend on where a virtual environment lives.

use std::path::{Path, PathBuf};

/// Environment variable read by [`PackagePath::from_env`]: package roots separated by `:`.
pub const PACKAGE_PATH_ENV: &str = "PFNAV_PACKAGE_PATH";

pub(crate) const PACKAGE_SCHEME: &str = "package://";

/// Ordered list of package roots.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PackagePath {
    roots: Vec<PathBuf>,
}

impl PackagePath {
    /// Roots searched in order.
    pub fn new(roots: Vec<PathBuf>) -> Self {
        PackagePath { roots }
    }

    /// Roots from [`PACKAGE_PATH_ENV`] (empty when unset).
    pub fn from_env() -> Self {
        let roots = std::env::var_os(PACKAGE_PATH_ENV)
            .map(|value| {
                std::env::split_paths(&value)
                    .filter(|p| !p.as_os_str().is_empty())
                    .collect()
            })
            .unwrap_or_default();
        PackagePath { roots }
    }

    /// The roots.
    pub fn roots(&self) -> &[PathBuf] {
        &self.roots
    }

    /// The file `reference` names: `package://NAME/PATH` through the roots, a relative path
    /// from `relative_to`, an absolute path as is. The file must exist.
    pub fn resolve(&self, reference: &str, relative_to: &Path) -> Result<PathBuf, String> {
        let path = match reference.strip_prefix(PACKAGE_SCHEME) {
            Some(rest) => self.resolve_package(reference, rest)?,
            None => relative_to.join(reference),
        };
        if path.is_file() {
            Ok(path)
        } else {
            Err(format!(
                "`{reference}` resolves to {}, which is not a file",
                path.display()
            ))
        }
    }

    /// The folder of package `name`: `ROOT/name` of the first root that has one.
    pub fn package_dir(&self, name: &str) -> Option<PathBuf> {
        self.roots
            .iter()
            .map(|root| root.join(name))
            .find(|dir| dir.is_dir())
    }

    fn resolve_package(&self, reference: &str, rest: &str) -> Result<PathBuf, String> {
        let (package, inner) = rest
            .split_once('/')
            .filter(|(package, inner)| !package.is_empty() && !inner.is_empty())
            .ok_or_else(|| format!("`{reference}` is not of the form package://NAME/PATH"))?;
        if Path::new(inner)
            .components()
            .any(|c| !matches!(c, std::path::Component::Normal(_)))
        {
            return Err(format!(
                "`{reference}`: the path inside the package must be relative and must not leave it"
            ));
        }
        self.package_dir(package)
            .map(|dir| dir.join(inner))
            .ok_or_else(|| {
                format!(
                    "package `{package}` of `{reference}` is in none of the package roots {:?}; \
                     install it and list the folder that contains `{package}/` in {PACKAGE_PATH_ENV}",
                    self.roots
                )
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn package_uri_resolves_through_the_first_root_holding_the_package() {
        let dir = std::env::temp_dir().join(format!("pfnav-pkgpath-{}", std::process::id()));
        let file = dir.join("second/pkg/urdf/r.urdf");
        std::fs::create_dir_all(file.parent().expect("parent")).expect("mkdir");
        std::fs::write(&file, "<robot/>").expect("write");
        let path = PackagePath::new(vec![dir.join("first"), dir.join("second")]);
        assert_eq!(
            path.resolve("package://pkg/urdf/r.urdf", Path::new("/elsewhere")),
            Ok(file.clone())
        );
        let missing = path
            .resolve("package://other/r.urdf", Path::new("."))
            .expect_err("unknown package");
        assert!(missing.contains("package `other`"), "{missing}");
        assert!(missing.contains(PACKAGE_PATH_ENV), "{missing}");
        let escaping = path
            .resolve("package://pkg/../pkg/urdf/r.urdf", Path::new("."))
            .expect_err("`..` refused");
        assert!(escaping.contains("must not leave"), "{escaping}");
        assert!(path.resolve("package://pkg", Path::new(".")).is_err());
        assert_eq!(
            PackagePath::default().resolve("r.urdf", &dir.join("second/pkg/urdf")),
            Ok(file)
        );
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }
}
