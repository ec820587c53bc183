//! Rust code generation: one struct per LCM type with encode, decode and fingerprint.
//!
//! The generated code relies on a small hand-written runtime (reader, errors, the `Message`
//! trait), found at [`RustOptions::runtime_path`]; lcm-types provides it as `lcm_types::codec`.
//! Type names drop a trailing `_t` and become CamelCase (`terrain_map_t` → `TerrainMap`);
//! packages become modules (`a.b` → `a::b`); member names are kept (keywords become raw
//! identifiers). Arrays: fixed dimensions become `[T; N]`, variable ones `Vec<T>`, nested from
//! the first dimension outwards (`double v[n][3]` → `Vec<[f64; 3]>`).

use std::collections::{BTreeMap, HashSet};
use std::fmt::Write as _;

use crate::parse::{ConstValue, Dimension, Member, Primitive, QualifiedName, StructDef, TypeRef};
use crate::schema::Schema;

/// Code generation settings.
#[derive(Debug, Clone)]
pub struct RustOptions {
    /// Absolute path of the runtime module, e.g. `crate::codec` or `::lcm_types::codec`.
    pub runtime_path: String,
    /// Derive `serde::Serialize`/`Deserialize` on every type (the includer must depend on
    /// serde with the `derive` feature). Fixed arrays must then have at most 32 elements.
    pub serde: bool,
}

impl Default for RustOptions {
    fn default() -> Self {
        RustOptions {
            runtime_path: "crate::codec".to_string(),
            serde: false,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum GenerateError {
    #[error("types {first} and {second} both map to the Rust name {rust_name}")]
    NameCollision {
        first: String,
        second: String,
        rust_name: String,
    },
    #[error(
        "{owner}.{member}: fixed array dimension {size} exceeds 32, which serde cannot derive"
    )]
    SerdeArrayTooLarge {
        owner: String,
        member: String,
        size: usize,
    },
    #[error("{owner}: no Rust identifier for '{name}'")]
    BadIdentifier { owner: String, name: String },
}

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

fn package_segments(package: &str) -> Vec<String> {
    if package.is_empty() {
        Vec::new()
    } else {
        package.split('.').map(rust_field_name).collect()
    }
}

/// A place in generated code: a field (`self.x`) or a loop variable bound to a reference.
#[derive(Clone)]
enum Place {
    Field(String),
    Ref(String),
}

impl Place {
    /// For method calls (auto-deref makes both forms work).
    fn place(&self) -> &str {
        match self {
            Place::Field(s) | Place::Ref(s) => s,
        }
    }
    fn value(&self) -> String {
        match self {
            Place::Field(s) => s.clone(),
            Place::Ref(s) => format!("*{s}"),
        }
    }
    fn reference(&self) -> String {
        match self {
            Place::Field(s) => format!("&{s}"),
            Place::Ref(s) => s.clone(),
        }
    }
}

/// `expr` (the value of length member `member`) as an i64 expression.
fn widen_to_i64(def: &StructDef, member: &str, expr: &str) -> String {
    match def.member(member).map(|m| &m.ty) {
        Some(TypeRef::Primitive(Primitive::Int64)) => expr.to_string(),
        _ => format!("i64::from({expr})"),
    }
}

fn primitive_rust(p: Primitive) -> &'static str {
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

struct Generator<'a> {
    schema: &'a Schema,
    options: &'a RustOptions,
    rt: String,
}

