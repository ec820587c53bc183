//! Validation and conversion between the wire messages (`lcm_types::pfnav`) and the planner's
//! types. Every rule of `lcm_types/*.lcm` that the service enforces lives here; each violation
//! becomes a [`Rejection`] carrying the reply status and a human-readable reason.

use std::sync::Arc;

use lcm_types::pfnav::{PlanOptions, PlanReply, PlanRequest, TerrainMap};
use pf_planner::basis::{BasisKind, RbfGenerators};
use pf_planner::generators::MAX_ANSDMD_FUNCTIONS;
use pf_planner::grid::GoalRegion;
use pf_planner::lp::LpSolver;
use pf_planner::map::{GridMap, MapKnowledge, Point};
use pf_planner::pf::StartDensity;
use pf_planner::plan::Method;
use pf_planner::trajectory::{MAX_SAMPLES, MAX_SPEED};
use pf_planner::traversability::TraversabilityParams;

/// Why a message is not planned: the reply status (`PlanReply::STATUS_*`) and the reason.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rejection {
    pub status: i8,
    pub reason: String,
}

impl Rejection {
    pub fn new(status: i8, reason: impl Into<String>) -> Self {
        Self {
            status,
            reason: reason.into(),
        }
    }
    fn invalid_request(reason: impl Into<String>) -> Self {
        Self::new(PlanReply::STATUS_INVALID_REQUEST, reason)
    }
    fn invalid_map(reason: impl Into<String>) -> Self {
        Self::new(PlanReply::STATUS_INVALID_MAP, reason)
    }
}

/// Accepted values of the frame name of every message: the world frame.
fn check_frame(frame_id: &str, what: &str) -> Result<(), String> {
    if frame_id.is_empty() || frame_id == "world" {
        Ok(())
    } else {
        Err(format!(
            "{what} frame_id {frame_id:?} is not supported (only \"world\" or empty)"
        ))
    }
}

/// Checks a map's size claims against the service's cell limit. Runs on the claims read before
/// decoding (see [`crate::preflight`]) and again on the decoded message.
pub fn check_map_size(
    width: i32,
    height: i32,
    num_cells: i32,
    max_cells: usize,
) -> Result<(), Rejection> {
    if width <= 0 || height <= 0 {
        return Err(Rejection::invalid_map(format!(
            "map width and height must be > 0, got {width} x {height}"
        )));
    }
    let cells = i64::from(width) * i64::from(height);
    let claimed = cells.max(i64::from(num_cells));
    if usize::try_from(claimed).map_or(true, |c| c > max_cells) {
        return Err(Rejection::new(
            PlanReply::STATUS_MAP_TOO_LARGE,
            format!(
                "map of {width} x {height} cells ({claimed} claimed) exceeds the service limit of {max_cells} cells (--max-map-cells)"
            ),
        ));
    }
    if i64::from(num_cells) != cells {
        return Err(Rejection::invalid_map(format!(
            "num_cells is {num_cells}, expected width x height = {cells}"
        )));
    }
    Ok(())
}

/// p of unknown cells when `terrain_map_t.unknown_traversability` is 0.
pub const DEFAULT_UNKNOWN_TRAVERSABILITY: f64 = 0.5;

/// A map as received: the terrain and, for a partially observed one, which cells were seen
/// (obstacle flags of unknown cells already dropped: an unseen cell is never an obstacle).
#[derive(Debug, Clone, PartialEq)]
pub struct ReceivedMap {
    pub map: GridMap,
    /// `None`: every cell known (`num_known_cells` = 0).
    pub knowledge: Option<MapKnowledge>,
}

impl ReceivedMap {
    /// A fully known map.
    pub fn known(map: GridMap) -> Self {
        Self {
            map,
            knowledge: None,
        }
    }
}

/// The wire form of a fully known planner map (the inverse of [`map_from_message`]),
/// `header.seq = seq`.
pub fn map_to_message(map: &GridMap, seq: i64) -> TerrainMap {
    partial_map_to_message(map, None, seq)
}

/// The wire form of a planner map with its knowledge (`None`: every cell known),
/// `header.seq = seq`. Sizes that do not fit the wire's `int32_t` saturate (such a map is
/// refused on receipt).
pub fn partial_map_to_message(
    map: &GridMap,
    knowledge: Option<&MapKnowledge>,
    seq: i64,
) -> TerrainMap {
    let obstacles = map.obstacles.clone().unwrap_or_default();
    let known = knowledge.map_or_else(Vec::new, |k| k.known().to_vec());
    let variances = knowledge
        .and_then(MapKnowledge::height_variances)
        .map_or_else(Vec::new, <[f64]>::to_vec);
    let int = |n: usize| i32::try_from(n).unwrap_or(i32::MAX);
    TerrainMap {
        header: lcm_types::pfnav::Header {
            utime: 0,
            seq,
            frame_id: "world".into(),
        },
        origin_x: map.origin[0],
        origin_y: map.origin[1],
        resolution: map.resolution,
        width: int(map.width),
        height: int(map.height),
        num_cells: int(map.heights.len()),
        heights: map.heights.clone(),
        num_obstacle_cells: int(obstacles.len()),
        obstacle_mask: obstacles,
        num_known_cells: int(known.len()),
        known_mask: known,
        unknown_traversability: knowledge.map_or(0.0, MapKnowledge::unknown_traversability),
        num_variance_cells: int(variances.len()),
        height_variances: variances,
    }
}

