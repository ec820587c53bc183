//! Generated code for the codegen test schemas (lcm_types/codegen/tests/data/*.lcm): constants,
//! array shapes, recursive types, keyword members. Byte-level agreement with lcm-gen for these
//! schemas is checked in golden_lcm_gen.rs.

use lcm_types::{DecodeError, DecodeLimits, Message};

use crate::test_types;

use test_types::codegen_test::deep::{Holder, Keywords, Leaf};
use test_types::codegen_test::{AllPrimitives, Arrays};

#[test]
fn constants_have_their_declared_types_and_values() {
    let i8_min: i8 = AllPrimitives::I8_MIN;
    let i8_max: i8 = AllPrimitives::I8_MAX;
    let i16_hex: i16 = AllPrimitives::I16_HEX;
    let i32_min: i32 = AllPrimitives::I32_MIN;
    let i64_big: i64 = AllPrimitives::I64_BIG;
    let f: f32 = AllPrimitives::F;
    let d: f64 = AllPrimitives::D;
    assert_eq!((i8_min, i8_max), (-128, 127));
    assert_eq!(i16_hex, 0x7fff);
    assert_eq!(i32_min, i32::MIN);
    assert_eq!(i64_big, i64::MIN);
    assert_eq!(f, 1.5e-3_f32);
    assert_eq!(d, -2.25);
}

#[test]
fn array_shapes_follow_the_dimensions() {
    let a = Arrays {
        rows: 2,
        cols: 3,
        var2d: vec![vec![1.0; 3]; 2],
        fixed_then_var: [vec![0.5; 3], vec![0.25; 3]],
        var_then_fixed: vec![[1, 2]; 2],
        var3d: vec![vec![[7, 8]; 3]; 2],
        names: vec![vec!["n".to_string(); 3]; 2],
        grid: vec![Default::default(); 2],
        ..Arrays::default()
    };
    let bytes = a.encode().expect("consistent");
    assert_eq!(bytes.len(), 8 + a.encoded_len_one());
    assert_eq!(Arrays::decode(&bytes).expect("decodes"), a);

    // An inner row of the wrong length is an encode error naming the array.
    let mut ragged = a.clone();
    ragged.var2d[1].pop();
    let err = ragged.encode().expect_err("ragged");
    assert!(err.to_string().contains("arrays_t.var2d"), "{err}");
}

fn chain(depth: usize) -> Holder {
    let mut node = Holder {
        first: Leaf { value: 0 },
        ..Holder::default()
    };
    for level in 1..depth {
        node = Holder {
            first: Leaf {
                value: level as i32,
            },
            num_children: 1,
            children: vec![node],
            ..Holder::default()
        };
    }
    node
}

#[test]
fn recursive_types_round_trip_and_their_depth_is_limited() {
    let shallow = chain(10);
    let bytes = shallow.encode().expect("consistent");
    assert_eq!(Holder::decode(&bytes).expect("decodes"), shallow);

    // 70 nested Holders exceed the default depth limit of 64 (siblings do not add up).
    let deep = chain(70);
    let bytes = deep.encode().expect("consistent");
    let err = Holder::decode(&bytes).expect_err("too deep");
    assert!(
        matches!(err, DecodeError::TooDeep { limit: 64, .. }),
        "{err}"
    );
    let relaxed = DecodeLimits {
        max_depth: 71,
        ..DecodeLimits::default()
    };
    assert_eq!(
        Holder::decode_with_limits(&bytes, &relaxed).expect("70 holders + 1 leaf level"),
        deep
    );
}

#[test]
fn keyword_members_keep_their_lcm_names() {
    let k = Keywords {
        r#type: 3,
        r#move: 1.5,
        self_: true,
    };
    let json = serde_json::to_value(&k).expect("serializes");
    assert_eq!(
        json,
        serde_json::json!({"type": 3, "move": 1.5, "self": true})
    );
    assert_eq!(
        Keywords::decode(&k.encode().expect("encodes")).expect("decodes"),
        k
    );
}

#[test]
fn any_message_dispatches_on_fingerprint() {
    let leaf = Leaf { value: 42 };
    let bytes = leaf.encode().expect("encodes");
    let any = test_types::AnyMessage::decode(&bytes).expect("known fingerprint");
    assert_eq!(any, test_types::AnyMessage::Leaf(leaf));
    assert_eq!(any.type_name(), "codegen_test.deep.leaf_t");
    let mut unknown = bytes.clone();
    unknown[0] ^= 0x80;
    assert!(matches!(
        test_types::AnyMessage::decode(&unknown),
        Err(DecodeError::UnknownFingerprint { .. })
    ));
    assert!(test_types::AnyMessage::default_for("codegen_test.nope_t").is_none());
}
