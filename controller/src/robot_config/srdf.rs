//! The `standing` group state of an SRDF (the robot's authors' own stand pose), found next to a
//! URDF as ROS description packages lay them out (`srdf/` beside `urdf/` or `robots/`).

use std::path::{Path, PathBuf};

/// Joint name → angle (rad) of a named `<group_state>`; the floating `root_joint` is skipped.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupState {
    /// The SRDF it was read from.
    pub file: PathBuf,
    /// Joint angles by joint name.
    pub joints: Vec<(String, f64)>,
}

impl GroupState {
    /// The angle of `joint`, if the state names it.
    pub fn angle(&self, joint: &str) -> Option<f64> {
        self.joints
            .iter()
            .find(|(name, _)| name == joint)
            .map(|(_, value)| *value)
    }
}

/// The SRDF files in the `srdf/` folders beside the URDF's folder and its parent, sorted.
pub fn srdf_files_near(urdf: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = [urdf.parent(), urdf.parent().and_then(Path::parent)]
        .into_iter()
        .flatten()
        .filter_map(|dir| std::fs::read_dir(dir.join("../srdf")).ok())
        .flatten()
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "srdf"))
        .map(|p| std::fs::canonicalize(&p).unwrap_or(p))
        .collect();
    files.sort();
    files.dedup();
    files
}

/// The group state called `name` in the SRDF text (the first one), as joint angles. The
/// parser reads `<group_state name=…>` … `</group_state>` and its `<joint name= value=>`
/// elements only: SRDFs are small and flat.
pub fn group_state(text: &str, name: &str, file: &Path) -> Option<GroupState> {
    let start = text.find(&format!("<group_state name=\"{name}\""))?;
    let end = start + text[start..].find("</group_state>")?;
    let joints = text[start..end]
        .split("<joint ")
        .skip(1)
        .filter_map(|element| {
            let attribute = |key: &str| {
                let from = element.find(&format!("{key}=\""))? + key.len() + 2;
                let to = from + element[from..].find('"')?;
                Some(element[from..to].to_string())
            };
            let joint = attribute("name")?;
            let value = attribute("value")?.trim().parse::<f64>().ok()?;
            (joint != "root_joint" && value.is_finite()).then_some((joint, value))
        })
        .collect();
    Some(GroupState {
        file: file.to_path_buf(),
        joints,
    })
}

/// The `standing` pose of the first SRDF near `urdf` that has one.
pub fn standing_pose_near(urdf: &Path) -> Option<GroupState> {
    srdf_files_near(urdf).into_iter().find_map(|file| {
        let text = std::fs::read_to_string(&file).ok()?;
        group_state(&text, "standing", &file)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_named_state_and_skips_the_root_joint() {
        let text = r#"<robot name="r">
  <group_state name="crouch" group="all"><joint name="a" value="9"/></group_state>
  <group_state name="standing" group="all">
    <joint name="root_joint" value="0. 0. 0.5 0. 0. 0. 1." />
    <joint name="a" value="-0.2" /><joint name="b" value="0.75"/>
    <joint name="c" value="nan"/>
  </group_state>
</robot>"#;
        let state = group_state(text, "standing", Path::new("r.srdf")).expect("state");
        assert_eq!(state.joints, vec![("a".into(), -0.2), ("b".into(), 0.75)]);
        assert_eq!(state.angle("b"), Some(0.75));
        assert!(group_state(text, "lying", Path::new("r.srdf")).is_none());
    }
}