/// Turns a decoded `terrain_map_t` into a validated map: sizes, frame, heights, obstacle mask,
/// known mask (0 or width × height entries), `unknown_traversability` (0 = default, else
/// finite in (0, 1]) and the height variances (0 or width × height entries, each finite in
/// 0 ..= 100 m²; a fully known map with variances gets a knowledge of all cells known).
pub fn map_from_message(msg: &TerrainMap, max_cells: usize) -> Result<ReceivedMap, Rejection> {
    check_map_size(msg.width, msg.height, msg.num_cells, max_cells)?;
    check_frame(&msg.header.frame_id, "map").map_err(Rejection::invalid_map)?;
    let cells = msg.heights.len();
    let obstacles = match msg.obstacle_mask.len() {
        0 => None,
        n if n == cells => Some(msg.obstacle_mask.clone()),
        n => {
            return Err(Rejection::invalid_map(format!(
                "obstacle_mask has {n} entries, expected 0 or width x height = {cells}"
            )))
        }
    };
    let known_entries = msg.known_mask.len();
    if known_entries != 0 && known_entries != cells {
        return Err(Rejection::invalid_map(format!(
            "known_mask has {known_entries} entries, expected 0 (every cell known) or width x height = {cells}"
        )));
    }
    let prior = match msg.unknown_traversability {
        0.0 => DEFAULT_UNKNOWN_TRAVERSABILITY,
        p if p.is_finite() && p > 0.0 && p <= 1.0 => p,
        p => {
            return Err(Rejection::invalid_map(format!(
                "unknown_traversability must be 0 (default {DEFAULT_UNKNOWN_TRAVERSABILITY}) or finite in (0, 1], got {p}"
            )))
        }
    };
    let width = usize::try_from(msg.width).map_err(|_| Rejection::invalid_map("negative width"))?;
    let height =
        usize::try_from(msg.height).map_err(|_| Rejection::invalid_map("negative height"))?;
    let mut map = GridMap::new(
        [msg.origin_x, msg.origin_y],
        msg.resolution,
        width,
        height,
        msg.heights.clone(),
        obstacles,
    )
    .map_err(|e| Rejection::invalid_map(e.to_string()))?;
    let variance_entries = msg.height_variances.len();
    if variance_entries != 0 && variance_entries != cells {
        return Err(Rejection::invalid_map(format!(
            "height_variances has {variance_entries} entries, expected 0 (heights exact) or width x height = {cells}"
        )));
    }
    let knowledge = if known_entries == 0 && variance_entries == 0 {
        None
    } else {
        let known = if known_entries == 0 {
            vec![true; cells]
        } else {
            msg.known_mask.clone()
        };
        let mut knowledge = MapKnowledge::new(&map, known, prior)
            .map_err(|e| Rejection::invalid_map(e.to_string()))?;
        if variance_entries != 0 {
            knowledge = knowledge
                .with_height_variances(&map, &msg.height_variances)
                .map_err(|e| Rejection::invalid_map(e.to_string()))?;
        }
        knowledge.clear_unknown_obstacles(&mut map);
        Some(knowledge)
    };
    Ok(ReceivedMap { map, knowledge })
}

/// Defaults the service applies to `plan_options_t` fields left at 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OptionDefaults {
    /// RBF lattice size when `grid_size` is 0 and the basis is RBF.
    pub rbf_grid_size: usize,
    pub directions: usize,
    pub speed: f64,
    pub sample_period: f64,
    /// Solve-time limit, seconds (`f64::INFINITY` for none).
    pub max_solve_time: f64,
}

impl Default for OptionDefaults {
    fn default() -> Self {
        Self {
            rbf_grid_size: 32,
            directions: 8,
            speed: 0.5,
            sample_period: 0.1,
            max_solve_time: 30.0,
        }
    }
}

/// Smallest and largest accepted `grid_size`.
pub const GRID_SIZE_RANGE: std::ops::RangeInclusive<usize> = 2..=512;

