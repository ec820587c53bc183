//! Tokenizer and recursive-descent parser of the LCM type language.
//!
//! Follows `lcmgen.c`: a file is a sequence of `package NAME;` directives and
//! `struct NAME { ... }` blocks; a struct holds members (`TYPE name[dim]..., name2...;`) and
//! constants (`const TYPE NAME = VALUE, ...;`). A variable array dimension must name an earlier
//! integer member of the same struct. Comments directly above a struct, member or constant
//! become its documentation. Enums (deprecated in LCM) are rejected.
//!
//! This module holds the syntax tree the rest of the crate consumes; the text-level work is split
//! off so the tree can be read without the tokenizer (`lexer`) or the grammar (`parser`).

mod lexer;
mod parser;

#[cfg(test)]
mod tests;

use std::fmt;

pub use lexer::parse_c_integer;
pub use parser::parse_str;

/// The built-in LCM types.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Primitive {
    Int8,
    Int16,
    Int32,
    Int64,
    Byte,
    Float,
    Double,
    String,
    Boolean,
}

impl Primitive {
    /// The LCM spelling, which is also what the fingerprint hashes.
    pub fn lcm_name(self) -> &'static str {
        match self {
            Primitive::Int8 => "int8_t",
            Primitive::Int16 => "int16_t",
            Primitive::Int32 => "int32_t",
            Primitive::Int64 => "int64_t",
            Primitive::Byte => "byte",
            Primitive::Float => "float",
            Primitive::Double => "double",
            Primitive::String => "string",
            Primitive::Boolean => "boolean",
        }
    }

    pub fn from_lcm_name(name: &str) -> Option<Primitive> {
        Some(match name {
            "int8_t" => Primitive::Int8,
            "int16_t" => Primitive::Int16,
            "int32_t" => Primitive::Int32,
            "int64_t" => Primitive::Int64,
            "byte" => Primitive::Byte,
            "float" => Primitive::Float,
            "double" => Primitive::Double,
            "string" => Primitive::String,
            "boolean" => Primitive::Boolean,
            _ => return None,
        })
    }

    /// Types lcm-gen accepts as variable array dimensions.
    pub fn is_array_dimension_type(self) -> bool {
        matches!(
            self,
            Primitive::Int8 | Primitive::Int16 | Primitive::Int32 | Primitive::Int64
        )
    }

    /// Types lcm-gen accepts for `const`.
    pub fn is_const_type(self) -> bool {
        matches!(
            self,
            Primitive::Int8
                | Primitive::Int16
                | Primitive::Int32
                | Primitive::Int64
                | Primitive::Float
                | Primitive::Double
        )
    }

    /// Encoded size in bytes; for strings the minimum (length prefix + NUL).
    pub fn min_encoded_len(self) -> usize {
        match self {
            Primitive::Int8 | Primitive::Byte | Primitive::Boolean => 1,
            Primitive::Int16 => 2,
            Primitive::Int32 | Primitive::Float => 4,
            Primitive::Int64 | Primitive::Double => 8,
            Primitive::String => 5,
        }
    }
}

/// The type of a member: a primitive or a struct named by its fully qualified LCM name.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum TypeRef {
    Primitive(Primitive),
    Struct(QualifiedName),
}

/// `package.name` of a struct; `package` may be empty or contain dots.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct QualifiedName {
    pub package: String,
    pub name: String,
}

impl fmt::Display for QualifiedName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.package.is_empty() {
            f.write_str(&self.name)
        } else {
            write!(f, "{}.{}", self.package, self.name)
        }
    }
}

/// One array dimension.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Dimension {
    /// Fixed size; `token` is the text as written (it is what the fingerprint hashes).
    Const { token: String, size: usize },
    /// Size given at run time by an earlier integer member.
    Var { member: String },
}

impl Dimension {
    /// lcm-gen's `lcm_array_mode_t` value (LCM_CONST = 0, LCM_VAR = 1), hashed into fingerprints.
    pub fn mode(&self) -> u8 {
        match self {
            Dimension::Const { .. } => 0,
            Dimension::Var { .. } => 1,
        }
    }

    /// The size string hashed into fingerprints.
    pub fn size_token(&self) -> &str {
        match self {
            Dimension::Const { token, .. } => token,
            Dimension::Var { member } => member,
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Member {
    pub name: String,
    pub ty: TypeRef,
    pub dims: Vec<Dimension>,
    pub doc: Option<String>,
    pub line: usize,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ConstValue {
    Int(i64),
    Float(f32),
    Double(f64),
}

#[derive(Debug, Clone, PartialEq)]
pub struct Constant {
    pub name: String,
    pub ty: Primitive,
    /// The value as written in the file.
    pub token: String,
    pub value: ConstValue,
    pub doc: Option<String>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct StructDef {
    pub name: QualifiedName,
    pub doc: Option<String>,
    pub constants: Vec<Constant>,
    pub members: Vec<Member>,
    /// File the struct was declared in (for error messages).
    pub file: String,
    pub line: usize,
}

impl StructDef {
    pub fn member(&self, name: &str) -> Option<&Member> {
        self.members.iter().find(|m| m.name == name)
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct ParsedFile {
    pub file: String,
    pub structs: Vec<StructDef>,
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{file}:{line}: {message}")]
pub struct ParseError {
    pub file: String,
    pub line: usize,
    pub message: String,
}
