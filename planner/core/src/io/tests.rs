use super::*;

#[test]
fn header_is_64_byte_aligned_and_parses_back() {
    let data: Vec<f64> = (0..6).map(|i| i as f64 * 0.5 - 1.0).collect();
    let mut bytes = npy_header("<f8", &[2, 3]);
    assert_eq!(bytes.len() % 64, 0);
    for v in &data {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    let a = parse_npy(&bytes).expect("parse");
    assert_eq!(a.shape, (2, 3));
    assert_eq!(a.values, data);
}

#[test]
fn fortran_order_and_small_dtypes_are_converted() {
    // numpy: np.asfortranarray(np.array([[1, 2, 3], [4, 5, 6]], dtype='<i4')).
    let header = "{'descr': '<i4', 'fortran_order': True, 'shape': (2, 3), }";
    let mut bytes = NPY_MAGIC.to_vec();
    bytes.extend_from_slice(&[1, 0]);
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    for v in [1i32, 4, 2, 5, 3, 6] {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    let a = parse_npy(&bytes).expect("parse");
    assert_eq!(a.values, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
}

#[test]
fn malformed_files_are_errors() {
    assert!(parse_npy(b"hello").is_err());
    let mut bytes = npy_header("<f8", &[2, 3]);
    bytes.extend_from_slice(&[0u8; 8]);
    assert!(parse_npy(&bytes).unwrap_err().contains("expected 48"));
    let bytes = npy_header("<c16", &[1, 1]);
    assert!(parse_npy(&bytes).unwrap_err().contains("unsupported dtype"));
    let bytes = npy_header("<f8", &[1 << 40, 1 << 40]);
    assert!(parse_npy(&bytes).unwrap_err().contains("exceeds"));
}

/// A 5000² `.npy` was read whole (201 MB) before its size was refused: the header alone
/// decides now. The file here is the header of a 5000² array followed by one byte, so
/// reading the data would fail differently.
#[test]
fn regression_an_oversize_npy_is_refused_from_its_header() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("big.npy");
    let mut bytes = npy_header("<f8", &[5000, 5000]);
    bytes.push(0);
    fs::write(&path, &bytes).expect("write");
    let err = read_npy(&path).unwrap_err().to_string();
    assert!(err.contains("exceeds 16777216 cells"), "{err}");
    // Within the cell limit, the claimed size is checked against the file's length.
    let mut bytes = npy_header("<f8", &[4000, 4000]);
    bytes.push(0);
    fs::write(&path, &bytes).expect("write");
    let err = read_npy(&path).unwrap_err().to_string();
    assert!(err.contains("file has"), "{err}");
    let err = read_npy_limited(&path, 1024 * 1024)
        .unwrap_err()
        .to_string();
    assert!(err.contains("exceeds 1048576 cells"), "{err}");
    // A consistent small file still reads.
    let mut bytes = npy_header("<f8", &[2, 2]);
    for v in [1.0f64, 2.0, 3.0, 4.0] {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    fs::write(&path, &bytes).expect("write");
    let a = read_npy_limited(&path, 4).expect("read");
    assert_eq!(a.values, vec![1.0, 2.0, 3.0, 4.0]);
    assert!(read_npy_limited(&path, 3).is_err());
}

#[test]
fn regression_sidecar_array_paths_stay_in_the_sidecar_directory() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scenario = crate::scenarios::by_name("c_shape").expect("scenario");
    let json = save_scenario(&scenario, dir.path()).expect("save");
    assert!(load_scenario(&json).is_ok());
    let text = fs::read_to_string(&json).expect("read");
    let outside = dir.path().join("outside.npy");
    fs::copy(dir.path().join("c_shape.heights.npy"), &outside).expect("copy");
    for bad in [
        outside.display().to_string(),
        "../c_shape.heights.npy".to_owned(),
        "sub/../../x.npy".to_owned(),
        String::new(),
    ] {
        let edited = text.replace(
            "\"c_shape.heights.npy\"",
            &serde_json::to_string(&bad).expect("json"),
        );
        assert_ne!(edited, text);
        fs::write(&json, edited).expect("write");
        let err = load_scenario(&json).unwrap_err().to_string();
        assert!(
            err.contains("must be a relative path inside"),
            "{bad}: {err}"
        );
    }
}

#[test]
fn a_sidecar_claiming_a_map_above_the_limit_is_refused_before_its_arrays_are_read() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scenario = crate::scenarios::by_name("c_shape").expect("scenario");
    let json = save_scenario(&scenario, dir.path()).expect("save");
    let cells = scenario.map.width * scenario.map.height;
    let err = load_scenario_limited(&json, cells - 1)
        .unwrap_err()
        .to_string();
    assert!(err.contains("exceeds the limit"), "{err}");
    assert!(load_scenario_limited(&json, cells).is_ok());
    fs::write(dir.path().join("huge.json"), vec![b' '; 2 << 20]).expect("write");
    let err = load_scenario(&dir.path().join("huge.json"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("not a map sidecar"), "{err}");
}

#[test]
fn a_scenario_with_a_prior_round_trips_and_one_without_writes_no_prior_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let surprise = crate::scenarios::by_name("surprise").expect("scenario");
    assert!(surprise.prior.is_some());
    let json = save_scenario(&surprise, dir.path()).expect("save");
    assert!(dir.path().join("surprise.prior.heights.npy").is_file());
    assert!(!dir.path().join("surprise.prior.obstacles.npy").exists());
    let sidecar: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(&json).expect("read")).expect("json");
    assert_eq!(
        sidecar["prior"],
        serde_json::json!({"heights": "surprise.prior.heights.npy", "obstacles": null})
    );
    assert_eq!(load_scenario(&json).expect("load"), surprise);

    // A sidecar without a prior (every sidecar written before priors existed) has no such key
    // and reads back without one.
    let c_shape = crate::scenarios::by_name("c_shape").expect("scenario");
    let json = save_scenario(&c_shape, dir.path()).expect("save");
    let text = fs::read_to_string(&json).expect("read");
    assert!(!text.contains("prior"), "{text}");
    let loaded = load_scenario(&json).expect("load");
    assert_eq!(loaded.prior, None);
    assert_eq!(loaded, c_shape);
}

