//! Recursive-descent parser over the token stream: packages, structs, members, constants and
//! array dimensions, with the same acceptance rules (and error wording) as `lcmgen.c`.

use super::lexer::{parse_c_integer, tokenize, Token, TokenKind};
use super::{
    ConstValue, Constant, Dimension, Member, ParseError, ParsedFile, Primitive, QualifiedName,
    StructDef, TypeRef,
};

fn is_legal_name(name: &str) -> bool {
    let mut chars = name.chars();
    match chars.next() {
        Some(c) if c.is_ascii_alphabetic() || c == '_' => {}
        _ => return false,
    }
    chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

fn is_legal_type_name(name: &str) -> bool {
    !name.is_empty() && name.split('.').all(is_legal_name)
}

struct Parser<'a> {
    tokens: Vec<Token>,
    pos: usize,
    file: &'a str,
    package: String,
    pending_doc: Option<String>,
}

impl<'a> Parser<'a> {
    fn error(&self, line: usize, message: impl Into<String>) -> ParseError {
        ParseError {
            file: self.file.to_string(),
            line,
            message: message.into(),
        }
    }

    fn current_line(&self) -> usize {
        self.tokens
            .get(self.pos)
            .or_else(|| self.tokens.last())
            .map_or(1, |t| t.line)
    }

    /// Skips comments; with `keep`, gathers them as the documentation of what follows.
    fn skip_comments(&mut self, keep: bool) {
        let mut doc: Vec<String> = Vec::new();
        while let Some(tok) = self.tokens.get(self.pos) {
            if tok.kind != TokenKind::Comment {
                break;
            }
            doc.push(tok.text.clone());
            self.pos += 1;
        }
        if keep && !doc.is_empty() {
            self.pending_doc = Some(doc.join("\n"));
        }
    }

    fn next(&mut self, what: &str) -> Result<Token, ParseError> {
        self.skip_comments(false);
        let line = self.current_line();
        let tok = self
            .tokens
            .get(self.pos)
            .cloned()
            .ok_or_else(|| self.error(line, format!("end of file, expected {what}")))?;
        self.pos += 1;
        Ok(tok)
    }

    fn peek_is(&mut self, text: &str) -> bool {
        self.skip_comments(false);
        self.tokens
            .get(self.pos)
            .is_some_and(|t| t.kind != TokenKind::Comment && t.text == text)
    }

    fn try_consume(&mut self, text: &str) -> bool {
        let found = self.peek_is(text);
        if found {
            self.pos += 1;
        }
        found
    }

    fn require(&mut self, text: &str) -> Result<(), ParseError> {
        let tok = self.next(&format!("'{text}'"))?;
        if tok.text != text {
            return Err(self.error(tok.line, format!("expected '{text}', found '{}'", tok.text)));
        }
        Ok(())
    }

    fn word(&mut self, what: &str) -> Result<Token, ParseError> {
        let tok = self.next(what)?;
        if tok.kind != TokenKind::Word {
            return Err(self.error(tok.line, format!("expected {what}, found '{}'", tok.text)));
        }
        Ok(tok)
    }

    fn qualify(&self, name: &str) -> QualifiedName {
        match name.rsplit_once('.') {
            Some((package, short)) => QualifiedName {
                package: package.to_string(),
                name: short.to_string(),
            },
            None => QualifiedName {
                package: self.package.clone(),
                name: name.to_string(),
            },
        }
    }

