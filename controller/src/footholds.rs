//! Footholds stage: where the feet land (Raibert heuristic at the terrain height, moved off edges
//! and steep spots with a height map), the ground the base stands over, the swing apex that clears
//! the terrain and the friction normal under the stance feet. Owns the local height map.
//!
//! With a local [`HeightMap`] the reference's terrain plane is only the fallback: footholds take
//! the map's height and are moved (by at most `FOOTHOLD_SEARCH_RADIUS`) off edges, wall feet and
//! pit rims onto locally flat ground; the swing apex is raised to clear the terrain between
//! lift-off and touchdown; the base height and pitch references follow the ground under the four
//! nominal footholds. A single plane fitted around the reference point is badly wrong beside a
//! wall, a pit or a valley side: footholds at its height land early, late or on a rim, which is
//! what made the robot fall on the scenario maps.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::api::{HeightMap, Leg, Reference, GRAVITY, NUM_LEGS};
use crate::config::ControllerConfig;
use crate::estimate::Estimate;
use crate::gait::{swing_blend, swing_bump_shape};
use crate::math::rot_z;

/// Largest distance a foothold is moved from its Raibert position to find flat ground, m.
pub const FOOTHOLD_SEARCH_RADIUS: f64 = 0.2;
/// Candidates per ring of the foothold search (ring k at radius k/(len − 1) of the search radius).
const FOOTHOLD_RINGS: [usize; 6] = [1, 8, 12, 16, 16, 20];
/// Distance at which the foothold search probes the height around a candidate, m.
const EDGE_PROBE: f64 = 0.05;
const EDGE_DIAGONAL: f64 = EDGE_PROBE * std::f64::consts::FRAC_1_SQRT_2;
/// The probe offsets around a foothold candidate (8 directions).
const EDGE_PROBES: [(f64, f64); 8] = [
    (EDGE_PROBE, 0.0),
    (-EDGE_PROBE, 0.0),
    (0.0, EDGE_PROBE),
    (0.0, -EDGE_PROBE),
    (EDGE_DIAGONAL, EDGE_DIAGONAL),
    (EDGE_DIAGONAL, -EDGE_DIAGONAL),
    (-EDGE_DIAGONAL, EDGE_DIAGONAL),
    (-EDGE_DIAGONAL, -EDGE_DIAGONAL),
];
/// Cost of one metre of height change around a candidate, in metres of foothold displacement.
const EDGE_WEIGHT: f64 = 2.0;
/// Steepest local slope (rise over run within `EDGE_PROBE`) a foothold may have without extra
/// cost: about half the friction cone of the feet (μ ≈ 0.8 in simulation).
const STEEP_SLOPE: f64 = 0.6;
/// Cost per unit of local slope beyond `STEEP_SLOPE`, in metres of foothold displacement: a foot
/// on a slope steeper than its friction cone slides down it.
const STEEP_WEIGHT: f64 = 0.5;
/// Clearance the swing foot keeps above the terrain between lift-off and touchdown, m.
const SWING_TERRAIN_MARGIN: f64 = 0.06;
/// Highest swing apex (above the lift-off/touchdown line) the clearance logic may ask for, m.
const MAX_SWING_HEIGHT: f64 = 0.2;
/// Largest Raibert offset of a foothold from under its hip (per horizontal axis), m: beyond it a
/// velocity error would put the foot outside the leg's workspace.
const MAX_RAIBERT_OFFSET: f64 = 0.15;
/// Front-to-rear distance of the nominal feet below which the pitch reference comes from the
/// terrain plane instead of the footholds, m.
const MIN_FRONT_REAR_LENGTH: f64 = 1e-6;
/// Norm below which the sum of the stance feet's normals counts as "no map normal".
const MIN_NORMAL_SUM: f64 = 1e-9;
/// Progress points (tenths of the swing, ends excluded: the foot is on the ground there) at which
/// the swing apex is checked against the terrain.
const SWING_CLEARANCE_SAMPLES: std::ops::RangeInclusive<u32> = 2..=8;

/// Base motion the MPC should follow.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct MotionTarget {
    /// Base xy, world frame, m.
    pub xy: [f64; 2],
    /// Roll, rad.
    pub roll: f64,
    /// Yaw, rad.
    pub yaw: f64,
    /// Velocity xy, world frame, m/s.
    pub velocity: [f64; 2],
    /// Velocity the footholds' feedback steers the body to, world xy, m/s: `velocity`, except
    /// while a push is taken out ([`crate::reference_governor`]), when `velocity` starts at the
    /// pushed body's and this is the given reference's.
    pub foothold_velocity: [f64; 2],
    /// Yaw rate, rad/s.
    pub yaw_rate: f64,
}

