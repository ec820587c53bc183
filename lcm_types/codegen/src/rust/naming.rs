//! The LCM → Rust name mapping, shared by every emitter so a type is spelled the same in its
//! declaration, its codec and the schema-wide enum.

use crate::parse::Primitive;

const RUST_KEYWORDS: &[&str] = &[
    "as", "async", "await", "break", "const", "continue", "dyn", "else", "enum", "extern", "false",
    "fn", "for", "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut", "pub", "ref",
    "return", "static", "struct", "trait", "true", "type", "unsafe", "use", "where", "while",
    "abstract", "become", "box", "do", "final", "gen", "macro", "override", "priv", "try",
    "typeof", "unsized", "virtual", "yield",
];
const NON_RAW_KEYWORDS: &[&str] = &["self", "Self", "super", "crate", "_"];

/// Rust type name of an LCM struct name: `terrain_map_t` → `TerrainMap`.
pub fn rust_type_name(lcm_name: &str) -> String {
    let base = lcm_name
        .strip_suffix("_t")
        .filter(|b| !b.is_empty())
        .unwrap_or(lcm_name);
    let mut out = String::with_capacity(base.len());
    let mut upper = true;
    for c in base.chars() {
        if c == '_' {
            upper = true;
        } else if upper {
            out.extend(c.to_uppercase());
            upper = false;
        } else {
            out.push(c);
        }
    }
    if out.is_empty() || out.starts_with(|c: char| c.is_ascii_digit()) {
        out.insert(0, 'T');
    }
    if NON_RAW_KEYWORDS.contains(&out.as_str()) {
        out.push('_');
    }
    out
}

/// Rust identifier of a member or module name: keywords become raw identifiers.
pub fn rust_field_name(name: &str) -> String {
    if NON_RAW_KEYWORDS.contains(&name) {
        format!("{name}_")
    } else if RUST_KEYWORDS.contains(&name) {
        format!("r#{name}")
    } else {
        name.to_string()
    }
}

pub(super) fn package_segments(package: &str) -> Vec<String> {
    if package.is_empty() {
        Vec::new()
    } else {
        package.split('.').map(rust_field_name).collect()
    }
}

pub(super) fn primitive_rust(p: Primitive) -> &'static str {
    match p {
        Primitive::Int8 => "i8",
        Primitive::Int16 => "i16",
        Primitive::Int32 => "i32",
        Primitive::Int64 => "i64",
        Primitive::Byte => "u8",
        Primitive::Float => "f32",
        Primitive::Double => "f64",
        Primitive::String => "::std::string::String",
        Primitive::Boolean => "bool",
    }
}
