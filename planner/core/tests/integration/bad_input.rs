//! Bad requests become typed errors, never panics.

use pf_planner::error::{MapError, PlanError};
use pf_planner::grid::GoalRegion;
use pf_planner::io::load_scenario;
use pf_planner::map::GridMap;
use pf_planner::plan::{plan, Method, PlanRequest, PlannerOptions};

fn flat_map(w: usize, h: usize) -> GridMap {
    GridMap::new([0.0, 0.0], 0.5, w, h, vec![0.3; w * h], None).expect("map")
}

fn request(map: GridMap, method: Method) -> PlanRequest {
    PlanRequest {
        map,
        start: [0.6, 0.6],
        start_yaw: 0.0,
        goal: GoalRegion {
            center: [4.4, 4.4],
            radius: 0.3,
        },
        method,
        options: PlannerOptions {
            grid_size: 10,
            ..PlannerOptions::default()
        },
    }
}

fn each_method(req: &PlanRequest, check: impl Fn(Method, Result<(), PlanError>)) {
    for method in Method::ALL {
        let r = PlanRequest {
            method,
            ..req.clone()
        };
        check(method, plan(&r).map(|_| ()));
    }
}

#[test]
fn a_valid_request_plans_with_every_method() {
    each_method(&request(flat_map(10, 10), Method::Pf), |m, r| {
        assert!(r.is_ok(), "{m}: {r:?}")
    });
}

#[test]
fn nan_negative_and_empty_maps() {
    let mut nan = flat_map(10, 10);
    nan.heights[17] = f64::NAN; // fields are public: plan() must re-validate
    each_method(&request(nan, Method::Pf), |m, r| {
        assert!(
            matches!(
                r,
                Err(PlanError::InvalidMap(MapError::NonFiniteHeight {
                    ix: 7,
                    iy: 1
                }))
            ),
            "{m}: {r:?}"
        )
    });
    let mut negative = flat_map(10, 10);
    negative.heights[3] = -0.2;
    each_method(&request(negative, Method::Pf), |m, r| {
        assert!(
            matches!(
                r,
                Err(PlanError::InvalidMap(MapError::NegativeHeight {
                    ix: 3,
                    iy: 0,
                    ..
                }))
            ),
            "{m}: {r:?}"
        )
    });
    let empty = GridMap {
        width: 0,
        height: 0,
        heights: vec![],
        ..flat_map(1, 1)
    };
    each_method(&request(empty, Method::Pf), |m, r| {
        assert!(
            matches!(r, Err(PlanError::InvalidMap(MapError::Empty { .. }))),
            "{m}: {r:?}"
        )
    });
    let absurd = GridMap {
        width: 1 << 20,
        height: 1 << 20,
        heights: vec![],
        ..flat_map(1, 1)
    };
    each_method(&request(absurd, Method::Pf), |m, r| {
        assert!(
            matches!(r, Err(PlanError::InvalidMap(MapError::TooLarge { .. }))),
            "{m}: {r:?}"
        )
    });
}

#[test]
fn start_and_goal_off_the_map_or_in_obstacles() {
    let base = request(flat_map(10, 10), Method::Pf);
    let off = PlanRequest {
        start: [-1.0, 0.5],
        ..base.clone()
    };
    each_method(&off, |m, r| {
        assert!(
            matches!(r, Err(PlanError::StartOffMap { .. })),
            "{m}: {r:?}"
        )
    });
    let nan_start = PlanRequest {
        start: [f64::NAN, 0.5],
        ..base.clone()
    };
    each_method(&nan_start, |m, r| {
        assert!(
            matches!(r, Err(PlanError::StartOffMap { .. })),
            "{m}: {r:?}"
        )
    });
    let goal_off = PlanRequest {
        goal: GoalRegion {
            center: [9.0, 2.0],
            radius: 0.3,
        },
        ..base.clone()
    };
    each_method(&goal_off, |m, r| {
        assert!(matches!(r, Err(PlanError::GoalOffMap { .. })), "{m}: {r:?}")
    });

    let mut map = flat_map(10, 10);
    let mut mask = vec![false; 100];
    mask[11] = true; // cell (1, 1) contains the start (0.6, 0.6)
    mask[8 * 10 + 8] = true; // contains the goal centre (4.4, 4.4)
    map.obstacles = Some(mask);
    let blocked = PlanRequest {
        map: map.clone(),
        ..base.clone()
    };
    each_method(&blocked, |m, r| {
        assert!(
            matches!(r, Err(PlanError::StartInObstacle { .. })),
            "{m}: {r:?}"
        )
    });
    let goal_blocked = PlanRequest {
        map,
        start: [2.4, 0.6],
        ..base.clone()
    };
    each_method(&goal_blocked, |m, r| {
        assert!(
            matches!(r, Err(PlanError::GoalInObstacle { .. })),
            "{m}: {r:?}"
        )
    });
}

