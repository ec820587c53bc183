//! The schema-wide `AnyMessage` enum and name/fingerprint tables, which dispatch on the wire
//! fingerprint and so need every struct of the schema at once.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use super::naming::{package_segments, rust_type_name};
use super::Generator;
use crate::parse::StructDef;

impl Generator<'_> {
    pub(super) fn emit_any_message(&self, out: &mut String) {
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
