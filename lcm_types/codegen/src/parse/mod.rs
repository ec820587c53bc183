//! Tokenizer and recursive-descent parser of the LCM type language.
//!
//! Follows `lcmgen.c`: a file is a sequence of `package NAME;` directives and
//! `struct NAME { ... }` blocks; a struct holds members (`TYPE name[dim]..., name2...;`) and
//! constants (`const TYPE NAME = VALUE, ...;`). A variable array dimension must name an earlier
//! integer member of the same struct. Comments directly above a struct, member or constant
//! become its documentation. Enums (deprecated in LCM) are rejected.

use std::fmt;

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

#[derive(Debug, Clone, PartialEq, Eq)]
enum TokenKind {
    Word,
    Punct,
    Comment,
}

#[derive(Debug, Clone)]
struct Token {
    kind: TokenKind,
    text: String,
    line: usize,
}

const PUNCTUATION: &[char] = &['{', '}', '[', ']', ';', ',', '='];

fn tokenize(src: &str, file: &str) -> Result<Vec<Token>, ParseError> {
    let chars: Vec<char> = src.chars().collect();
    let mut tokens = Vec::new();
    let mut i = 0;
    let mut line = 1;
    while i < chars.len() {
        let c = chars[i];
        if c == '\n' {
            line += 1;
            i += 1;
        } else if c.is_whitespace() {
            i += 1;
        } else if c == '/' && chars.get(i + 1) == Some(&'/') {
            let start = i + 2;
            let mut end = start;
            while end < chars.len() && chars[end] != '\n' {
                end += 1;
            }
            let text: String = chars[start..end].iter().collect();
            tokens.push(Token {
                kind: TokenKind::Comment,
                text: strip_comment_line(&text),
                line,
            });
            i = end;
        } else if c == '/' && chars.get(i + 1) == Some(&'*') {
            let start_line = line;
            let start = i + 2;
            let mut end = start;
            loop {
                if end + 1 >= chars.len() {
                    return Err(ParseError {
                        file: file.to_string(),
                        line: start_line,
                        message: "unterminated /* comment".to_string(),
                    });
                }
                if chars[end] == '*' && chars[end + 1] == '/' {
                    break;
                }
                if chars[end] == '\n' {
                    line += 1;
                }
                end += 1;
            }
            let body: String = chars[start..end].iter().collect();
            let text = body
                .lines()
                .map(|l| {
                    let t = l.trim();
                    let t = t.strip_prefix('*').unwrap_or(t);
                    t.strip_prefix(' ').unwrap_or(t).trim_end().to_string()
                })
                .collect::<Vec<_>>()
                .join("\n")
                .trim_matches('\n')
                .to_string();
            tokens.push(Token {
                kind: TokenKind::Comment,
                text,
                line: start_line,
            });
            i = end + 2;
        } else if PUNCTUATION.contains(&c) {
            tokens.push(Token {
                kind: TokenKind::Punct,
                text: c.to_string(),
                line,
            });
            i += 1;
        } else {
            let start = i;
            while i < chars.len() && !ends_word(chars[i], chars.get(i + 1)) {
                i += 1;
            }
            tokens.push(Token {
                kind: TokenKind::Word,
                text: chars[start..i].iter().collect(),
                line,
            });
        }
    }
    Ok(tokens)
}

fn ends_word(c: char, next: Option<&char>) -> bool {
    c.is_whitespace()
        || PUNCTUATION.contains(&c)
        || (c == '/' && matches!(next, Some('/') | Some('*')))
}

fn strip_comment_line(text: &str) -> String {
    let t = text.strip_prefix('/').unwrap_or(text);
    t.strip_prefix(' ').unwrap_or(t).trim_end().to_string()
}

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

/// C `strtoll(s, &end, 0)` over the whole token: optional sign, `0x` hex, leading-`0` octal,
/// else decimal. Returns None if the token is not entirely a number or overflows i64.
pub fn parse_c_integer(token: &str) -> Option<i64> {
    let (negative, digits) = match token.as_bytes().first() {
        Some(b'-') => (true, &token[1..]),
        Some(b'+') => (false, &token[1..]),
        _ => (false, token),
    };
    let (radix, body) = if let Some(hex) = digits
        .strip_prefix("0x")
        .or_else(|| digits.strip_prefix("0X"))
    {
        (16, hex)
    } else if digits.len() > 1 && digits.starts_with('0') {
        (8, &digits[1..])
    } else {
        (10, digits)
    };
    if body.is_empty() || !body.chars().all(|c| c.is_digit(radix)) {
        return None;
    }
    let magnitude = i128::from_str_radix(body, radix).ok()?;
    let value = if negative { -magnitude } else { magnitude };
    i64::try_from(value).ok()
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

#[cfg(test)]
mod tests;