#[test]
fn walled_off_goal_is_unreachable() {
    let mut map = flat_map(10, 10);
    let mut mask = vec![false; 100];
    for iy in 0..10 {
        mask[iy * 10 + 5] = true;
    }
    map.obstacles = Some(mask);
    each_method(&request(map, Method::Pf), |m, r| {
        assert!(
            matches!(
                r,
                Err(PlanError::Unreachable { .. }) | Err(PlanError::Infeasible { .. })
            ),
            "{m}: {r:?}"
        )
    });
}

#[test]
fn bad_options() {
    let base = request(flat_map(10, 10), Method::Pf);
    for (options, name) in [
        (
            PlannerOptions {
                speed: 0.0,
                ..base.options.clone()
            },
            "speed",
        ),
        (
            PlannerOptions {
                speed: f64::NAN,
                ..base.options.clone()
            },
            "speed",
        ),
        (
            PlannerOptions {
                speed: -1.0,
                ..base.options.clone()
            },
            "speed",
        ),
        (
            PlannerOptions {
                grid_size: 1_000_000,
                ..base.options.clone()
            },
            "grid_size",
        ),
        (
            PlannerOptions {
                grid_size: 0,
                ..base.options.clone()
            },
            "grid_size",
        ),
        (
            PlannerOptions {
                directions: 5,
                ..base.options.clone()
            },
            "directions",
        ),
    ] {
        let req = PlanRequest {
            options,
            ..base.clone()
        };
        each_method(&req, |m, r| {
            assert!(
                matches!(&r, Err(PlanError::InvalidOption { name: n, .. }) if *n == name),
                "{m} {name}: {r:?}"
            )
        });
    }
    let negative_radius = PlanRequest {
        goal: GoalRegion {
            center: [4.4, 4.4],
            radius: -1.0,
        },
        ..base.clone()
    };
    each_method(&negative_radius, |m, r| {
        assert!(
            matches!(r, Err(PlanError::InvalidOption { .. })),
            "{m}: {r:?}"
        )
    });
    let pf_zero_umax = PlanRequest {
        options: PlannerOptions {
            u_max: 0.0,
            ..base.options.clone()
        },
        ..base
    };
    assert!(matches!(
        plan(&pf_zero_umax),
        Err(PlanError::InvalidOption { .. })
    ));
}

#[test]
fn missing_and_malformed_files() {
    let dir = std::env::temp_dir().join(format!("pf-planner-bad-input-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    assert!(matches!(
        load_scenario(&dir.join("nope.json")),
        Err(PlanError::Io { .. })
    ));
    let json = dir.join("broken.json");
    std::fs::write(&json, "{\"name\": 3").expect("write");
    assert!(matches!(
        load_scenario(&json),
        Err(PlanError::Format { .. })
    ));
    std::fs::write(
        &json,
        r#"{"name":"x","origin":[0,0],"resolution":0.5,"width":2,"height":2,"heights":"h.npy","start":[0.1,0.1],"goal":{"center":[0.9,0.9],"radius":0.1}}"#,
    )
    .expect("write");
    std::fs::write(dir.join("h.npy"), b"not numpy").expect("write");
    assert!(matches!(
        load_scenario(&json),
        Err(PlanError::Format { .. })
    ));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