/// Planner settings after defaults were applied and ranges checked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResolvedOptions {
    pub basis: BasisKind,
    /// Planning cells along the longer map side.
    pub grid_size: usize,
    pub directions: usize,
    pub speed: f64,
    pub start_density: StartDensity,
    pub sample_period: f64,
    pub max_solve_time: f64,
    pub solver: LpSolver,
    /// κ of the start-uncertainty margin (standard deviations).
    pub confidence_sigmas: f64,
}

/// κ when `options.confidence_sigmas` is 0: a Gaussian belief's true position lies outside
/// κσ with probability exp(−κ²/2) = 13.5 %.
pub const DEFAULT_CONFIDENCE_SIGMAS: f64 = 2.0;
/// Largest accepted κ (exp(−κ²/2) = 4·10⁻⁶: beyond, the margin only blocks the map).
pub const MAX_CONFIDENCE_SIGMAS: f64 = 5.0;
/// Largest accepted `start_sigma`, metres.
pub const MAX_START_SIGMA: f64 = 10.0;

/// Largest number of basis functions (grid_size²) for which Clarabel may be requested: its
/// interior-point iterations grow with the grid (128²: 2–4 s, 256²: minutes), so larger grids
/// could not honour the time limit; the exact solver has no such limit.
pub const MAX_CLARABEL_FUNCTIONS: usize = 128 * 128;

fn positive_or_default(value: f64, default: f64, name: &str) -> Result<f64, Rejection> {
    if value == 0.0 {
        Ok(default)
    } else if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(Rejection::invalid_request(format!(
            "options.{name} must be 0 (default) or finite and > 0, got {value}"
        )))
    }
}

/// Applies the defaults of `plan_options_t` and checks every range.
pub fn resolve_options(
    options: &PlanOptions,
    map: &GridMap,
    defaults: &OptionDefaults,
) -> Result<ResolvedOptions, Rejection> {
    let generators = match options.generators {
        PlanOptions::GENERATORS_DEFAULT | PlanOptions::GENERATORS_TRANSFER => {
            RbfGenerators::Transfer
        }
        PlanOptions::GENERATORS_ANSDMD => RbfGenerators::Ansdmd,
        other => {
            return Err(Rejection::invalid_request(format!(
                "unknown options.generators {other} (0 default, 1 transfer, 2 ansdmd)"
            )))
        }
    };
    let basis = match options.basis {
        PlanOptions::BASIS_DEFAULT | PlanOptions::BASIS_INDICATOR => BasisKind::Indicator,
        PlanOptions::BASIS_RBF => match generators {
            RbfGenerators::Transfer => BasisKind::DEFAULT_RBF,
            RbfGenerators::Ansdmd => BasisKind::ANSDMD_RBF,
        },
        other => {
            return Err(Rejection::invalid_request(format!(
                "unknown options.basis {other} (0 default, 1 indicator, 2 rbf)"
            )))
        }
    };
    let grid_size = match options.grid_size {
        0 => match basis {
            BasisKind::Indicator => map.width.max(map.height).min(*GRID_SIZE_RANGE.end()),
            BasisKind::Rbf { .. } => defaults.rbf_grid_size,
        },
        n => usize::try_from(n)
            .ok()
            .filter(|n| GRID_SIZE_RANGE.contains(n))
            .ok_or_else(|| {
                Rejection::invalid_request(format!(
                    "options.grid_size must be 0 (default) or 2..=512, got {n}"
                ))
            })?,
    };
    let directions = match options.directions {
        0 => defaults.directions,
        4 => 4,
        8 => 8,
        other => {
            return Err(Rejection::invalid_request(format!(
                "options.directions must be 0 (default), 4 or 8, got {other}"
            )))
        }
    };
    let start_density = match options.start_density {
        PlanOptions::START_DENSITY_DEFAULT => StartDensity::default(),
        PlanOptions::START_DENSITY_POINT => StartDensity::PointMass,
        PlanOptions::START_DENSITY_UNIFORM => StartDensity::UniformFree,
        // σ comes with the request (`validate_request` fills it in).
        PlanOptions::START_DENSITY_BELIEF => StartDensity::Belief { sigma_m: 0.0 },
        other => {
            return Err(Rejection::invalid_request(format!(
                "unknown options.start_density {other} (0 default, 1 point, 2 uniform, 3 belief)"
            )))
        }
    };
    let solver = match options.solver {
        PlanOptions::SOLVER_DEFAULT | PlanOptions::SOLVER_EXACT => LpSolver::Exact,
        PlanOptions::SOLVER_CLARABEL => LpSolver::Clarabel,
        other => {
            return Err(Rejection::invalid_request(format!(
                "unknown options.solver {other} (0 default, 1 exact, 2 clarabel)"
            )))
        }
    };
    let confidence_sigmas = positive_or_default(
        options.confidence_sigmas,
        DEFAULT_CONFIDENCE_SIGMAS,
        "confidence_sigmas",
    )?;
    if confidence_sigmas > MAX_CONFIDENCE_SIGMAS {
        return Err(Rejection::invalid_request(format!(
            "options.confidence_sigmas must be <= {MAX_CONFIDENCE_SIGMAS}, got {confidence_sigmas}"
        )));
    }
    if generators == RbfGenerators::Ansdmd
        && matches!(basis, BasisKind::Rbf { .. })
        && grid_size * grid_size > MAX_ANSDMD_FUNCTIONS
    {
        // Refused before any work: its dense least squares is what the limit bounds.
        return Err(Rejection::invalid_request(format!(
            "options.generators = ansdmd is limited to {MAX_ANSDMD_FUNCTIONS} RBF functions (grid_size <= 64), got grid_size {grid_size}; use the transfer generators"
        )));
    }
    if solver == LpSolver::Clarabel && grid_size * grid_size > MAX_CLARABEL_FUNCTIONS {
        return Err(Rejection::invalid_request(format!(
            "options.solver = clarabel is limited to {MAX_CLARABEL_FUNCTIONS} basis functions (grid_size <= 128), got grid_size {grid_size}; use the exact solver"
        )));
    }
    let speed = positive_or_default(options.speed, defaults.speed, "speed")?;
    if speed > MAX_SPEED {
        return Err(Rejection::invalid_request(format!(
            "options.speed must be <= {MAX_SPEED} m/s, got {speed}"
        )));
    }
    Ok(ResolvedOptions {
        confidence_sigmas,
        solver,
        basis,
        grid_size,
        directions,
        speed,
        start_density,
        sample_period: positive_or_default(
            options.sample_period,
            defaults.sample_period,
            "sample_period",
        )?,
        max_solve_time: positive_or_default(
            options.max_solve_time,
            defaults.max_solve_time,
            "max_solve_time",
        )?,
    })
}