#[test]
fn a_prior_with_obstacles_round_trips() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut scenario = crate::scenarios::by_name("surprise").expect("scenario");
    let prior = scenario.prior.as_mut().expect("prior");
    let mut mask = vec![false; prior.len()];
    mask[7] = true;
    prior.obstacles = Some(mask);
    let json = save_scenario(&scenario, dir.path()).expect("save");
    assert!(dir.path().join("surprise.prior.obstacles.npy").is_file());
    assert_eq!(load_scenario(&json).expect("load"), scenario);
}

#[test]
fn a_prior_of_another_shape_or_outside_the_sidecar_directory_is_refused_with_a_reason() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scenario = crate::scenarios::by_name("surprise").expect("scenario");
    let (w, h) = (scenario.map.width, scenario.map.height);
    let json = save_scenario(&scenario, dir.path()).expect("save");
    let prior_file = dir.path().join("surprise.prior.heights.npy");

    write_npy_f64(&prior_file, (h / 2, w), &vec![0.5; h / 2 * w]).expect("write");
    let err = load_scenario(&json).unwrap_err().to_string();
    assert!(
        err.contains(
            "prior array shape (64, 128) does not match the sidecar's (height, width) = (128, 128)"
        ),
        "{err}"
    );
    write_npy_f64(&prior_file, (w, h), &vec![f64::NAN; w * h]).expect("write");
    assert!(load_scenario(&json).is_err(), "a prior with NaN heights");

    let text = fs::read_to_string(&json).expect("read");
    let outside = dir.path().join("outside.npy");
    fs::copy(dir.path().join("surprise.heights.npy"), &outside).expect("copy");
    for bad in [
        outside.display().to_string(),
        "../surprise.prior.heights.npy".to_owned(),
    ] {
        let edited = text.replace(
            "\"surprise.prior.heights.npy\"",
            &serde_json::to_string(&bad).expect("json"),
        );
        assert_ne!(edited, text);
        fs::write(&json, edited).expect("write");
        let err = load_scenario(&json).unwrap_err().to_string();
        assert!(
            err.contains("prior array file") && err.contains("must be a relative path inside"),
            "{bad}: {err}"
        );
    }
    let edited = text.replace(
        "\"obstacles\": null\n  }",
        "\"obstacles\": null, \"extra\": 1\n  }",
    );
    assert_ne!(edited, text);
    fs::write(&json, edited).expect("write");
    let err = load_scenario(&json).unwrap_err().to_string();
    assert!(err.contains("unknown field `extra`"), "{err}");
}

#[test]
fn a_prior_of_other_geometry_is_not_saved() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut scenario = crate::scenarios::by_name("surprise").expect("scenario");
    if let Some(prior) = scenario.prior.as_mut() {
        prior.resolution *= 2.0;
    }
    let err = save_scenario(&scenario, dir.path())
        .unwrap_err()
        .to_string();
    assert!(err.contains("must have the true map's geometry"), "{err}");
    assert!(!dir.path().join("surprise.json").exists());
}
