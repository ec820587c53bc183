//! Bodies of `encoded_len_one`, `encode_one` and `decode_one`, member by member. Kept apart from
//! the declarations because this is the part whose output must stay byte-compatible with lcm-gen.

use std::fmt::Write as _;

use super::naming::{primitive_rust, rust_field_name};
use super::Generator;
use crate::parse::{Dimension, Member, Primitive, StructDef, TypeRef};

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

impl Generator<'_> {
    pub(super) fn emit_len_member(&self, out: &mut String, m: &Member) {
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

    pub(super) fn emit_encode_member(&self, out: &mut String, def: &StructDef, m: &Member) {
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

    pub(super) fn emit_decode_member(&self, out: &mut String, def: &StructDef, m: &Member) {
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
}