/// A request that passed every check the service can make without planning.
#[derive(Debug, Clone)]
pub struct ValidatedRequest {
    pub request_id: i64,
    /// The method code as sent (echoed in the reply).
    pub method_code: i8,
    pub method: Method,
    pub map: Arc<ReceivedMap>,
    /// `header.seq` of the map planned on.
    pub map_seq: i64,
    pub start: Point,
    pub start_yaw: f64,
    pub goal: GoalRegion,
    pub options: ResolvedOptions,
    /// Standard deviation of the start position, metres (0: exact).
    pub start_sigma: f64,
}

impl ValidatedRequest {
    /// The service's cost model with the footprint widened by κ·σ of the start: a path point
    /// then costs the worst p within the robot's reach for every true position within κσ of
    /// the believed one, which holds with probability 1 − exp(−κ²/2) for a Gaussian belief.
    /// The same κ sets the confidence bounds of a map's heights where it carries variances.
    pub fn traversability(&self, service: &TraversabilityParams) -> TraversabilityParams {
        TraversabilityParams {
            footprint_radius_m: service.footprint_radius_m
                + self.options.confidence_sigmas * self.start_sigma,
            height_confidence_sigmas: self.options.confidence_sigmas,
            ..*service
        }
    }
}

/// Where a request's map comes from when it is not inline.
pub trait MapSource {
    /// The stored map with `header.seq == seq`, or the latest one for `seq == -1`, with its seq.
    fn map_by_seq(&self, seq: i64) -> Option<(i64, Arc<ReceivedMap>)>;
}

/// The wire code (`plan_request_t.METHOD_*`) of every planning method: the one table between the
/// schema's constants and [`Method`] (a test checks it covers [`Method::ALL`] once each).
pub const METHOD_CODES: [(i8, Method); 4] = [
    (PlanRequest::METHOD_PF, Method::Pf),
    (PlanRequest::METHOD_ASTAR, Method::AStar),
    (PlanRequest::METHOD_DIJKSTRA, Method::Dijkstra),
    (
        PlanRequest::METHOD_ASTAR_ADMISSIBLE,
        Method::AStarAdmissible,
    ),
];

/// The method of a wire code, `None` for a code the schema does not define.
pub fn method_of_code(code: i8) -> Option<Method> {
    METHOD_CODES
        .iter()
        .find(|(known, _)| *known == code)
        .map(|&(_, method)| method)
}

