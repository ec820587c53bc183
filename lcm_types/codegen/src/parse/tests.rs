use super::*;

#[test]
fn c_integers_follow_strtoll_base_zero() {
    assert_eq!(parse_c_integer("42"), Some(42));
    assert_eq!(parse_c_integer("-7"), Some(-7));
    assert_eq!(parse_c_integer("0x1F"), Some(31));
    assert_eq!(parse_c_integer("010"), Some(8));
    assert_eq!(parse_c_integer("0"), Some(0));
    assert_eq!(parse_c_integer("9223372036854775807"), Some(i64::MAX));
    assert_eq!(parse_c_integer("-9223372036854775808"), Some(i64::MIN));
    assert_eq!(parse_c_integer("9223372036854775808"), None);
    assert_eq!(parse_c_integer("12abc"), None);
    assert_eq!(parse_c_integer("08"), None);
    assert_eq!(parse_c_integer(""), None);
}

#[test]
fn parses_members_constants_dims_and_docs() {
    let src = "package a.b;\n// the doc\nstruct s_t {\n  const int8_t K = 3, L = -4;\n  // n doc\n  int32_t n;\n  double v[n][3], w;\n  c.d.e_t nested;\n  other_t here[2];\n}\n";
    let f = parse_str(src, "x.lcm").unwrap();
    let s = &f.structs[0];
    assert_eq!(s.name.package, "a.b");
    assert_eq!(s.name.name, "s_t");
    assert_eq!(s.doc.as_deref(), Some("the doc"));
    assert_eq!(s.constants.len(), 2);
    assert_eq!(s.constants[1].value, ConstValue::Int(-4));
    assert_eq!(s.members.len(), 5);
    assert_eq!(s.members[0].doc.as_deref(), Some("n doc"));
    assert_eq!(
        s.members[1].dims,
        vec![
            Dimension::Var { member: "n".into() },
            Dimension::Const {
                token: "3".into(),
                size: 3
            }
        ]
    );
    assert!(s.members[2].dims.is_empty());
    assert_eq!(
        s.members[3].ty,
        TypeRef::Struct(QualifiedName {
            package: "c.d".into(),
            name: "e_t".into()
        })
    );
    assert_eq!(
        s.members[4].ty,
        TypeRef::Struct(QualifiedName {
            package: "a.b".into(),
            name: "other_t".into()
        })
    );
}

#[test]
fn rejects_what_lcm_gen_rejects() {
    let bad = [
        ("struct s { double v[n]; }", "unknown array size"),
        ("struct s { double n; double v[n]; }", "must be a scalar"),
        (
            "struct s { int32_t n[2]; double v[n]; }",
            "must be a scalar",
        ),
        ("struct s { int32_t a; int32_t a; }", "duplicate member"),
        ("struct s { const int8_t A = 200; }", "out of range"),
        ("struct s { const string A = 1; }", "invalid type for const"),
        ("struct s { double v[0]; }", "constant array size"),
        ("struct s { int32_t 1a; }", "invalid name"),
        ("enum e { A, B }", "enums are not supported"),
        ("struct s { int32_t a }", "expected ';'"),
        ("struct s { int32_t a; /* open", "unterminated"),
        (
            "struct s { int32_t a; } struct s { int8_t b; }",
            "duplicate type",
        ),
    ];
    for (src, expected) in bad {
        let err = parse_str(src, "bad.lcm").unwrap_err();
        assert!(
            err.message.contains(expected),
            "{src}: got '{}'",
            err.message
        );
    }
}
