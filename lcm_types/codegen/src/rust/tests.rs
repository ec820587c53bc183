use super::*;

#[test]
fn names_follow_rust_conventions() {
    assert_eq!(rust_type_name("terrain_map_t"), "TerrainMap");
    assert_eq!(rust_type_name("header_t"), "Header");
    assert_eq!(rust_type_name("_t"), "T");
    assert_eq!(rust_type_name("x2y"), "X2y");
    assert_eq!(rust_type_name("self_t"), "Self_");
    assert_eq!(rust_field_name("type"), "r#type");
    assert_eq!(rust_field_name("self"), "self_");
    assert_eq!(rust_field_name("utime"), "utime");
}

#[test]
fn array_dimensions_map_to_nested_rust_types() {
    let src = "package p.q; struct s_t { int16_t n; double a[n][3]; float b[2][n]; string c[n]; r_t d[2]; }\n\
               package p.q; struct r_t { byte x; }";
    let f = crate::parse::parse_str(src, "t.lcm").unwrap();
    let code = generate(&Schema::new(vec![f]).unwrap(), &RustOptions::default()).unwrap();
    for expected in [
        "pub mod p {",
        "pub mod q {",
        "pub struct S {",
        "pub a: ::std::vec::Vec<[f64; 3]>,",
        "pub b: [::std::vec::Vec<f32>; 2],",
        "pub c: ::std::vec::Vec<::std::string::String>,",
        "pub d: [super::super::p::q::R; 2],",
        "crate::codec::encode_dim(i64::from(self.n), Self::TYPE_NAME, \"n\")?",
        "r.check_array(&dims, 8, Self::TYPE_NAME, \"a\")?",
        "r.check_array(&dims, 5, Self::TYPE_NAME, \"c\")?",
        "const MIN_ENCODED_LEN: usize = 4;",
    ] {
        assert!(code.contains(expected), "missing `{expected}` in:\n{code}");
    }
}

#[test]
fn colliding_rust_names_are_rejected() {
    let f = crate::parse::parse_str("struct a_t { int8_t x; } struct a { int8_t y; }", "t.lcm")
        .unwrap();
    let s = Schema::new(vec![f]).unwrap();
    let err = generate(&s, &RustOptions::default()).unwrap_err();
    assert!(matches!(err, GenerateError::NameCollision { .. }), "{err}");
}