/// Checks a decoded request field by field and resolves its map.
pub fn validate_request(
    msg: &PlanRequest,
    maps: &dyn MapSource,
    max_cells: usize,
    defaults: &OptionDefaults,
) -> Result<ValidatedRequest, Rejection> {
    if msg.request_id <= 0 {
        return Err(Rejection::invalid_request(format!(
            "request_id must be > 0, got {}",
            msg.request_id
        )));
    }
    check_frame(&msg.header.frame_id, "request").map_err(Rejection::invalid_request)?;
    let method = method_of_code(msg.method).ok_or_else(|| {
        let known: Vec<String> = METHOD_CODES
            .iter()
            .map(|(code, method)| format!("{code} {method}"))
            .collect();
        Rejection::invalid_request(format!(
            "unknown method {} ({})",
            msg.method,
            known.join(", ")
        ))
    })?;
    for (name, value) in [
        ("start_x", msg.start_x),
        ("start_y", msg.start_y),
        ("start_yaw", msg.start_yaw),
        ("goal_x", msg.goal_x),
        ("goal_y", msg.goal_y),
    ] {
        if !value.is_finite() {
            return Err(Rejection::invalid_request(format!(
                "{name} must be finite, got {value}"
            )));
        }
    }
    if !(msg.start_sigma.is_finite() && (0.0..=MAX_START_SIGMA).contains(&msg.start_sigma)) {
        return Err(Rejection::invalid_request(format!(
            "start_sigma must be finite in 0 ..= {MAX_START_SIGMA} m, got {}",
            msg.start_sigma
        )));
    }
    if !(msg.goal_radius.is_finite() && msg.goal_radius > 0.0) {
        return Err(Rejection::invalid_request(format!(
            "goal_radius must be finite and > 0, got {}",
            msg.goal_radius
        )));
    }
    let (map_seq, map) = match (msg.num_inline_maps, msg.inline_map.as_slice()) {
        (1, [inline]) => (inline.header.seq, Arc::new(map_from_message(inline, max_cells)?)),
        (0, []) => maps.map_by_seq(msg.map_seq).ok_or_else(|| {
            Rejection::invalid_map(if msg.map_seq == -1 {
                "no inline map and the service has not received any map yet".to_owned()
            } else {
                format!(
                    "no inline map and the service holds no map with seq {} (it keeps the most recent ones)",
                    msg.map_seq
                )
            })
        })?,
        (n, _) => {
            return Err(Rejection::invalid_request(format!(
                "num_inline_maps must be 0 or 1, got {n}"
            )))
        }
    };
    let mut options = resolve_options(&msg.options, &map.map, defaults)?;
    if let StartDensity::Belief { sigma_m } = &mut options.start_density {
        *sigma_m = msg.start_sigma;
    }
    // Every path from start to goal is at least the straight line minus the goal radius long: a
    // reference sampled that finely would exceed the sample cap whatever the planner finds, so
    // the request is refused before any work.
    let shortest =
        ((msg.goal_x - msg.start_x).hypot(msg.goal_y - msg.start_y) - msg.goal_radius).max(0.0);
    let least_samples = shortest / (options.speed * options.sample_period);
    if least_samples > MAX_SAMPLES as f64 {
        return Err(Rejection::invalid_request(format!(
            "the reference would need at least {least_samples:.3e} samples ({shortest:.1} m at {} m/s, one every {} s), more than the limit of {MAX_SAMPLES}; raise speed or sample_period",
            options.speed, options.sample_period
        )));
    }
    Ok(ValidatedRequest {
        request_id: msg.request_id,
        method_code: msg.method,
        method,
        map,
        map_seq,
        start: [msg.start_x, msg.start_y],
        start_yaw: msg.start_yaw,
        goal: GoalRegion {
            center: [msg.goal_x, msg.goal_y],
            radius: msg.goal_radius,
        },
        options,
        start_sigma: msg.start_sigma,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use lcm_types::pfnav::Header;

    struct NoMaps;
    impl MapSource for NoMaps {
        fn map_by_seq(&self, _: i64) -> Option<(i64, Arc<ReceivedMap>)> {
            None
        }
    }

    fn map_msg(width: i32, height: i32) -> TerrainMap {
        let n = (width * height) as usize;
        TerrainMap {
            header: Header {
                utime: 0,
                seq: 3,
                frame_id: "world".into(),
            },
            origin_x: -1.0,
            origin_y: 2.0,
            resolution: 0.25,
            width,
            height,
            num_cells: width * height,
            heights: (0..n).map(|i| i as f64 * 0.01).collect(),
            num_obstacle_cells: 0,
            obstacle_mask: Vec::new(),
            ..TerrainMap::default()
        }
    }

    fn request() -> PlanRequest {
        PlanRequest {
            request_id: 9,
            num_inline_maps: 1,
            inline_map: vec![map_msg(4, 3)],
            start_x: -0.9,
            start_y: 2.1,
            goal_x: -0.1,
            goal_y: 2.6,
            goal_radius: 0.2,
            method: PlanRequest::METHOD_DIJKSTRA,
            ..PlanRequest::default()
        }
    }

    #[test]
    fn every_method_has_exactly_one_wire_code() {
        for method in Method::ALL {
            let codes: Vec<i8> = METHOD_CODES
                .iter()
                .filter(|(_, m)| *m == method)
                .map(|&(code, _)| code)
                .collect();
            assert_eq!(codes.len(), 1, "{method}: codes {codes:?}");
            assert_eq!(method_of_code(codes[0]), Some(method));
        }
        assert_eq!(METHOD_CODES.len(), Method::ALL.len());
        let mut admissible = request();
        admissible.method = PlanRequest::METHOD_ASTAR_ADMISSIBLE;
        let v = validate_request(&admissible, &NoMaps, 100, &OptionDefaults::default()).unwrap();
        assert_eq!(v.method, Method::AStarAdmissible);
    }

    /// `options.generators` selects the RBF generators; 0 is the transfer, and the indicator
    /// basis is not affected by it.
    #[test]
    fn the_generators_field_selects_the_rbf_generators() {
        let defaults = OptionDefaults::default();
        let resolved = |basis: i8, generators: i8| {
            let mut r = request();
            r.options.basis = basis;
            r.options.generators = generators;
            validate_request(&r, &NoMaps, 100, &defaults)
                .expect("valid")
                .options
                .basis
        };
        assert_eq!(
            resolved(PlanOptions::BASIS_RBF, PlanOptions::GENERATORS_DEFAULT),
            BasisKind::DEFAULT_RBF
        );
        assert_eq!(
            resolved(PlanOptions::BASIS_RBF, PlanOptions::GENERATORS_TRANSFER),
            BasisKind::DEFAULT_RBF
        );
        assert_eq!(
            resolved(PlanOptions::BASIS_RBF, PlanOptions::GENERATORS_ANSDMD),
            BasisKind::ANSDMD_RBF
        );
        assert_eq!(
            resolved(PlanOptions::BASIS_INDICATOR, PlanOptions::GENERATORS_ANSDMD),
            BasisKind::Indicator
        );
        // The wire names and the planner's names are the same list.
        for (code, kind) in [
            (PlanOptions::GENERATORS_TRANSFER, RbfGenerators::Transfer),
            (PlanOptions::GENERATORS_ANSDMD, RbfGenerators::Ansdmd),
        ] {
            assert_eq!(
                RbfGenerators::ALL.iter().position(|&g| g == kind),
                Some(code as usize - 1)
            );
        }
    }

    #[test]
    fn a_valid_request_resolves_defaults() {
        let v = validate_request(&request(), &NoMaps, 100, &OptionDefaults::default()).unwrap();
        assert_eq!(v.request_id, 9);
        assert_eq!(v.method, Method::Dijkstra);
        assert_eq!(v.map_seq, 3);
        assert_eq!((v.map.map.width, v.map.map.height), (4, 3));
        assert_eq!(v.map.map.origin, [-1.0, 2.0]);
        assert_eq!(v.map.knowledge, None);
        assert_eq!(v.options.grid_size, 4);
        assert_eq!(v.options.directions, 8);
        assert_eq!(v.options.speed, 0.5);
        assert_eq!(v.options.start_density, StartDensity::UniformFree);
        assert_eq!(v.options.confidence_sigmas, DEFAULT_CONFIDENCE_SIGMAS);
        assert_eq!(v.start_sigma, 0.0);
        let service = TraversabilityParams {
            footprint_radius_m: 0.25,
            ..TraversabilityParams::default()
        };
        // No start σ: the footprint as configured; κ also bounds the map's heights.
        assert_eq!(
            v.traversability(&service),
            TraversabilityParams {
                height_confidence_sigmas: DEFAULT_CONFIDENCE_SIGMAS,
                ..service
            }
        );
        let mut uncertain = request();
        uncertain.start_sigma = 0.1;
        uncertain.options.confidence_sigmas = 3.0;
        let v = validate_request(&uncertain, &NoMaps, 100, &OptionDefaults::default()).unwrap();
        assert!((v.traversability(&service).footprint_radius_m - 0.55).abs() < 1e-12);
        // The belief density takes the request's σ.
        uncertain.options.start_density = PlanOptions::START_DENSITY_BELIEF;
        let v = validate_request(&uncertain, &NoMaps, 100, &OptionDefaults::default()).unwrap();
        assert_eq!(
            v.options.start_density,
            StartDensity::Belief { sigma_m: 0.1 }
        );
    }

    #[test]
    fn each_invalid_field_gets_its_status_and_names_the_field() {
        let defaults = OptionDefaults::default();
        type Case = (Box<dyn Fn(&mut PlanRequest)>, i8, &'static str);
        let cases: Vec<Case> = vec![
            (
                Box::new(|r| r.request_id = 0),
                PlanReply::STATUS_INVALID_REQUEST,
                "request_id",
            ),
            (
                Box::new(|r| r.method = 5),
                PlanReply::STATUS_INVALID_REQUEST,
                "unknown method",
            ),
            (
                Box::new(|r| r.start_x = f64::NAN),
                PlanReply::STATUS_INVALID_REQUEST,
                "start_x",
            ),
            (
                Box::new(|r| r.goal_radius = 0.0),
                PlanReply::STATUS_INVALID_REQUEST,
                "goal_radius",
            ),
            (
                Box::new(|r| r.options.directions = 6),
                PlanReply::STATUS_INVALID_REQUEST,
                "directions",
            ),
            (
                Box::new(|r| r.options.grid_size = 1),
                PlanReply::STATUS_INVALID_REQUEST,
                "grid_size",
            ),
            (
                Box::new(|r| r.options.basis = 9),
                PlanReply::STATUS_INVALID_REQUEST,
                "basis",
            ),
            (
                Box::new(|r| r.options.generators = 3),
                PlanReply::STATUS_INVALID_REQUEST,
                "generators",
            ),
            (
                Box::new(|r| {
                    r.options.basis = PlanOptions::BASIS_RBF;
                    r.options.generators = PlanOptions::GENERATORS_ANSDMD;
                    r.options.grid_size = 65;
                }),
                PlanReply::STATUS_INVALID_REQUEST,
                "ansdmd is limited",
            ),
            (
                Box::new(|r| r.start_sigma = f64::NAN),
                PlanReply::STATUS_INVALID_REQUEST,
                "start_sigma",
            ),
            (
                Box::new(|r| r.start_sigma = -0.1),
                PlanReply::STATUS_INVALID_REQUEST,
                "start_sigma",
            ),
            (
                Box::new(|r| r.start_sigma = 11.0),
                PlanReply::STATUS_INVALID_REQUEST,
                "start_sigma",
            ),
            (
                Box::new(|r| r.options.confidence_sigmas = -2.0),
                PlanReply::STATUS_INVALID_REQUEST,
                "confidence_sigmas",
            ),
            (
                Box::new(|r| r.options.confidence_sigmas = 6.0),
                PlanReply::STATUS_INVALID_REQUEST,
                "confidence_sigmas",
            ),
            (
                Box::new(|r| r.options.confidence_sigmas = f64::INFINITY),
                PlanReply::STATUS_INVALID_REQUEST,
                "confidence_sigmas",
            ),
            (
                Box::new(|r| r.options.speed = -1.0),
                PlanReply::STATUS_INVALID_REQUEST,
                "speed",
            ),
            (
                Box::new(|r| r.header.frame_id = "odom".into()),
                PlanReply::STATUS_INVALID_REQUEST,
                "frame_id",
            ),
            (
                Box::new(|r| r.inline_map[0].heights[5] = f64::NAN),
                PlanReply::STATUS_INVALID_MAP,
                "not finite",
            ),
            (
                Box::new(|r| r.inline_map[0].resolution = 0.0),
                PlanReply::STATUS_INVALID_MAP,
                "resolution",
            ),
            (
                Box::new(|r| r.inline_map[0].num_cells = 11),
                PlanReply::STATUS_INVALID_MAP,
                "num_cells",
            ),
            (
                Box::new(|r| r.inline_map[0].width = 40),
                PlanReply::STATUS_MAP_TOO_LARGE,
                "--max-map-cells",
            ),
            (
                Box::new(|r| {
                    r.inline_map[0].num_obstacle_cells = 2;
                    r.inline_map[0].obstacle_mask = vec![true, false];
                }),
                PlanReply::STATUS_INVALID_MAP,
                "obstacle_mask",
            ),
            (
                Box::new(|r| {
                    r.inline_map[0].num_known_cells = 5;
                    r.inline_map[0].known_mask = vec![true; 5];
                }),
                PlanReply::STATUS_INVALID_MAP,
                "known_mask has 5 entries",
            ),
            (
                Box::new(|r| r.inline_map[0].unknown_traversability = 1.5),
                PlanReply::STATUS_INVALID_MAP,
                "unknown_traversability",
            ),
            (
                Box::new(|r| r.inline_map[0].unknown_traversability = f64::NAN),
                PlanReply::STATUS_INVALID_MAP,
                "unknown_traversability",
            ),
            (
                Box::new(|r| {
                    r.inline_map[0].num_variance_cells = 3;
                    r.inline_map[0].height_variances = vec![0.01; 3];
                }),
                PlanReply::STATUS_INVALID_MAP,
                "height_variances has 3 entries",
            ),
            (
                Box::new(|r| {
                    let cells = r.inline_map[0].heights.len();
                    r.inline_map[0].num_variance_cells = cells as i32;
                    r.inline_map[0].height_variances = vec![0.01; cells];
                    r.inline_map[0].height_variances[4] = f64::NAN;
                }),
                PlanReply::STATUS_INVALID_MAP,
                "height variance of cell",
            ),
            (
                Box::new(|r| {
                    let cells = r.inline_map[0].heights.len();
                    r.inline_map[0].num_variance_cells = cells as i32;
                    r.inline_map[0].height_variances = vec![-1e-3; cells];
                }),
                PlanReply::STATUS_INVALID_MAP,
                "height variance of cell",
            ),
            (
                Box::new(|r| {
                    let cells = r.inline_map[0].heights.len();
                    r.inline_map[0].num_variance_cells = cells as i32;
                    r.inline_map[0].height_variances = vec![101.0; cells];
                }),
                PlanReply::STATUS_INVALID_MAP,
                "height variance of cell",
            ),
            (
                Box::new(|r| {
                    r.num_inline_maps = 0;
                    r.inline_map.clear();
                    r.map_seq = -1;
                }),
                PlanReply::STATUS_INVALID_MAP,
                "not received any map",
            ),
        ];
        for (mutate, status, needle) in cases {
            let mut r = request();
            mutate(&mut r);
            let rejection = validate_request(&r, &NoMaps, 100, &defaults).unwrap_err();
            assert_eq!(rejection.status, status, "{rejection:?}");
            assert!(
                rejection.reason.contains(needle),
                "{:?} lacks {needle:?}",
                rejection.reason
            );
        }
    }

    #[test]
    fn a_partially_known_map_keeps_its_mask_and_drops_unknown_obstacles() {
        let mut msg = map_msg(4, 3);
        msg.num_obstacle_cells = 12;
        msg.obstacle_mask = vec![false; 12];
        msg.obstacle_mask[1] = true; // known obstacle
        msg.obstacle_mask[2] = true; // unknown: dropped
        msg.num_known_cells = 12;
        msg.known_mask = (0..12).map(|i| i != 2 && i != 7).collect();
        let received = map_from_message(&msg, 100).expect("valid");
        let knowledge = received.knowledge.as_ref().expect("partial");
        assert_eq!(knowledge.known_count(), 10);
        assert_eq!(
            knowledge.unknown_traversability(),
            DEFAULT_UNKNOWN_TRAVERSABILITY
        );
        let obstacles = received.map.obstacles.as_ref().expect("one obstacle left");
        assert_eq!(obstacles.iter().filter(|&&b| b).count(), 1);
        assert!(obstacles[1]);
        // An explicit prior is kept, and the message form round-trips.
        msg.unknown_traversability = 0.8;
        let received = map_from_message(&msg, 100).expect("valid");
        let knowledge = received.knowledge.as_ref().expect("partial");
        assert_eq!(knowledge.unknown_traversability(), 0.8);
        let back = partial_map_to_message(&received.map, Some(knowledge), 3);
        assert_eq!(map_from_message(&back, 100).expect("valid"), received);
        // No mask: every cell known, whatever the prior field says (0 = default).
        let full = map_from_message(&map_msg(4, 3), 100).expect("valid");
        assert_eq!(full.knowledge, None);
    }

    #[test]
    fn height_variances_are_kept_and_round_trip() {
        let mut msg = map_msg(4, 3);
        msg.num_known_cells = 12;
        msg.known_mask = (0..12).map(|i| i != 5).collect();
        msg.num_variance_cells = 12;
        msg.height_variances = (0..12).map(|i| 1e-4 * f64::from(i)).collect();
        let received = map_from_message(&msg, 100).expect("valid");
        let knowledge = received.knowledge.as_ref().expect("partial");
        assert_eq!(
            knowledge.height_variances(),
            Some(&msg.height_variances[..])
        );
        assert_eq!(knowledge.height_sigma(4), 2e-2);
        // An unknown cell has no height, so no σ either.
        assert_eq!(knowledge.height_sigma(5), 0.0);
        let back = partial_map_to_message(&received.map, Some(knowledge), 3);
        assert_eq!(back.height_variances, msg.height_variances);
        assert_eq!(map_from_message(&back, 100).expect("valid"), received);
        // Variances without a mask: every cell known, with its variance.
        let mut full = map_msg(4, 3);
        full.num_variance_cells = 12;
        full.height_variances = vec![4e-4; 12];
        let received = map_from_message(&full, 100).expect("valid");
        let knowledge = received.knowledge.as_ref().expect("variances kept");
        assert_eq!(knowledge.known_count(), 12);
        assert_eq!(knowledge.height_sigma(7), 2e-2);
    }
}
