//! LCM type fingerprints, computed exactly as `lcm-gen` computes them.
//!
//! `lcmgen.c` hashes, per member in declaration order: the member name, the type name if the
//! type is primitive, the number of dimensions, and per dimension its mode and size string.
//! Every step is `v = ((v << 8) ^ (v >> 55)) + c` on a signed 64-bit integer with `c` a C
//! `char` (signed on the platforms LCM targets), so lengths above 127 wrap to negative values.
//! The generated bindings then add the fingerprints of all struct members (recursively, a type
//! already on the path counting 0) and rotate left by one bit.

use crate::parse::{QualifiedName, StructDef, TypeRef};

/// Finds the definition of a struct type by name (the schema's table; kept abstract so that
/// hashing does not depend on how types are stored).
pub type Lookup<'a> = dyn Fn(&QualifiedName) -> Option<&'a StructDef> + 'a;

fn hash_update(v: i64, c: u8) -> i64 {
    // `c as i8` reproduces the signed `char` of lcmgen.c.
    let c = i64::from(c as i8);
    ((v << 8) ^ (v >> 55)).wrapping_add(c)
}

fn hash_string_update(mut v: i64, s: &str) -> i64 {
    // strlen() is passed through a `char` parameter: only its low byte counts.
    v = hash_update(v, (s.len() & 0xff) as u8);
    for &b in s.as_bytes() {
        v = hash_update(v, b);
    }
    v
}

/// The per-type hash lcm-gen writes into generated code (before nested types are added).
pub fn base_hash(def: &StructDef) -> u64 {
    let mut v: i64 = 0x1234_5678;
    for member in &def.members {
        v = hash_string_update(v, &member.name);
        if let TypeRef::Primitive(p) = member.ty {
            v = hash_string_update(v, p.lcm_name());
        }
        // The dimension count goes through a `char` too.
        v = hash_update(v, (member.dims.len() & 0xff) as u8);
        for dim in &member.dims {
            v = hash_update(v, dim.mode());
            v = hash_string_update(v, dim.size_token());
        }
    }
    v as u64
}

/// The fingerprint sent on the wire in front of an encoded `name` message.
///
/// Returns None if `name` (or a type it contains) is not in the schema.
pub fn fingerprint(lookup: &Lookup<'_>, name: &QualifiedName) -> Option<u64> {
    let mut parents = Vec::new();
    recursive_hash(lookup, name, &mut parents)
}

fn recursive_hash(
    lookup: &Lookup<'_>,
    name: &QualifiedName,
    parents: &mut Vec<QualifiedName>,
) -> Option<u64> {
    if parents.contains(name) {
        return Some(0);
    }
    let def = lookup(name)?;
    parents.push(name.clone());
    let mut hash = base_hash(def);
    for member in &def.members {
        if let TypeRef::Struct(child) = &member.ty {
            hash = hash.wrapping_add(recursive_hash(lookup, child, parents)?);
        }
    }
    parents.pop();
    Some(hash.rotate_left(1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parse::{parse_str, ParsedFile};

    fn parse(src: &str) -> ParsedFile {
        parse_str(src, "t.lcm").unwrap()
    }

    fn find<'a>(file: &'a ParsedFile, name: &QualifiedName) -> Option<&'a StructDef> {
        file.structs.iter().find(|s| &s.name == name)
    }

    fn qn(package: &str, name: &str) -> QualifiedName {
        QualifiedName {
            package: package.into(),
            name: name.into(),
        }
    }

    // Reference values from lcm-gen 1.5.3 (`lcm-gen --python`): `_get_hash_recursive` constants
    // and `_packed_fingerprint` of the generated modules.
    #[test]
    fn empty_struct_hash_is_the_seed_rotated() {
        let f = parse("struct e_t { }");
        let def = find(&f, &qn("", "e_t")).unwrap();
        assert_eq!(base_hash(def), 0x1234_5678);
        assert_eq!(
            fingerprint(&|n| find(&f, n), &qn("", "e_t")),
            Some(0x2468_acf0)
        );
    }

    #[test]
    fn hash_step_is_arithmetic_shift_with_signed_chars() {
        // Negative v: the right shift must propagate the sign bit.
        assert_eq!(hash_update(-1, 0), (-1i64 << 8) ^ -1);
        // A byte >= 0x80 counts as a negative char.
        assert_eq!(hash_update(0, 0xff), -1);
    }

    #[test]
    fn recursive_type_counts_itself_as_zero() {
        let f = parse("package p; struct node_t { int32_t n; node_t kids[n]; }");
        let def = find(&f, &qn("p", "node_t")).unwrap();
        assert_eq!(base_hash(def), 0x90af_a2d1_3a5e_e21c);
        assert_eq!(
            fingerprint(&|n| find(&f, n), &qn("p", "node_t")),
            Some(0x215f_45a2_74bd_c439)
        );
    }
}
