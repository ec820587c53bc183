//! Struct declarations: fields, docs, constants, `Default` and the `Message` impl skeleton, plus
//! the type-spelling helpers the codec emitters reuse so both agree on every Rust type.

use std::collections::HashSet;
use std::fmt::Write as _;

use super::naming::{package_segments, primitive_rust, rust_field_name, rust_type_name};
use super::{GenerateError, Generator};
use crate::parse::{ConstValue, Dimension, QualifiedName, StructDef, TypeRef};

impl Generator<'_> {
    /// Path from the module of package `from` to struct `to`.
    pub(super) fn struct_path(&self, from: &str, to: &QualifiedName) -> String {
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

    pub(super) fn element_type(&self, from: &str, ty: &TypeRef) -> String {
        match ty {
            TypeRef::Primitive(p) => primitive_rust(*p).to_string(),
            TypeRef::Struct(name) => self.struct_path(from, name),
        }
    }

    /// Rust type of `dims[level..]` of elements `elem`.
    pub(super) fn array_type(&self, elem: &str, dims: &[Dimension]) -> String {
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

    pub(super) fn default_expr(&self, dims: &[Dimension]) -> String {
        match dims.split_first() {
            Some((Dimension::Const { .. }, rest)) => {
                format!("::core::array::from_fn(|_| {})", self.default_expr(rest))
            }
            _ => "::core::default::Default::default()".to_string(),
        }
    }

    pub(super) fn elem_min_len(&self, ty: &TypeRef) -> usize {
        match ty {
            TypeRef::Primitive(p) => p.min_encoded_len(),
            TypeRef::Struct(name) => self.schema.min_encoded_len(name),
        }
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

    pub(super) fn emit_struct(
        &self,
        out: &mut String,
        def: &StructDef,
    ) -> Result<(), GenerateError> {
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
}
