//! The foot radius of a robot whose feet are collision meshes: how far the mesh reaches below the
//! foot point when the robot stands. The controller treats a foot as a sphere around the foot
//! point, so that depth is the radius it needs; nobody should have to measure it by hand.
//!
//! STL (binary or ASCII) and Wavefront OBJ meshes are read; other formats (COLLADA `.dae`) get an
//! error that says to measure by hand.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use nalgebra::{Matrix3, Rotation3, Vector3};

use super::{PackagePath, RobotConfig};
use crate::api::Leg;
use crate::model::RobotModel;

/// Meshes beyond this many triangles are refused rather than read (a foot has a few thousand).
const MAX_TRIANGLES: usize = 2_000_000;
/// Files beyond this size are refused rather than read, bytes.
const MAX_MESH_BYTES: u64 = 256 << 20;
/// Legs whose measured radii differ by more than this are reported, m.
const LEG_SPREAD_TOLERANCE: f64 = 0.001;
/// The foot turns this far about the pitch axis during a stance (± from the stand), rad; the
/// depth over that range says how round the sole is.
pub const STANCE_PITCH_RANGE: f64 = 0.35;

/// The measured sole depth of every leg's foot mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct FootMeshRadius {
    /// The radius to configure: the largest leg's depth at the stand, m.
    pub radius: f64,
    /// Each leg's depth at the stand, m.
    pub per_leg: Vec<(Leg, f64)>,
    /// Smallest and largest depth of any leg while its foot pitches ±[`STANCE_PITCH_RANGE`], m.
    pub stance_range: (f64, f64),
    /// The mesh files measured.
    pub meshes: Vec<String>,
}

impl FootMeshRadius {
    /// Whether the legs' depths differ by more than a millimetre.
    pub fn legs_differ(&self) -> bool {
        let (min, max) = self
            .per_leg
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (_, d)| {
                (lo.min(*d), hi.max(*d))
            });
        max - min > LEG_SPREAD_TOLERANCE
    }
}

/// Measures the foot radius from the foot links' mesh collisions, with the legs at `stand`
/// (per leg: abduction, hip, knee, rad). `urdf_dir` resolves relative mesh paths.
pub fn measure_foot_radius(
    robot: &urdf_rs::Robot,
    config: &RobotConfig,
    model: &RobotModel,
    stand: &[[f64; 3]; 4],
    packages: &PackagePath,
    urdf_dir: &Path,
) -> Result<FootMeshRadius, String> {
    let mut per_leg = Vec::new();
    let mut meshes = Vec::new();
    let mut stance_range = (f64::INFINITY, f64::NEG_INFINITY);
    for leg in Leg::ALL {
        let leg_config = config.legs.get(leg);
        let link = robot
            .links
            .iter()
            .find(|l| l.name == leg_config.foot_link)
            .ok_or_else(|| format!("foot link `{}` is not in the URDF", leg_config.foot_link))?;
        let mut vertices = Vec::new();
        for collision in &link.collision {
            let urdf_rs::Geometry::Mesh { filename, scale } = &collision.geometry else {
                continue;
            };
            let path = packages.resolve(filename, urdf_dir)?;
            let scale = scale.as_ref().map_or([1.0; 3], |s| [s[0], s[1], s[2]]);
            let origin = pose_rotation(&collision.origin);
            let shift = Vector3::from(*collision.origin.xyz);
            for v in read_mesh_vertices(&path)? {
                let scaled = Vector3::new(v[0] * scale[0], v[1] * scale[1], v[2] * scale[2]);
                vertices.push(origin * scaled + shift);
            }
            meshes.push(filename.clone());
        }
        if vertices.is_empty() {
            return Err(format!(
                "foot link `{}` has no mesh collision to measure",
                leg_config.foot_link
            ));
        }
        let foot_point = Vector3::from(leg_config.foot_offset.unwrap_or([0.0; 3]));
        let q = stand[leg.index()];
        let depth_at = |pitch: f64| {
            let pitched = Rotation3::from_axis_angle(&Vector3::y_axis(), pitch);
            let rotation = pitched * model.foot_link_rotation(leg, q);
            vertices
                .iter()
                .map(|v| -(rotation * (v - foot_point))[2])
                .fold(f64::NEG_INFINITY, f64::max)
        };
        per_leg.push((leg, depth_at(0.0)));
        for k in -4..=4 {
            let depth = depth_at(STANCE_PITCH_RANGE * f64::from(k) / 4.0);
            stance_range = (stance_range.0.min(depth), stance_range.1.max(depth));
        }
    }
    meshes.dedup();
    let radius = per_leg.iter().map(|(_, d)| *d).fold(f64::MIN, f64::max);
    if !(radius.is_finite() && radius > 0.0) {
        return Err(format!(
            "the foot meshes reach {:.4} m below the foot point: the foot point is not inside the foot (check `foot_offset`)",
            radius
        ));
    }
    Ok(FootMeshRadius {
        radius,
        per_leg,
        stance_range,
        meshes,
    })
}

fn pose_rotation(pose: &urdf_rs::Pose) -> Matrix3<f64> {
    *Rotation3::from_euler_angles(pose.rpy[0], pose.rpy[1], pose.rpy[2]).matrix()
}

/// Every vertex of an STL or OBJ mesh, in the mesh's own units and frame.
fn read_mesh_vertices(path: &Path) -> Result<Vec<[f64; 3]>, String> {
    let shown = path.display();
    let size = std::fs::metadata(path)
        .map_err(|e| format!("cannot read {shown}: {e}"))?
        .len();
    if size > MAX_MESH_BYTES {
        return Err(format!(
            "{shown} is {size} bytes, more than the {MAX_MESH_BYTES} a foot mesh is read up to"
        ));
    }
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let file = File::open(path).map_err(|e| format!("cannot open {shown}: {e}"))?;
    let mut reader = BufReader::new(file);
    match extension.as_str() {
        "stl" => {
            let triangles = stl_io::create_stl_reader(&mut reader)
                .map_err(|e| format!("{shown} is not a readable STL: {e}"))?;
            let mut vertices = Vec::new();
            for (count, triangle) in triangles.enumerate() {
                if count >= MAX_TRIANGLES {
                    return Err(format!(
                        "{shown} has more than {MAX_TRIANGLES} triangles; a foot mesh has far fewer"
                    ));
                }
                let triangle =
                    triangle.map_err(|e| format!("{shown} is not a readable STL: {e}"))?;
                vertices.extend(
                    triangle
                        .vertices
                        .iter()
                        .map(|v| v.0.map(f64::from)),
                );
            }
            Ok(vertices)
        }
        "obj" => {
            let (models, _materials) = tobj::load_obj_buf(
                &mut reader,
                &tobj::LoadOptions::default(),
                |_| Err(tobj::LoadError::OpenFileFailed),
            )
            .map_err(|e| format!("{shown} is not a readable OBJ: {e}"))?;
            Ok(models
                .iter()
                .flat_map(|m| m.mesh.positions.chunks_exact(3))
                .map(|p| [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])])
                .collect())
        }
        other => Err(format!(
            "{shown}: cannot read `.{other}` meshes (STL and OBJ only); measure the sole's depth below the foot point by hand"
        )),
    }
}