/// Where the base should stand relative to the ground its feet will use.
#[derive(Clone, Copy, Debug)]
pub struct StanceGround {
    /// Mean terrain height under the footholds, m.
    pub height: f64,
    /// Pitch reference, rad.
    pub pitch: f64,
    /// Mean displacement of the footholds from their nominal positions, world xy, m.
    pub shift: [f64; 2],
}

/// Offset of one foothold search candidate from the nominal foothold.
#[derive(Clone, Copy, Debug)]
struct FootholdCandidate {
    ring: f64,
    dx: f64,
    dy: f64,
}

fn foothold_candidates() -> Vec<FootholdCandidate> {
    let last_ring = (FOOTHOLD_RINGS.len() - 1) as f64;
    FOOTHOLD_RINGS
        .iter()
        .enumerate()
        .flat_map(|(k, &count)| {
            let ring = FOOTHOLD_SEARCH_RADIUS * k as f64 / last_ring;
            (0..count).map(move |i| {
                let angle = std::f64::consts::TAU * i as f64 / count as f64;
                FootholdCandidate {
                    ring,
                    dx: ring * angle.cos(),
                    dy: ring * angle.sin(),
                }
            })
        })
        .collect()
}

/// Height of the reference's terrain plane at (x, y).
pub fn terrain_height(reference: &Reference, x: f64, y: f64) -> f64 {
    let t = &reference.terrain;
    t.height + t.slope_x * (x - reference.x) + t.slope_y * (y - reference.y)
}

/// Unit normal of the reference's terrain plane.
pub fn terrain_normal(reference: &Reference) -> Vector3<f64> {
    Vector3::new(-reference.terrain.slope_x, -reference.terrain.slope_y, 1.0).normalize()
}

/// The foothold planner and the terrain knowledge behind it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FootholdPlanner {
    /// Nominal foot position under each hip, base frame (xy used for footholds).
    nominal_feet_body: [Vector3<f64>; NUM_LEGS],
    foot_radius: f64,
    /// Nominal base height above the terrain, m (when the reference gives ≤ 0).
    body_height: f64,
    swing_height: f64,
    raibert_gain: f64,
    max_terrain_pitch: f64,
    height_map: HeightMap,
    /// Foothold search candidates, ring by ring (nearest first).
    #[serde(skip, default = "foothold_candidates")]
    foothold_candidates: Vec<FootholdCandidate>,
}

impl FootholdPlanner {
    /// A planner for feet at `nominal_feet_body` (base frame) of radius `foot_radius`, m.
    pub fn new(
        config: &ControllerConfig,
        nominal_feet_body: [Vector3<f64>; NUM_LEGS],
        foot_radius: f64,
    ) -> Self {
        FootholdPlanner {
            nominal_feet_body,
            foot_radius,
            body_height: config.body_height,
            swing_height: config.swing_height,
            raibert_gain: config.raibert_gain,
            max_terrain_pitch: config.max_terrain_pitch,
            height_map: HeightMap::default(),
            foothold_candidates: foothold_candidates(),
        }
    }

    /// Replaces the height map (validated by the caller).
    pub fn set_height_map(&mut self, map: &HeightMap) {
        self.height_map = *map;
    }

    /// The height map in use.
    pub fn height_map(&self) -> &HeightMap {
        &self.height_map
    }

    /// Raibert foothold with velocity feedback and the centrifugal term, at terrain height:
    /// `p = p_hip(t_td) + v T_st/2 + k (v − v_ref) + (z/2g) v × ω_ref`.
    pub fn raibert_foothold(
        &self,
        estimate: &Estimate,
        reference: &Reference,
        target: &MotionTarget,
        leg: Leg,
        time_to_touchdown: f64,
        stance_time: f64,
    ) -> Vector3<f64> {
        let yaw = estimate.rpy.z + target.yaw_rate * (time_to_touchdown + 0.5 * stance_time);
        let hip = rot_z(yaw) * self.nominal_feet_body[leg.index()];
        let v = estimate.velocity;
        let v_ref = Vector3::new(target.velocity[0], target.velocity[1], 0.0);
        let v_steer = Vector3::new(
            target.foothold_velocity[0],
            target.foothold_velocity[1],
            0.0,
        );
        let base_at_touchdown = estimate.position + v_ref * time_to_touchdown;
        let height = self.body_height(reference);
        let centrifugal = height / (2.0 * GRAVITY);
        let mut offset = v * (0.5 * stance_time) + (v - v_steer) * self.raibert_gain;
        offset.x += centrifugal * v.y * target.yaw_rate;
        offset.y -= centrifugal * v.x * target.yaw_rate;
        offset.x = offset.x.clamp(-MAX_RAIBERT_OFFSET, MAX_RAIBERT_OFFSET);
        offset.y = offset.y.clamp(-MAX_RAIBERT_OFFSET, MAX_RAIBERT_OFFSET);
        let x = base_at_touchdown.x + hip.x + offset.x;
        let y = base_at_touchdown.y + hip.y + offset.y;
        self.select_foothold(reference, x, y)
    }

