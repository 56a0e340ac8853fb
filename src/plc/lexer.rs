//! Tokens of IEC 61131-3 Structured Text. Generic: the PLC parser and (later) the scripted
//! programs of issue 12 share it. Keywords and identifiers are case-insensitive (IEC 61131-3
//! 6.1.2); identifiers keep their spelling for messages, keywords are upper-cased.

use super::diag::{Diag, Span};

/// One token.
#[derive(Debug, Clone, PartialEq)]
pub enum Tok {
    /// An identifier, as written.
    Ident(String),
    /// A reserved word, upper-cased.
    Kw(&'static str),
    /// An integer literal, optionally typed (`INT#5`), any base (`16#FF`).
    Int(i128, Option<String>),
    /// A real literal, optionally typed (`LREAL#1.5`).
    Real(f64, Option<String>),
    /// A duration literal (`T#1s500ms`) in nanoseconds.
    Time(i64),
    /// A character string literal.
    Str(String),
    /// A located address (`%IX0.0`), kept verbatim.
    Address(String),
    /// Punctuation or an operator.
    P(&'static str),
    /// End of input.
    Eof,
}

/// A token with where it starts.
#[derive(Debug, Clone, PartialEq)]
pub struct Token {
    /// What it is.
    pub tok: Tok,
    /// Where it starts.
    pub span: Span,
}

/// Reserved words (the subset this dialect uses; others are ordinary identifiers).
pub const KEYWORDS: &[&str] = &[
    "PROGRAM",
    "END_PROGRAM",
    "FUNCTION_BLOCK",
    "END_FUNCTION_BLOCK",
    "FUNCTION",
    "END_FUNCTION",
    "VAR",
    "VAR_INPUT",
    "VAR_OUTPUT",
    "VAR_IN_OUT",
    "VAR_GLOBAL",
    "VAR_TEMP",
    "VAR_EXTERNAL",
    "END_VAR",
    "RETAIN",
    "PERSISTENT",
    "NON_RETAIN",
    "CONSTANT",
    "AT",
    "TYPE",
    "END_TYPE",
    "STRUCT",
    "END_STRUCT",
    "ARRAY",
    "OF",
    "IF",
    "THEN",
    "ELSIF",
    "ELSE",
    "END_IF",
    "CASE",
    "END_CASE",
    "FOR",
    "TO",
    "BY",
    "DO",
    "END_FOR",
    "WHILE",
    "END_WHILE",
    "REPEAT",
    "UNTIL",
    "END_REPEAT",
    "EXIT",
    "CONTINUE",
    "RETURN",
    "AND",
    "OR",
    "XOR",
    "NOT",
    "MOD",
    "TRUE",
    "FALSE",
];

const PUNCT: &[&str] = &[
    ":=", "=>", "<=", ">=", "<>", "..", "**", "(", ")", "[", "]", ",", ";", ":", ".", "+", "-",
    "*", "/", "=", "<", ">", "&", "^", "#",
];

/// Splits `src` into tokens. Lexical errors are collected (the offending character is
/// skipped) so that the parser still reports its own errors.
pub fn lex(src: &str, diags: &mut Vec<Diag>) -> Vec<Token> {
    let mut lx = Lexer {
        s: src.as_bytes(),
        src,
        i: 0,
        line: 1,
        col: 1,
    };
    let mut out = Vec::new();
    loop {
        lx.skip_trivia(diags);
        let span = lx.span();
        let Some(c) = lx.peek(0) else {
            out.push(Token {
                tok: Tok::Eof,
                span,
            });
            return out;
        };
        let tok = if c.is_ascii_alphabetic() || c == b'_' {
            lx.word(span, diags)
        } else if c.is_ascii_digit() {
            lx.number(None, span, diags)
        } else if c == b'\'' || c == b'"' {
            lx.string(c, span, diags)
        } else if c == b'%' {
            let start = lx.i;
            lx.bump();
            while lx
                .peek(0)
                .is_some_and(|c| c.is_ascii_alphanumeric() || c == b'.' || c == b'*')
            {
                lx.bump();
            }
            Some(Tok::Address(src[start..lx.i].to_string()))
        } else if let Some(p) = PUNCT
            .iter()
            .find(|p| lx.s[lx.i..].starts_with(p.as_bytes()))
        {
            for _ in 0..p.len() {
                lx.bump();
            }
            Some(Tok::P(p))
        } else {
            let ch = src[lx.i..].chars().next().unwrap_or('?');
            diags.push(Diag::new(span, format!("unexpected character {ch:?}")));
            for _ in 0..ch.len_utf8() {
                lx.bump();
            }
            None
        };
        if let Some(tok) = tok {
            out.push(Token { tok, span });
        }
    }
}

struct Lexer<'a> {
    s: &'a [u8],
    src: &'a str,
    i: usize,
    line: u32,
    col: u32,
}

impl Lexer<'_> {
    fn peek(&self, k: usize) -> Option<u8> {
        self.s.get(self.i + k).copied()
    }
    fn span(&self) -> Span {
        Span {
            line: self.line,
            col: self.col,
        }
    }
    fn bump(&mut self) {
        if let Some(&c) = self.s.get(self.i) {
            self.i += 1;
            if c == b'\n' {
                self.line += 1;
                self.col = 1;
            } else if c & 0xC0 != 0x80 {
                self.col += 1;
            }
        }
    }
    fn skip_trivia(&mut self, diags: &mut Vec<Diag>) {
        loop {
            match (self.peek(0), self.peek(1)) {
                (Some(c), _) if c.is_ascii_whitespace() => self.bump(),
                (Some(b'/'), Some(b'/')) => {
                    while self.peek(0).is_some_and(|c| c != b'\n') {
                        self.bump();
                    }
                }
                (Some(b'('), Some(b'*')) => self.block_comment(b"(*", b"*)", diags),
                (Some(b'/'), Some(b'*')) => self.block_comment(b"/*", b"*/", diags),
                // TwinCAT pragmas `{attribute 'x'}`: no meaning here.
                (Some(b'{'), _) => self.block_comment(b"{", b"}", diags),
                _ => return,
            }
        }
    }
    /// Comments nest (CODESYS and TwinCAT accept nested `(* (* *) *)`).
    fn block_comment(&mut self, open: &[u8], close: &[u8], diags: &mut Vec<Diag>) {
        let span = self.span();
        let mut depth = 0usize;
        loop {
            if self.s[self.i..].starts_with(open) {
                depth += 1;
                for _ in 0..open.len() {
                    self.bump();
                }
            } else if self.s[self.i..].starts_with(close) {
                depth -= 1;
                for _ in 0..close.len() {
                    self.bump();
                }
                if depth == 0 {
                    return;
                }
            } else if self.peek(0).is_none() {
                diags.push(Diag::new(span, "unterminated comment"));
                return;
            } else {
                self.bump();
            }
        }
    }
    fn take_while(&mut self, f: impl Fn(u8) -> bool) -> &str {
        let start = self.i;
        while self.peek(0).is_some_and(&f) {
            self.bump();
        }
        &self.src[start..self.i]
    }
    fn word(&mut self, span: Span, diags: &mut Vec<Diag>) -> Option<Tok> {
        let w = self
            .take_while(|c| c.is_ascii_alphanumeric() || c == b'_')
            .to_string();
        let up = w.to_ascii_uppercase();
        let typed_number = self.peek(0) == Some(b'#')
            && (matches!(up.as_str(), "T" | "TIME" | "LT" | "LTIME" | "BOOL")
                || self
                    .peek(1)
                    .is_some_and(|c| c.is_ascii_digit() || c == b'-'));
        // `Mode#Idle` (a typed enumeration value) lexes as name, '#', name.
        if typed_number {
            self.bump();
            return match up.as_str() {
                "T" | "TIME" | "LT" | "LTIME" => self.duration(span, diags),
                "BOOL" => match self.take_while(|c| c.is_ascii_alphanumeric()) {
                    "1" | "TRUE" | "true" => Some(Tok::Kw("TRUE")),
                    "0" | "FALSE" | "false" => Some(Tok::Kw("FALSE")),
                    other => {
                        diags.push(Diag::new(span, format!("bad BOOL literal {other:?}")));
                        None
                    }
                },
                _ => self.number(Some(up), span, diags),
            };
        }
        Some(match KEYWORDS.iter().find(|k| **k == up) {
            Some(k) => Tok::Kw(k),
            None => Tok::Ident(w),
        })
    }
    fn number(&mut self, ty: Option<String>, span: Span, diags: &mut Vec<Diag>) -> Option<Tok> {
        let neg = if self.peek(0) == Some(b'-') {
            self.bump();
            true
        } else {
            false
        };
        let digits = self
            .take_while(|c| c.is_ascii_digit() || c == b'_')
            .replace('_', "");
        // Based literal 16#FF, 8#17, 2#1010.
        if self.peek(0) == Some(b'#') {
            self.bump();
            let body = self
                .take_while(|c| c.is_ascii_hexdigit() || c == b'_')
                .replace('_', "");
            let base: u32 = digits.parse().unwrap_or(0);
            return match (
                matches!(base, 2 | 8 | 16),
                i128::from_str_radix(&body, base),
            ) {
                (true, Ok(v)) if !neg => Some(Tok::Int(v, ty)),
                _ => {
                    diags.push(Diag::new(span, format!("bad based literal {base}#{body}")));
                    None
                }
            };
        }
        let is_real =
            self.peek(0) == Some(b'.') && self.peek(1).is_some_and(|c| c.is_ascii_digit());
        let exp = |l: &Self, k: usize| {
            matches!(l.peek(k), Some(b'e' | b'E'))
                && (l.peek(k + 1).is_some_and(|c| c.is_ascii_digit())
                    || (matches!(l.peek(k + 1), Some(b'+' | b'-'))
                        && l.peek(k + 2).is_some_and(|c| c.is_ascii_digit())))
        };
        if is_real || exp(self, 0) {
            let mut text = digits;
            if is_real {
                self.bump();
                text.push('.');
                text.push_str(
                    &self
                        .take_while(|c| c.is_ascii_digit() || c == b'_')
                        .replace('_', ""),
                );
            }
            if exp(self, 0) {
                self.bump();
                text.push('e');
                if let Some(c @ (b'+' | b'-')) = self.peek(0) {
                    self.bump();
                    text.push(c as char);
                }
                text.push_str(self.take_while(|c| c.is_ascii_digit()));
            }
            let v: f64 = text.parse().unwrap_or(f64::NAN);
            return Some(Tok::Real(if neg { -v } else { v }, ty));
        }
        // A sign only gets here in a typed literal (`INT#-5`).
        match digits.parse::<i128>() {
            Ok(v) => Some(Tok::Int(if neg { -v } else { v }, ty)),
            Err(_) => {
                diags.push(Diag::new(
                    span,
                    format!("integer literal {digits} too large"),
                ));
                None
            }
        }
    }
    /// `T#1d2h3m4s5ms6us7ns`, `T#1.5s`, `T#-5s`, with optional underscores.
    fn duration(&mut self, span: Span, diags: &mut Vec<Diag>) -> Option<Tok> {
        let neg = if self.peek(0) == Some(b'-') {
            self.bump();
            true
        } else {
            false
        };
        let text = self
            .take_while(|c| c.is_ascii_alphanumeric() || c == b'_' || c == b'.')
            .to_ascii_lowercase()
            .replace('_', "");
        match parse_duration(&text) {
            Some(ns) => Some(Tok::Time(if neg { -ns } else { ns })),
            None => {
                diags.push(Diag::new(span, format!("bad TIME literal T#{text}")));
                None
            }
        }
    }
    fn string(&mut self, q: u8, span: Span, diags: &mut Vec<Diag>) -> Option<Tok> {
        self.bump();
        let mut s = String::new();
        loop {
            match self.peek(0) {
                None | Some(b'\n') => {
                    diags.push(Diag::new(span, "unterminated string literal"));
                    return None;
                }
                Some(c) if c == q => {
                    self.bump();
                    return Some(Tok::Str(s));
                }
                Some(b'$') => {
                    self.bump();
                    if let Some(c) = self.peek(0) {
                        s.push(c as char);
                        self.bump();
                    }
                }
                Some(_) => {
                    let ch = self.src[self.i..].chars().next().unwrap_or('?');
                    s.push(ch);
                    for _ in 0..ch.len_utf8() {
                        self.bump();
                    }
                }
            }
        }
    }
}

/// Parses the body of a duration literal (lower case, no underscores, no sign) into
/// nanoseconds: units d, h, m, s, ms, us, ns, each with an optional fraction.
pub fn parse_duration(text: &str) -> Option<i64> {
    let b = text.as_bytes();
    let mut i = 0;
    let mut total = 0f64;
    let mut any = false;
    while i < b.len() {
        let start = i;
        while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') {
            i += 1;
        }
        let v: f64 = text[start..i].parse().ok()?;
        let ustart = i;
        while i < b.len() && b[i].is_ascii_alphabetic() {
            i += 1;
        }
        let unit = match &text[ustart..i] {
            "d" => 86_400e9,
            "h" => 3_600e9,
            "m" => 60e9,
            "s" => 1e9,
            "ms" => 1e6,
            "us" => 1e3,
            "ns" => 1.0,
            _ => return None,
        };
        total += v * unit;
        any = true;
    }
    (any && total.abs() < 9.2e18).then_some(total.round() as i64)
}
