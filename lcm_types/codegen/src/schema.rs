//! The set of all structs of a code generation run, checked as a whole.

use std::collections::{BTreeMap, HashSet};

use crate::fingerprint;
use crate::parse::{ParsedFile, QualifiedName, StructDef, TypeRef};

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SchemaError {
    #[error("type {name} is declared twice: in {first} and in {second}")]
    DuplicateType {
        name: String,
        first: String,
        second: String,
    },
    #[error("{file}:{line}: member '{member}' of {owner} has unknown type {ty}")]
    UnknownType {
        file: String,
        line: usize,
        owner: String,
        member: String,
        ty: String,
    },
    #[error("type {name} contains itself without a variable-length array in between: its size would be infinite")]
    InfiniteSize { name: String },
}

/// All structs, by fully qualified name, with every member type resolved.
#[derive(Debug, Clone)]
pub struct Schema {
    structs: BTreeMap<QualifiedName, StructDef>,
}

impl Schema {
    pub fn new(files: Vec<ParsedFile>) -> Result<Schema, SchemaError> {
        let mut structs: BTreeMap<QualifiedName, StructDef> = BTreeMap::new();
        for file in files {
            for def in file.structs {
                if let Some(prior) = structs.get(&def.name) {
                    return Err(SchemaError::DuplicateType {
                        name: def.name.to_string(),
                        first: prior.file.clone(),
                        second: def.file.clone(),
                    });
                }
                structs.insert(def.name.clone(), def);
            }
        }
        let schema = Schema { structs };
        for def in schema.structs.values() {
            for member in &def.members {
                if let TypeRef::Struct(ty) = &member.ty {
                    if !schema.structs.contains_key(ty) {
                        return Err(SchemaError::UnknownType {
                            file: def.file.clone(),
                            line: member.line,
                            owner: def.name.to_string(),
                            member: member.name.clone(),
                            ty: ty.to_string(),
                        });
                    }
                }
            }
        }
        for name in schema.structs.keys() {
            schema.check_finite(name, &mut Vec::new())?;
        }
        Ok(schema)
    }

    /// A struct must not reach itself through members that are scalars or fixed arrays only.
    fn check_finite(
        &self,
        name: &QualifiedName,
        path: &mut Vec<QualifiedName>,
    ) -> Result<(), SchemaError> {
        if path.contains(name) {
            return Err(SchemaError::InfiniteSize {
                name: name.to_string(),
            });
        }
        let Some(def) = self.structs.get(name) else {
            return Ok(());
        };
        path.push(name.clone());
        for member in &def.members {
            let has_var_dim = member
                .dims
                .iter()
                .any(|d| matches!(d, crate::parse::Dimension::Var { .. }));
            if let (TypeRef::Struct(child), false) = (&member.ty, has_var_dim) {
                self.check_finite(child, path)?;
            }
        }
        path.pop();
        Ok(())
    }

    pub fn get(&self, name: &QualifiedName) -> Option<&StructDef> {
        self.structs.get(name)
    }

    /// Structs in a stable order (by package, then name).
    pub fn structs(&self) -> impl Iterator<Item = &StructDef> {
        self.structs.values()
    }

    /// Distinct packages in a stable order.
    pub fn packages(&self) -> Vec<String> {
        let mut seen = HashSet::new();
        self.structs
            .keys()
            .filter(|k| seen.insert(k.package.clone()))
            .map(|k| k.package.clone())
            .collect()
    }

    /// The wire fingerprint of `name` (see [`fingerprint::fingerprint`]).
    pub fn fingerprint(&self, name: &QualifiedName) -> Option<u64> {
        fingerprint::fingerprint(&|n| self.get(n), name)
    }

    /// The fewest bytes an encoding of `name` (without fingerprint) can take; variable-length
    /// arrays count as empty. Used by decoders to reject length fields the buffer cannot hold.
    pub fn min_encoded_len(&self, name: &QualifiedName) -> usize {
        let Some(def) = self.structs.get(name) else {
            return 0;
        };
        let mut total = 0usize;
        for member in &def.members {
            let mut count = 1usize;
            for dim in &member.dims {
                match dim {
                    crate::parse::Dimension::Const { size, .. } => {
                        count = count.saturating_mul(*size)
                    }
                    crate::parse::Dimension::Var { .. } => count = 0,
                }
            }
            if count == 0 {
                continue;
            }
            let element = match &member.ty {
                TypeRef::Primitive(p) => p.min_encoded_len(),
                // Schema::new rejected cycles without a variable dimension, so this terminates.
                TypeRef::Struct(child) => self.min_encoded_len(child),
            };
            total = total.saturating_add(count.saturating_mul(element));
        }
        total
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parse::parse_str;

    fn parse(src: &str) -> ParsedFile {
        parse_str(src, "t.lcm").unwrap()
    }

    #[test]
    fn rejects_unknown_duplicate_and_infinite_types() {
        let err = Schema::new(vec![parse("struct a_t { b_t x; }")]).unwrap_err();
        assert!(matches!(err, SchemaError::UnknownType { .. }), "{err}");
        let err = Schema::new(vec![
            parse("struct a_t { int8_t x; }"),
            parse("struct a_t { int8_t y; }"),
        ])
        .unwrap_err();
        assert!(matches!(err, SchemaError::DuplicateType { .. }), "{err}");
        let err = Schema::new(vec![parse(
            "struct a_t { b_t x[2]; } struct b_t { a_t y; }",
        )])
        .unwrap_err();
        assert!(matches!(err, SchemaError::InfiniteSize { .. }), "{err}");
        assert!(Schema::new(vec![parse("struct a_t { int8_t n; a_t y[n]; }")]).is_ok());
    }

    #[test]
    fn min_encoded_len_counts_fixed_parts_only() {
        let s = Schema::new(vec![parse(
            "struct in_t { int16_t a; string s; } struct out_t { int32_t n; double v[n]; in_t x[3]; float f[2][2]; boolean b; }",
        )])
        .unwrap();
        let out = QualifiedName {
            package: String::new(),
            name: "out_t".into(),
        };
        // 4 (n) + 0 (v) + 3 * (2 + 5) + 4 * 4 + 1
        assert_eq!(s.min_encoded_len(&out), 4 + 21 + 16 + 1);
    }
}