    /// Terrain height at (x, y): the height map where it covers the point, else the plane.
    pub fn ground(&self, reference: &Reference, x: f64, y: f64) -> f64 {
        self.height_map
            .height(x, y)
            .unwrap_or_else(|| terrain_height(reference, x, y))
    }

    /// Cost of a foothold candidate at (cx, cy), `ring` metres from the nominal foothold:
    /// `ring + EDGE_WEIGHT·edge + STEEP_WEIGHT·(edge/EDGE_PROBE − STEEP_SLOPE)⁺`, where `edge` is
    /// the largest height change within `EDGE_PROBE` (8 directions). `None` when a probe leaves
    /// the map, or as soon as the cost reaches `reject_at`: the cost only grows with `edge`, so
    /// the remaining probes cannot make the candidate win.
    fn foothold_cost(&self, ring: f64, cx: f64, cy: f64, reject_at: f64) -> Option<f64> {
        let map = &self.height_map;
        let cost_of = |edge: f64| {
            let steep = (edge / EDGE_PROBE - STEEP_SLOPE).max(0.0);
            ring + EDGE_WEIGHT * edge + STEEP_WEIGHT * steep
        };
        let centre = map.height(cx, cy)?;
        let mut edge: f64 = 0.0;
        for (dx, dy) in EDGE_PROBES {
            edge = edge.max((map.height(cx + dx, cy + dy)? - centre).abs());
            if cost_of(edge) >= reject_at {
                return None;
            }
        }
        Some(cost_of(edge))
    }

    /// Foot (sphere centre) target near the nominal foothold (x, y): with a height map, the
    /// candidate within `FOOTHOLD_SEARCH_RADIUS` minimising displacement + `EDGE_WEIGHT`·edge +
    /// `STEEP_WEIGHT`·(slope − `STEEP_SLOPE`)⁺
    /// (rings of `FOOTHOLD_RINGS` candidates; ties keep the earlier, nearer one), at the map's
    /// height; without one, (x, y) at the plane's height.
    ///
    /// The search runs ring by ring and stops at the first ring whose displacement alone
    /// already costs as much as the best candidate (on even ground: after the first one); this
    /// is what keeps the search cheap enough for every tick and every MPC horizon step.
    pub fn select_foothold(&self, reference: &Reference, x: f64, y: f64) -> Vector3<f64> {
        let radius = self.foot_radius;
        let mut best: Option<(f64, f64, f64)> = None;
        if self.height_map.is_present() {
            for candidate in &self.foothold_candidates {
                // A candidate replaces the best only when cheaper by more than 1e-9.
                let reject_at = best.map_or(f64::INFINITY, |(c, _, _)| c - 1e-9);
                if candidate.ring >= reject_at {
                    break; // rings only grow from here on
                }
                let (cx, cy) = (x + candidate.dx, y + candidate.dy);
                if let Some(cost) = self.foothold_cost(candidate.ring, cx, cy, reject_at) {
                    best = Some((cost, cx, cy));
                }
            }
        }
        let (fx, fy) = best.map_or((x, y), |(_, bx, by)| (bx, by));
        Vector3::new(fx, fy, self.ground(reference, fx, fy) + radius)
    }

    /// Swing apex height (above the straight lift-off → touchdown line) that keeps the foot
    /// `SWING_TERRAIN_MARGIN` above the terrain along the way: at least `swing_height`, at most
    /// `MAX_SWING_HEIGHT`.
    pub fn swing_apex(
        &self,
        reference: &Reference,
        start: &Vector3<f64>,
        end: &Vector3<f64>,
    ) -> f64 {
        self.apex_above(reference, start, end, self.swing_height)
    }

    /// Apex of a swing cut short by a push (`start` is where the foot is in the air): no bump of
    /// its own, only what keeps the foot `SWING_TERRAIN_MARGIN` above the terrain.
    pub fn landing_apex(
        &self,
        reference: &Reference,
        start: &Vector3<f64>,
        end: &Vector3<f64>,
    ) -> f64 {
        self.apex_above(reference, start, end, 0.0)
    }