    fn parse_file(mut self) -> Result<ParsedFile, ParseError> {
        let mut structs: Vec<StructDef> = Vec::new();
        loop {
            self.pending_doc = None;
            self.skip_comments(true);
            if self.pos >= self.tokens.len() {
                break;
            }
            let tok = self.word("'package' or 'struct'")?;
            match tok.text.as_str() {
                "package" => {
                    let name = self.word("package name")?;
                    if !is_legal_type_name(&name.text) {
                        return Err(
                            self.error(name.line, format!("invalid package name '{}'", name.text))
                        );
                    }
                    self.package = name.text;
                    self.require(";")?;
                }
                "struct" => {
                    let def = self.parse_struct(tok.line)?;
                    if structs.iter().any(|s| s.name == def.name) {
                        return Err(self.error(tok.line, format!("duplicate type {}", def.name)));
                    }
                    structs.push(def);
                }
                "enum" => {
                    return Err(self.error(
                        tok.line,
                        "enums are not supported (deprecated in LCM); use int constants",
                    ))
                }
                other => {
                    return Err(self.error(
                        tok.line,
                        format!("expected 'package' or 'struct', found '{other}'"),
                    ))
                }
            }
        }
        Ok(ParsedFile {
            file: self.file.to_string(),
            structs,
        })
    }

    fn parse_struct(&mut self, line: usize) -> Result<StructDef, ParseError> {
        let doc = self.pending_doc.take();
        let name_tok = self.word("struct name")?;
        if !is_legal_type_name(&name_tok.text) {
            return Err(self.error(
                name_tok.line,
                format!("invalid struct name '{}'", name_tok.text),
            ));
        }
        let mut def = StructDef {
            name: self.qualify(&name_tok.text),
            doc,
            constants: Vec::new(),
            members: Vec::new(),
            file: self.file.to_string(),
            line,
        };
        self.require("{")?;
        loop {
            self.pending_doc = None;
            self.skip_comments(true);
            if self.try_consume("}") {
                break;
            }
            if self.try_consume("const") {
                self.parse_const(&mut def)?;
            } else {
                self.parse_member(&mut def)?;
            }
        }
        Ok(def)
    }

    fn check_new_name(&self, def: &StructDef, tok: &Token) -> Result<(), ParseError> {
        if !is_legal_name(&tok.text) {
            return Err(self.error(
                tok.line,
                format!(
                    "invalid name '{}': must match [a-zA-Z_][a-zA-Z0-9_]*",
                    tok.text
                ),
            ));
        }
        if def.member(&tok.text).is_some() || def.constants.iter().any(|c| c.name == tok.text) {
            return Err(self.error(tok.line, format!("duplicate member name '{}'", tok.text)));
        }
        Ok(())
    }

    fn parse_const(&mut self, def: &mut StructDef) -> Result<(), ParseError> {
        let ty_tok = self.word("constant type")?;
        let ty = Primitive::from_lcm_name(&ty_tok.text)
            .filter(|p| p.is_const_type())
            .ok_or_else(|| {
                self.error(
                    ty_tok.line,
                    format!("invalid type for const: '{}'", ty_tok.text),
                )
            })?;
        loop {
            let doc = self.pending_doc.take();
            let name = self.word("constant name")?;
            self.check_new_name(def, &name)?;
            self.require("=")?;
            let value_tok = self.word("constant value")?;
            let value = const_value(ty, &value_tok.text).map_err(|msg| {
                self.error(value_tok.line, format!("constant {}: {msg}", name.text))
            })?;
            def.constants.push(Constant {
                name: name.text,
                ty,
                token: value_tok.text,
                value,
                doc,
            });
            if !self.try_consume(",") {
                break;
            }
        }
        self.require(";")
    }

    fn parse_member(&mut self, def: &mut StructDef) -> Result<(), ParseError> {
        let ty_tok = self.word("type name")?;
        if !is_legal_type_name(&ty_tok.text) {
            return Err(self.error(ty_tok.line, format!("invalid type name '{}'", ty_tok.text)));
        }
        if ty_tok.text == "struct" || ty_tok.text == "enum" {
            return Err(self.error(ty_tok.line, "nested type declarations are not supported"));
        }
        let ty = match Primitive::from_lcm_name(&ty_tok.text) {
            Some(p) => TypeRef::Primitive(p),
            None => TypeRef::Struct(self.qualify(&ty_tok.text)),
        };
        loop {
            let doc = self.pending_doc.take();
            let name = self.word("member name")?;
            self.check_new_name(def, &name)?;
            let mut dims = Vec::new();
            while self.try_consume("[") {
                let size = self.word("array size")?;
                dims.push(self.dimension(def, &size)?);
                self.require("]")?;
            }
            def.members.push(Member {
                name: name.text,
                ty: ty.clone(),
                dims,
                doc,
                line: name.line,
            });
            if !self.try_consume(",") {
                break;
            }
        }
        self.require(";")
    }

