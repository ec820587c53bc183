use super::*;

const VALID: &str = r#"
urdf = "r.urdf"
base_link = "body"
stand_height = 0.3

[legs.FR]
joints = ["abd0", "hip0", "knee0"]
foot_link = "f0"
knee_points = "backward"

[legs.FL]
joints = ["abd1", "hip1", "knee1"]
foot_link = "f1"
knee_points = "backward"

[legs.RR]
joints = ["abd2", "hip2", "knee2"]
foot_link = "l2"
foot_offset = [0.0, 0.01, -0.2]
knee_points = "forward"

[legs.RL]
joints = ["abd3", "hip3", "knee3"]
foot_link = "f3"
knee_points = "forward"
"#;

fn config_error(text: &str) -> String {
    match RobotConfig::from_toml_str(text, "test.toml") {
        Err(ModelError::Config { file, reason, .. }) => {
            assert_eq!(file, "test.toml");
            reason
        }
        other => panic!("expected a config error, got {other:?}"),
    }
}

#[test]
fn valid_config_parses_with_defaults() {
    let config = RobotConfig::from_toml_str(VALID, "test.toml").expect("valid");
    assert_eq!(config.base_link, "body");
    assert_eq!(
        config.legs.get(Leg::RR).foot_offset,
        Some([0.0, 0.01, -0.2])
    );
    assert_eq!(config.legs.get(Leg::RL).knee_points, KneeDirection::Forward);
    assert_eq!(config.legs.get(Leg::FL).joints[2], "knee1");
    assert!(config.massless_links.is_empty());
    assert_eq!(config.limits, LimitOverrides::default());
    assert_eq!(config.foot_radius, None);
}

#[test]
fn unknown_keys_are_refused_with_their_name() {
    let top = config_error(&format!("stand_hieght = 0.3\n{VALID}"));
    assert!(top.contains("stand_hieght"), "{top}");
    let leg = config_error(&VALID.replace("foot_link = \"f1\"", "foot_link = \"f1\"\nfoot = 1"));
    assert!(leg.contains("foot"), "{leg}");
    let unknown_leg = config_error(&VALID.replace("[legs.RL]", "[legs.HL]"));
    assert!(unknown_leg.contains("HL"), "{unknown_leg}");
}

#[test]
fn syntax_errors_give_the_line() {
    let text = VALID.replace("stand_height = 0.3", "stand_height = = 0.3");
    let reason = config_error(&text);
    assert!(reason.contains("line 4"), "{reason}");
}

#[test]
fn a_leg_with_two_or_four_joints_is_refused() {
    let two = config_error(&VALID.replace(r#"["abd0", "hip0", "knee0"]"#, r#"["abd0", "hip0"]"#));
    assert!(two.contains("expected exactly 3 values, found 2"), "{two}");
    assert!(two.contains("legs.FR") || two.contains("joints"), "{two}");
    let four = config_error(&VALID.replace(
        r#"["abd0", "hip0", "knee0"]"#,
        r#"["abd0", "hip0", "knee0", "extra0"]"#,
    ));
    assert!(
        four.contains("expected exactly 3 values, found 4"),
        "{four}"
    );
    let offset = config_error(&VALID.replace("[0.0, 0.01, -0.2]", "[0.0, 0.01, -0.2, 1.0]"));
    assert!(offset.contains("found 4"), "{offset}");
}

#[test]
fn missing_leg_and_bad_values_are_refused() {
    let start = VALID.find("[legs.RL]").expect("RL");
    let missing = config_error(&VALID[..start]);
    assert!(missing.contains("RL"), "{missing}");
    let height = config_error(&VALID.replace("stand_height = 0.3", "stand_height = -0.3"));
    assert!(height.contains("stand_height"), "{height}");
    let nan = config_error(&VALID.replace("stand_height = 0.3", "stand_height = nan"));
    assert!(nan.contains("stand_height"), "{nan}");
    let radius = config_error(&format!("foot_radius = 0.0\n{VALID}"));
    assert!(radius.contains("foot_radius"), "{radius}");
    let effort = config_error(&format!("{VALID}\n[limits]\neffort = [1.0, 0.0, 1.0]\n"));
    assert!(effort.contains("limits.effort"), "{effort}");
    let offset = config_error(&VALID.replace("[0.0, 0.01, -0.2]", "[0.0, inf, -0.2]"));
    assert!(offset.contains("legs.RR.foot_offset"), "{offset}");
    let knee = config_error(&VALID.replacen("\"backward\"", "\"sideways\"", 1));
    assert!(knee.contains("sideways"), "{knee}");
    let twice = config_error(&VALID.replace(
        r#"["abd1", "hip1", "knee1"]"#,
        r#"["abd0", "hip1", "knee1"]"#,
    ));
    assert!(twice.contains("`abd0`"), "{twice}");
}

#[test]
fn missing_config_file_names_the_path() {
    match RobotConfig::from_file(Path::new("/nonexistent/robot.toml")) {
        Err(ModelError::Io { path, .. }) => assert_eq!(path, "/nonexistent/robot.toml"),
        other => panic!("expected Io, got {other:?}"),
    }
}
