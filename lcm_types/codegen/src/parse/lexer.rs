//! Tokenizer: words, punctuation and comments with their line numbers, following how `lcmgen.c`
//! splits its input (so error lines and doc-comment attachment match lcm-gen), plus C integer
//! literal syntax.

use super::ParseError;

#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum TokenKind {
    Word,
    Punct,
    Comment,
}

#[derive(Debug, Clone)]
pub(super) struct Token {
    pub(super) kind: TokenKind,
    pub(super) text: String,
    pub(super) line: usize,
}

const PUNCTUATION: &[char] = &['{', '}', '[', ']', ';', ',', '='];

pub(super) fn tokenize(src: &str, file: &str) -> Result<Vec<Token>, ParseError> {
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