impl Generator<'_> {
    /// Path from the module of package `from` to struct `to`.
    fn struct_path(&self, from: &str, to: &QualifiedName) -> String {
        let depth = package_segments(from).len();
        let mut path = if depth == 0 {
            "self::".to_string()
        } else {
            "super::".repeat(depth)
        };
        for seg in package_segments(&to.package) {
            path.push_str(&seg);
            path.push_str("::");
        }
        path.push_str(&rust_type_name(&to.name));
        path
    }

    fn element_type(&self, from: &str, ty: &TypeRef) -> String {
        match ty {
            TypeRef::Primitive(p) => primitive_rust(*p).to_string(),
            TypeRef::Struct(name) => self.struct_path(from, name),
        }
    }

    /// Rust type of `dims[level..]` of elements `elem`.
    fn array_type(&self, elem: &str, dims: &[Dimension]) -> String {
        match dims.split_first() {
            None => elem.to_string(),
            Some((Dimension::Const { size, .. }, rest)) => {
                format!("[{}; {size}]", self.array_type(elem, rest))
            }
            Some((Dimension::Var { .. }, rest)) => {
                format!("::std::vec::Vec<{}>", self.array_type(elem, rest))
            }
        }
    }

    fn default_expr(&self, dims: &[Dimension]) -> String {
        match dims.split_first() {
            Some((Dimension::Const { .. }, rest)) => {
                format!("::core::array::from_fn(|_| {})", self.default_expr(rest))
            }
            _ => "::core::default::Default::default()".to_string(),
        }
    }

    fn elem_min_len(&self, ty: &TypeRef) -> usize {
        match ty {
            TypeRef::Primitive(p) => p.min_encoded_len(),
            TypeRef::Struct(name) => self.schema.min_encoded_len(name),
        }
    }

    fn generate(&self) -> Result<String, GenerateError> {
        let mut out = String::new();
        out.push_str("// @generated by lcm-codegen from .lcm files. Do not edit.\n\n");

        // Group structs by package; check that Rust names are unique within a package.
        let mut by_package: BTreeMap<String, Vec<&StructDef>> = BTreeMap::new();
        for def in self.schema.structs() {
            by_package
                .entry(def.name.package.clone())
                .or_default()
                .push(def);
        }
        for defs in by_package.values() {
            let mut seen: BTreeMap<String, &QualifiedName> = BTreeMap::new();
            for def in defs {
                let rust_name = rust_type_name(&def.name.name);
                if let Some(prior) = seen.insert(rust_name.clone(), &def.name) {
                    return Err(GenerateError::NameCollision {
                        first: prior.to_string(),
                        second: def.name.to_string(),
                        rust_name,
                    });
                }
            }
        }

        // Emit nested modules for dotted packages; packages sorted so a prefix precedes its
        // children, which lets us open and close modules as a stack.
        let mut open: Vec<String> = Vec::new();
        for (package, defs) in &by_package {
            let segs = package_segments(package);
            let common = open.iter().zip(&segs).take_while(|(a, b)| a == b).count();
            while open.len() > common {
                open.pop();
                out.push_str("}\n");
            }
            for seg in &segs[common..] {
                let _ = writeln!(
                    out,
                    "/// LCM package `{}`.\npub mod {seg} {{",
                    segs[..=open.len()].join(".")
                );
                open.push(seg.clone());
            }
            for def in defs {
                self.emit_struct(&mut out, def)?;
            }
        }
        while open.pop().is_some() {
            out.push_str("}\n");
        }
        self.emit_any_message(&mut out);
        Ok(out)
    }

    /// Writes .lcm comments as rustdoc. Comments are plain text, not Markdown: characters
    /// rustdoc would read as links, HTML or emphasis are escaped, and indentation is dropped
    /// so that no line turns into a code block (which rustdoc would compile as a doctest).
    fn emit_doc(out: &mut String, indent: &str, doc: Option<&str>, fallback: &str) {
        let Some(text) = doc else {
            // The fallback is ours and already rustdoc Markdown.
            let _ = writeln!(out, "{indent}/// {fallback}");
            return;
        };
        for line in text.lines() {
            let line = line.trim();
            if line.is_empty() {
                let _ = writeln!(out, "{indent}///");
                continue;
            }
            let mut escaped = String::with_capacity(line.len());
            for c in line.chars() {
                match c {
                    '[' | ']' | '*' | '`' | '\\' | '#' | '_' => {
                        escaped.push('\\');
                        escaped.push(c);
                    }
                    '<' => escaped.push_str("&lt;"),
                    '>' => escaped.push_str("&gt;"),
                    '&' => escaped.push_str("&amp;"),
                    _ => escaped.push(c),
                }
            }
            let _ = writeln!(out, "{indent}/// {escaped}");
        }
    }

    fn emit_struct(&self, out: &mut String, def: &StructDef) -> Result<(), GenerateError> {
        let rt = &self.rt;
        let pkg = &def.name.package;
        let name = rust_type_name(&def.name.name);
        let lcm_name = def.name.to_string();
        let fingerprint =
            self.schema
                .fingerprint(&def.name)
                .ok_or_else(|| GenerateError::BadIdentifier {
                    owner: lcm_name.clone(),
                    name: def.name.name.clone(),
                })?;
        let base_hash = crate::fingerprint::base_hash(def);
        let min_len = self.schema.min_encoded_len(&def.name);

        Self::emit_doc(
            out,
            "",
            def.doc.as_deref(),
            &format!("LCM type `{lcm_name}`."),
        );
        let _ = writeln!(
            out,
            "///\n/// LCM type `{lcm_name}`, fingerprint `{fingerprint:#018x}`."
        );
        // std implements Default for arrays of up to 32 elements only.
        let derive_default = def
            .members
            .iter()
            .flat_map(|m| &m.dims)
            .all(|d| !matches!(d, Dimension::Const { size, .. } if *size > 32));
        if derive_default {
            out.push_str("#[derive(Debug, Clone, PartialEq, Default)]\n");
        } else {
            out.push_str("#[derive(Debug, Clone, PartialEq)]\n");
        }
        if self.options.serde {
            out.push_str("#[derive(::serde::Serialize, ::serde::Deserialize)]\n");
        }
        let _ = writeln!(out, "pub struct {name} {{");
        let mut field_names = HashSet::new();
        for m in &def.members {
            let field = rust_field_name(&m.name);
            if !field_names.insert(field.clone()) {
                return Err(GenerateError::BadIdentifier {
                    owner: lcm_name.clone(),
                    name: m.name.clone(),
                });
            }
            if self.options.serde {
                for d in &m.dims {
                    if let Dimension::Const { size, .. } = d {
                        if *size > 32 {
                            return Err(GenerateError::SerdeArrayTooLarge {
                                owner: lcm_name.clone(),
                                member: m.name.clone(),
                                size: *size,
                            });
                        }
                    }
                }
                if field.ends_with('_') && !m.name.ends_with('_') {
                    let _ = writeln!(out, "    #[serde(rename = \"{}\")]", m.name);
                }
            }
            Self::emit_doc(
                out,
                "    ",
                m.doc.as_deref(),
                &format!("LCM member `{}`.", m.name),
            );
            let elem = self.element_type(pkg, &m.ty);
            let _ = writeln!(out, "    pub {field}: {},", self.array_type(&elem, &m.dims));
        }
        out.push_str("}\n\n");

        // Constants.
        if !def.constants.is_empty() {
            let _ = writeln!(out, "impl {name} {{");
            for c in &def.constants {
                Self::emit_doc(
                    out,
                    "    ",
                    c.doc.as_deref(),
                    &format!("LCM constant `{}` = {}.", c.name, c.token),
                );
                let value = match c.value {
                    ConstValue::Int(v) => format!("{v}"),
                    ConstValue::Float(v) => format!("{v:?}"),
                    ConstValue::Double(v) => format!("{v:?}"),
                };
                let cname = rust_field_name(&c.name);
                let _ = writeln!(
                    out,
                    "    pub const {cname}: {} = {value};",
                    primitive_rust(c.ty)
                );
            }
            out.push_str("}\n\n");
        }

        if !derive_default {
            self.emit_default(out, def, &name);
        }

        // Message impl.
        let _ = writeln!(out, "impl {rt}::Message for {name} {{");
        let _ = writeln!(out, "    const TYPE_NAME: &'static str = \"{lcm_name}\";");
        let _ = writeln!(out, "    const FINGERPRINT: u64 = {fingerprint:#018x};");
        let _ = writeln!(out, "    const BASE_HASH: u64 = {base_hash:#018x};");
        let _ = writeln!(out, "    const MIN_ENCODED_LEN: usize = {min_len};\n");

        // encoded_len_one
        out.push_str("    fn encoded_len_one(&self) -> usize {\n");
        if def.members.is_empty() {
            out.push_str("        0\n");
        } else {
            out.push_str("        let mut len = 0usize;\n");
            for m in &def.members {
                self.emit_len_member(out, m);
            }
            out.push_str("        len\n");
        }
        out.push_str("    }\n\n");

        // encode_one
        let _ = writeln!(
            out,
            "    fn encode_one(&self, out: &mut ::std::vec::Vec<u8>) -> ::core::result::Result<(), {rt}::EncodeError> {{"
        );
        if def.members.is_empty() {
            out.push_str("        let _ = out;\n");
        }
        for m in &def.members {
            self.emit_encode_member(out, def, m);
        }
        out.push_str("        ::core::result::Result::Ok(())\n    }\n\n");

        // decode_one
        let _ = writeln!(
            out,
            "    fn decode_one(r: &mut {rt}::Reader<'_>) -> ::core::result::Result<Self, {rt}::DecodeError> {{"
        );
        out.push_str("        r.enter(Self::TYPE_NAME)?;\n");
        for m in &def.members {
            self.emit_decode_member(out, def, m);
        }
        out.push_str("        r.leave();\n        ::core::result::Result::Ok(Self {\n");
        for m in &def.members {
            let _ = writeln!(
                out,
                "            {}: f_{},",
                rust_field_name(&m.name),
                m.name
            );
        }
        out.push_str("        })\n    }\n}\n\n");
        Ok(())
    }

    fn emit_default(&self, out: &mut String, def: &StructDef, name: &str) {
        let _ = writeln!(out, "impl ::core::default::Default for {name} {{\n    fn default() -> Self {{\n        Self {{");
        for m in &def.members {
            let _ = writeln!(
                out,
                "            {}: {},",
                rust_field_name(&m.name),
                self.default_expr(&m.dims)
            );
        }
        out.push_str("        }\n    }\n}\n\n");
    }

    fn emit_len_member(&self, out: &mut String, m: &Member) {
        let field = Place::Field(format!("self.{}", rust_field_name(&m.name)));
        let mut code = String::new();
        self.len_level(&mut code, &field, &m.ty, &m.dims, 0, 2);
        out.push_str(&code);
    }

    fn len_level(
        &self,
        out: &mut String,
        expr: &Place,
        ty: &TypeRef,
        dims: &[Dimension],
        depth: usize,
        indent: usize,
    ) {
        let pad = "    ".repeat(indent);
        match (dims.split_first(), ty) {
            (None, TypeRef::Primitive(Primitive::String)) => {
                let _ = writeln!(out, "{pad}len += 5 + {}.len();", expr.place());
            }
            (None, TypeRef::Primitive(p)) => {
                let _ = writeln!(out, "{pad}len += {};", p.min_encoded_len());
            }
            (None, TypeRef::Struct(_)) => {
                let _ = writeln!(
                    out,
                    "{pad}len += {}::Message::encoded_len_one({});",
                    self.rt,
                    expr.reference()
                );
            }
            (Some(_), TypeRef::Primitive(p)) if dims.len() == 1 && *p != Primitive::String => {
                match p.min_encoded_len() {
                    1 => writeln!(out, "{pad}len += {}.len();", expr.place()),
                    size => writeln!(out, "{pad}len += {}.len() * {size};", expr.place()),
                }
                .unwrap_or(());
            }
            (Some((_, rest)), _) => {
                let var = format!("e{depth}");
                let _ = writeln!(out, "{pad}for {var} in {}.iter() {{", expr.place());
                self.len_level(out, &Place::Ref(var), ty, rest, depth + 1, indent + 1);
                let _ = writeln!(out, "{pad}}}");
            }
        }
    }

    fn emit_encode_member(&self, out: &mut String, def: &StructDef, m: &Member) {
        let rt = &self.rt;
        let field = rust_field_name(&m.name);
        if m.dims.is_empty() {
            out.push_str(&self.encode_scalar(&Place::Field(format!("self.{field}")), &m.ty, 2));
            return;
        }
        out.push_str("        {\n");
        for (level, dim) in m.dims.iter().enumerate() {
            if let Dimension::Var { member } = dim {
                let value = widen_to_i64(def, member, &format!("self.{}", rust_field_name(member)));
                let _ = writeln!(
                    out,
                    "            let d{level} = {rt}::encode_dim({value}, Self::TYPE_NAME, \"{member}\")?;"
                );
            }
        }
        let mut code = String::new();
        self.encode_level(&mut code, m, &Place::Field(format!("self.{field}")), 0, 3);
        out.push_str(&code);
        out.push_str("        }\n");
    }

    fn encode_level(
        &self,
        out: &mut String,
        m: &Member,
        expr: &Place,
        level: usize,
        indent: usize,
    ) {
        let rt = &self.rt;
        let pad = "    ".repeat(indent);
        if level == m.dims.len() {
            out.push_str(&self.encode_scalar(expr, &m.ty, indent));
            return;
        }
        if let Dimension::Var { .. } = m.dims[level] {
            let _ = writeln!(
                out,
                "{pad}{rt}::check_len({}.len(), d{level}, Self::TYPE_NAME, \"{}\")?;",
                expr.place(),
                m.name
            );
        }
        let innermost = level + 1 == m.dims.len();
        match m.ty {
            TypeRef::Primitive(Primitive::Byte) if innermost => {
                let _ = writeln!(out, "{pad}out.extend_from_slice(&{}[..]);", expr.place());
                return;
            }
            TypeRef::Primitive(p) if innermost && p != Primitive::String => {
                let _ = writeln!(out, "{pad}{rt}::put_slice(&{}[..], out);", expr.place());
                return;
            }
            _ => {}
        }
        let var = format!("e{level}");
        let _ = writeln!(out, "{pad}for {var} in {}.iter() {{", expr.place());
        self.encode_level(out, m, &Place::Ref(var), level + 1, indent + 1);
        let _ = writeln!(out, "{pad}}}");
    }

    fn encode_scalar(&self, expr: &Place, ty: &TypeRef, indent: usize) -> String {
        let rt = &self.rt;
        let pad = "    ".repeat(indent);
        match ty {
            TypeRef::Primitive(Primitive::String) => {
                format!("{pad}{rt}::put_string(out, {})?;\n", expr.reference())
            }
            TypeRef::Primitive(_) => {
                format!("{pad}{rt}::WirePrimitive::put({}, out);\n", expr.value())
            }
            TypeRef::Struct(_) => {
                format!(
                    "{pad}{rt}::Message::encode_one({}, out)?;\n",
                    expr.reference()
                )
            }
        }
    }

    fn decode_scalar(&self, pkg: &str, ty: &TypeRef) -> String {
        let rt = &self.rt;
        match ty {
            TypeRef::Primitive(Primitive::String) => "r.read_string()?".to_string(),
            TypeRef::Primitive(p) => format!("r.read_prim::<{}>()?", primitive_rust(*p)),
            TypeRef::Struct(name) => format!(
                "<{} as {rt}::Message>::decode_one(r)?",
                self.struct_path(pkg, name)
            ),
        }
    }

    fn emit_decode_member(&self, out: &mut String, def: &StructDef, m: &Member) {
        let pkg = &def.name.package;
        if m.dims.is_empty() {
            let _ = writeln!(
                out,
                "        let f_{} = {};",
                m.name,
                self.decode_scalar(pkg, &m.ty)
            );
            return;
        }
        let _ = writeln!(out, "        let f_{} = {{", m.name);
        let mut dims = Vec::new();
        for dim in &m.dims {
            match dim {
                Dimension::Const { size, .. } => dims.push(format!("{size}usize")),
                Dimension::Var { member } => dims.push(format!(
                    "r.decode_dim({}, Self::TYPE_NAME, \"{member}\")?",
                    widen_to_i64(def, member, &format!("f_{member}"))
                )),
            }
        }
        let _ = writeln!(
            out,
            "            let dims: [usize; {}] = [{}];",
            dims.len(),
            dims.join(", ")
        );
        let _ = writeln!(
            out,
            "            r.check_array(&dims, {}, Self::TYPE_NAME, \"{}\")?;",
            self.elem_min_len(&m.ty),
            m.name
        );
        let elem = self.element_type(pkg, &m.ty);
        let mut code = String::new();
        self.decode_level(&mut code, pkg, m, &elem, 0, 3);
        out.push_str(&code);
        out.push_str("        };\n");
    }

    /// Writes an expression (as statements ending in a value) building `dims[level..]`.
    fn decode_level(
        &self,
        out: &mut String,
        pkg: &str,
        m: &Member,
        elem: &str,
        level: usize,
        indent: usize,
    ) {
        let pad = "    ".repeat(indent);
        let rest = &m.dims[level + 1..];
        let inner_is_scalar = rest.is_empty();
        let fast_prim = match m.ty {
            TypeRef::Primitive(p) if inner_is_scalar && p != Primitive::String => Some(p),
            _ => None,
        };
        match (&m.dims[level], fast_prim) {
            (Dimension::Var { .. }, Some(p)) => {
                let _ = writeln!(
                    out,
                    "{pad}r.read_prim_vec::<{}>(dims[{level}])?",
                    primitive_rust(p)
                );
            }
            (Dimension::Var { .. }, None) => {
                let _ = writeln!(out, "{pad}{{");
                let _ = writeln!(
                    out,
                    "{pad}    let mut v = ::std::vec::Vec::with_capacity(dims[{level}]);"
                );
                let _ = writeln!(out, "{pad}    for _ in 0..dims[{level}] {{");
                let _ = writeln!(out, "{pad}        v.push({{");
                self.decode_inner(out, pkg, m, elem, level, indent + 3);
                let _ = writeln!(out, "{pad}        }});");
                let _ = writeln!(out, "{pad}    }}");
                let _ = writeln!(out, "{pad}    v");
                let _ = writeln!(out, "{pad}}}");
            }
            (Dimension::Const { .. }, _) => {
                let ty = self.array_type(elem, &m.dims[level..]);
                let _ = writeln!(out, "{pad}{{");
                let _ = writeln!(
                    out,
                    "{pad}    let mut a: {ty} = {};",
                    self.default_expr(&m.dims[level..])
                );
                let _ = writeln!(out, "{pad}    for slot in a.iter_mut() {{");
                let _ = writeln!(out, "{pad}        *slot = {{");
                self.decode_inner(out, pkg, m, elem, level, indent + 3);
                let _ = writeln!(out, "{pad}        }};");
                let _ = writeln!(out, "{pad}    }}");
                let _ = writeln!(out, "{pad}    a");
                let _ = writeln!(out, "{pad}}}");
            }
        }
    }

    fn decode_inner(
        &self,
        out: &mut String,
        pkg: &str,
        m: &Member,
        elem: &str,
        level: usize,
        indent: usize,
    ) {
        if level + 1 == m.dims.len() {
            let pad = "    ".repeat(indent);
            let _ = writeln!(out, "{pad}{}", self.decode_scalar(pkg, &m.ty));
        } else {
            self.decode_level(out, pkg, m, elem, level + 1, indent);
        }
    }

    fn emit_any_message(&self, out: &mut String) {
        let rt = &self.rt;
        let defs: Vec<&StructDef> = self.schema.structs().collect();
        // Variants are the Rust type names; only a name used in two packages gets the package
        // prepended (`a.b.x_t` → `ABX`).
        let mut name_uses: BTreeMap<String, usize> = BTreeMap::new();
        for def in &defs {
            *name_uses.entry(rust_type_name(&def.name.name)).or_default() += 1;
        }
        let variant = |def: &StructDef| -> String {
            let short = rust_type_name(&def.name.name);
            if name_uses.get(&short) == Some(&1) {
                return short;
            }
            let mut v: String = package_segments(&def.name.package)
                .iter()
                .map(|s| rust_type_name(s.trim_start_matches("r#")))
                .collect();
            v.push_str(&short);
            v
        };
        out.push_str(
            "/// Any message of this schema, identified on the wire by its fingerprint.\n",
        );
        out.push_str("#[derive(Debug, Clone, PartialEq)]\n");
        if self.options.serde {
            out.push_str("#[derive(::serde::Serialize, ::serde::Deserialize)]\n#[serde(tag = \"type\", content = \"value\")]\n");
        }
        // Variants hold the schema's structs by value, like lcm-gen's classes; whichever type has
        // large fixed-size arrays is the schema's choice, so the size lint does not apply here.
        out.push_str("#[allow(clippy::large_enum_variant)]\n");
        out.push_str("pub enum AnyMessage {\n");
        for def in &defs {
            let _ = writeln!(out, "    /// `{}`", def.name);
            if self.options.serde {
                let _ = writeln!(out, "    #[serde(rename = \"{}\")]", def.name);
            }
            let _ = writeln!(
                out,
                "    {}({}),",
                variant(def),
                self.struct_path("", &def.name)
            );
        }
        out.push_str("}\n\n");
        out.push_str("/// LCM names (`package.type`) of every type of this schema.\npub const TYPE_NAMES: &[&str] = &[\n");
        for def in &defs {
            let _ = writeln!(out, "    \"{}\",", def.name);
        }
        out.push_str("];\n\n");
        out.push_str("/// `(package.type, fingerprint)` of every type of this schema.\npub const FINGERPRINTS: &[(&str, u64)] = &[\n");
        for def in &defs {
            let path = self.struct_path("", &def.name);
            let _ = writeln!(
                out,
                "    (\"{}\", <{path} as {rt}::Message>::FINGERPRINT),",
                def.name
            );
        }
        out.push_str("];\n\n");
        out.push_str("impl AnyMessage {\n");
        out.push_str(
            "    /// Decodes a message of any type of this schema, chosen by its fingerprint.\n",
        );
        let _ = writeln!(out, "    pub fn decode_with_limits(buf: &[u8], limits: &{rt}::DecodeLimits) -> ::core::result::Result<Self, {rt}::DecodeError> {{");
        let _ = writeln!(
            out,
            "        let fingerprint = {rt}::peek_fingerprint(buf)?;"
        );
        for def in &defs {
            let path = self.struct_path("", &def.name);
            let _ = writeln!(
                out,
                "        if fingerprint == <{path} as {rt}::Message>::FINGERPRINT {{\n            return <{path} as {rt}::Message>::decode_with_limits(buf, limits).map(Self::{});\n        }}",
                variant(def)
            );
        }
        let _ = writeln!(out, "        ::core::result::Result::Err({rt}::DecodeError::UnknownFingerprint {{ found: fingerprint }})\n    }}\n");
        let _ = writeln!(out, "    /// [`Self::decode_with_limits`] with the default limits.\n    pub fn decode(buf: &[u8]) -> ::core::result::Result<Self, {rt}::DecodeError> {{\n        Self::decode_with_limits(buf, &{rt}::DecodeLimits::default())\n    }}\n");
        let _ = writeln!(out, "    /// Fingerprint followed by the encoding of the message.\n    pub fn encode(&self) -> ::core::result::Result<::std::vec::Vec<u8>, {rt}::EncodeError> {{\n        match self {{");
        for def in &defs {
            let _ = writeln!(
                out,
                "            Self::{}(m) => {rt}::Message::encode(m),",
                variant(def)
            );
        }
        out.push_str("        }\n    }\n\n");
        out.push_str("    /// A default-valued message of the named type (`package.type`).\n    pub fn default_for(type_name: &str) -> ::core::option::Option<Self> {\n        match type_name {\n");
        for def in &defs {
            let _ = writeln!(
                out,
                "            \"{}\" => ::core::option::Option::Some(Self::{}(::core::default::Default::default())),",
                def.name,
                variant(def)
            );
        }
        out.push_str("            _ => ::core::option::Option::None,\n        }\n    }\n\n");
        out.push_str("    /// LCM name (`package.type`) of the message's type.\n    pub fn type_name(&self) -> &'static str {\n        match self {\n");
        for def in &defs {
            let path = self.struct_path("", &def.name);
            let _ = writeln!(
                out,
                "            Self::{}(_) => <{path} as {rt}::Message>::TYPE_NAME,",
                variant(def)
            );
        }
        out.push_str("        }\n    }\n}\n");
    }
}

/// Generates the Rust source of every struct in `schema`.
pub fn generate(schema: &Schema, options: &RustOptions) -> Result<String, GenerateError> {
    let generator = Generator {
        schema,
        options,
        rt: options.runtime_path.trim_end_matches("::").to_string(),
    };
    generator.generate()
}

#[cfg(test)]
mod tests {
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
}