    fn dimension(&self, def: &StructDef, tok: &Token) -> Result<Dimension, ParseError> {
        if tok.text.starts_with(|c: char| c.is_ascii_digit()) {
            let size = parse_c_integer(&tok.text)
                .filter(|&v| v > 0 && v <= i64::from(i32::MAX))
                .ok_or_else(|| {
                    self.error(
                        tok.line,
                        format!(
                            "constant array size must be an integer in 1..=2^31-1, found '{}'",
                            tok.text
                        ),
                    )
                })?;
            let size = usize::try_from(size)
                .map_err(|_| self.error(tok.line, "array size does not fit in usize"))?;
            return Ok(Dimension::Const {
                token: tok.text.clone(),
                size,
            });
        }
        if !is_legal_name(&tok.text) {
            return Err(self.error(tok.line, format!("invalid array size '{}'", tok.text)));
        }
        let sizer = def.member(&tok.text).ok_or_else(|| {
            self.error(
                tok.line,
                format!(
                    "unknown array size member '{}': it must be declared before the array",
                    tok.text
                ),
            )
        })?;
        let is_integer = matches!(sizer.ty, TypeRef::Primitive(p) if p.is_array_dimension_type());
        if !sizer.dims.is_empty() || !is_integer {
            return Err(self.error(
                tok.line,
                format!(
                    "array size member '{}' must be a scalar int8_t/int16_t/int32_t/int64_t",
                    tok.text
                ),
            ));
        }
        Ok(Dimension::Var {
            member: tok.text.clone(),
        })
    }
}

fn const_value(ty: Primitive, token: &str) -> Result<ConstValue, String> {
    let int_in = |lo: i64, hi: i64| -> Result<ConstValue, String> {
        let v = parse_c_integer(token)
            .ok_or_else(|| format!("expected an integer, found '{token}'"))?;
        if v < lo || v > hi {
            return Err(format!("value {v} out of range for {}", ty.lcm_name()));
        }
        Ok(ConstValue::Int(v))
    };
    match ty {
        Primitive::Int8 => int_in(i8::MIN.into(), i8::MAX.into()),
        Primitive::Int16 => int_in(i16::MIN.into(), i16::MAX.into()),
        Primitive::Int32 => int_in(i32::MIN.into(), i32::MAX.into()),
        Primitive::Int64 => int_in(i64::MIN, i64::MAX),
        Primitive::Float | Primitive::Double => {
            let v: f64 = token
                .parse()
                .map_err(|_| format!("expected a floating-point number, found '{token}'"))?;
            if !v.is_finite() {
                return Err(format!("constant must be finite, found '{token}'"));
            }
            if ty == Primitive::Float {
                if v.abs() > f64::from(f32::MAX) {
                    return Err(format!("value {v} out of range for float"));
                }
                // lcm-gen stores `(float)strtod(...)`: round to nearest float.
                #[allow(clippy::cast_possible_truncation)]
                Ok(ConstValue::Float(v as f32))
            } else {
                Ok(ConstValue::Double(v))
            }
        }
        _ => Err(format!("invalid type for const: {}", ty.lcm_name())),
    }
}

/// Parses one `.lcm` source text. `file` names it in error messages.
pub fn parse_str(src: &str, file: &str) -> Result<ParsedFile, ParseError> {
    let tokens = tokenize(src, file)?;
    Parser {
        tokens,
        pos: 0,
        file,
        package: String::new(),
        pending_doc: None,
    }
    .parse_file()
}