    fn apex_above(
        &self,
        reference: &Reference,
        start: &Vector3<f64>,
        end: &Vector3<f64>,
        nominal: f64,
    ) -> f64 {
        if !self.height_map.is_present() {
            return nominal;
        }
        // The bump is h·swing_bump_shape(s): ask for `SWING_TERRAIN_MARGIN` of it above the
        // terrain's rise over the lift-off → touchdown line, on the middle of the swing only (at
        // the ends the foot is on the ground by construction).
        let radius = self.foot_radius;
        let mut apex = nominal;
        for i in SWING_CLEARANCE_SAMPLES {
            let s = 0.1 * f64::from(i);
            let p = start + (end - start) * swing_blend(s);
            let rise = self.ground(reference, p.x, p.y) + radius - p.z;
            if rise > 0.0 {
                apex = apex.max(SWING_TERRAIN_MARGIN + rise / swing_bump_shape(s));
            }
        }
        apex.min(MAX_SWING_HEIGHT.max(nominal))
    }

    /// Ground height, pitch and xy shift reference for a base at (x, y) facing `yaw`: the mean
    /// terrain height, the front/rear slope and the mean displacement of the (edge-avoiding)
    /// nominal footholds under the hips with a height map; the plane and no shift otherwise.
    pub fn stance_ground(&self, reference: &Reference, x: f64, y: f64, yaw: f64) -> StanceGround {
        let plane_pitch = self.terrain_pitch(reference, yaw);
        if !self.height_map.is_present() {
            return StanceGround {
                height: terrain_height(reference, x, y),
                pitch: plane_pitch,
                shift: [0.0; 2],
            };
        }
        let rotation = rot_z(yaw);
        let mut heights = [0.0; NUM_LEGS];
        let mut shift = [0.0; 2];
        for leg in Leg::ALL {
            let hip = rotation * self.nominal_feet_body[leg.index()];
            let foot = self.select_foothold(reference, x + hip.x, y + hip.y);
            heights[leg.index()] = foot.z - self.foot_radius;
            shift[0] += (foot.x - x - hip.x) / NUM_LEGS as f64;
            shift[1] += (foot.y - y - hip.y) / NUM_LEGS as f64;
        }
        let mean = heights.iter().sum::<f64>() / NUM_LEGS as f64;
        let front = 0.5 * (heights[Leg::FR.index()] + heights[Leg::FL.index()]);
        let rear = 0.5 * (heights[Leg::RR.index()] + heights[Leg::RL.index()]);
        let length =
            self.nominal_feet_body[Leg::FR.index()].x - self.nominal_feet_body[Leg::RR.index()].x;
        let limit = self.max_terrain_pitch;
        let pitch = if length > MIN_FRONT_REAR_LENGTH {
            (-((front - rear) / length).atan()).clamp(-limit, limit)
        } else {
            plane_pitch
        };
        StanceGround {
            height: mean,
            pitch,
            shift,
        }
    }

    pub fn body_height(&self, reference: &Reference) -> f64 {
        if reference.body_height > 0.0 {
            reference.body_height
        } else {
            self.body_height
        }
    }

    fn terrain_pitch(&self, reference: &Reference, yaw: f64) -> f64 {
        let slope = reference.terrain.slope_x * yaw.cos() + reference.terrain.slope_y * yaw.sin();
        let limit = self.max_terrain_pitch;
        (-slope.atan()).clamp(-limit, limit)
    }

    /// Normal of the MPC's friction pyramids: with a height map, the mean of the local terrain
    /// normals under the stance feet (a plane fitted around the base tilts by tens of degrees
    /// beside a valley side or a wall while the feet stand on flat ground), else the plane's.
    pub fn friction_normal(
        &self,
        reference: &Reference,
        estimate: &Estimate,
        contacts: [bool; NUM_LEGS],
    ) -> Vector3<f64> {
        let map = &self.height_map;
        let d = EDGE_PROBE;
        let mut sum = Vector3::zeros();
        for leg in Leg::ALL {
            let l = leg.index();
            if !contacts[l] {
                continue;
            }
            let p = estimate.feet_world[l];
            let samples = (
                map.height(p.x + d, p.y),
                map.height(p.x - d, p.y),
                map.height(p.x, p.y + d),
                map.height(p.x, p.y - d),
            );
            if let (Some(xp), Some(xm), Some(yp), Some(ym)) = samples {
                sum +=
                    Vector3::new(-(xp - xm) / (2.0 * d), -(yp - ym) / (2.0 * d), 1.0).normalize();
            }
        }
        if sum.norm() > MIN_NORMAL_SUM {
            sum.normalize()
        } else {
            terrain_normal(reference)
        }
    }
}

#[cfg(test)]
mod tests;
