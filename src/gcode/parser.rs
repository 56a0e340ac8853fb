//! One line of RS274/NGC text to a [`Line`]: words with unevaluated expressions, parameter
//! assignments, comments, or one O-word control statement.
//!
//! Parsing and evaluating are separate steps because LinuxCNC evaluates every value of a
//! line against the parameters as they were *before* the line, then applies the line's
//! assignments; a parsed line can also be executed many times (loops, subroutines).

use super::expr::{BinOp, Expr, Func};
use super::lexer::Cursor;

/// Most operands in one bracketed expression.
const MAX_OPERANDS: usize = 256;

/// A syntax error: column and message.
pub type ParseError = (u32, String);

/// One word: a letter and its value.
#[derive(Debug, Clone, PartialEq)]
pub struct Word {
    /// Lower-case letter.
    pub letter: u8,
    /// Unevaluated value.
    pub value: Expr,
    /// Column of the letter.
    pub col: u32,
}

/// Which parameter an assignment writes.
#[derive(Debug, Clone, PartialEq)]
pub enum Target {
    /// `#n=`, index evaluated with the other values of the line.
    Numbered(Expr),
    /// `#<name>=`.
    Named(Box<str>),
}

/// `#…=value`.
#[derive(Debug, Clone, PartialEq)]
pub struct Assign {
    /// Destination.
    pub target: Target,
    /// Value.
    pub value: Expr,
    /// Column of the `#`.
    pub col: u32,
}

/// The O-word keywords.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OKind {
    /// `sub`
    Sub,
    /// `endsub [v]`
    EndSub,
    /// `call [a]…`
    Call,
    /// `return [v]`
    Return,
    /// `do`
    Do,
    /// `while [c]` (loop head, or tail of a `do`)
    While,
    /// `endwhile`
    EndWhile,
    /// `if [c]`
    If,
    /// `elseif [c]`
    ElseIf,
    /// `else`
    Else,
    /// `endif`
    EndIf,
    /// `break`
    Break,
    /// `continue`
    Continue,
    /// `repeat [n]`
    Repeat,
    /// `endrepeat`
    EndRepeat,
    /// A bare `O123` or `O<name>` line: a program number or name as some CAM posts write it
    /// at the top (or a Fanuc subprogram's first line), which rs274 accepts; it does nothing
    /// where the program flows through it.
    ProgramNumber,
}

impl OKind {
    fn from_name(s: &str) -> Option<OKind> {
        Some(match s {
            "sub" => OKind::Sub,
            "endsub" => OKind::EndSub,
            "call" => OKind::Call,
            "return" => OKind::Return,
            "do" => OKind::Do,
            "while" => OKind::While,
            "endwhile" => OKind::EndWhile,
            "if" => OKind::If,
            "elseif" => OKind::ElseIf,
            "else" => OKind::Else,
            "endif" => OKind::EndIf,
            "break" => OKind::Break,
            "continue" => OKind::Continue,
            "repeat" => OKind::Repeat,
            "endrepeat" => OKind::EndRepeat,
            _ => return None,
        })
    }
}

/// An O-word statement.
#[derive(Debug, Clone, PartialEq)]
pub struct OStmt {
    /// Label: the name inside `o<…>` or the number of `o123`, normalised. Empty for a
    /// computed label.
    pub label: Box<str>,
    /// A computed label (`o[#2*10] call`, `o#5 call`), evaluated when the statement runs.
    pub label_expr: Option<Expr>,
    /// Keyword.
    pub kind: OKind,
    /// Bracketed arguments (condition, count, return value or call arguments).
    pub args: Vec<Expr>,
    /// Column of the `o`.
    pub col: u32,
}

/// A comment and where it starts.
#[derive(Debug, Clone, PartialEq)]
pub struct Comment {
    /// Text between the parentheses, as written.
    pub text: Box<str>,
    /// Column of `(`.
    pub col: u32,
}

/// A parsed line.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Line {
    /// Starts with `/`.
    pub block_delete: bool,
    /// O-word statement, if the line is one.
    pub o: Option<OStmt>,
    /// Words in order.
    pub words: Vec<Word>,
    /// Parameter assignments in order.
    pub assigns: Vec<Assign>,
    /// Parenthesised comments in order.
    pub comments: Vec<Comment>,
}

/// Parses one line (without its terminator). `max_depth` bounds expression nesting.
pub fn parse_line(text: &str, max_depth: usize) -> Result<Line, ParseError> {
    let mut line = Line::default();
    parse_line_into(text, max_depth, &mut line)?;
    Ok(line)
}

/// Like [`parse_line`], reusing `line`'s buffers (the interpreter's hot path parses every
/// line into the same scratch `Line`, so plain blocks cost no allocation).
pub fn parse_line_into(text: &str, max_depth: usize, line: &mut Line) -> Result<(), ParseError> {
    line.block_delete = false;
    line.o = None;
    line.words.clear();
    line.assigns.clear();
    line.comments.clear();
    let mut p = Parser {
        c: Cursor::new(text),
        max_depth,
    };
    p.line(line)
}

/// Cheap test used when indexing a file: does this line hold an O-word statement?
pub fn starts_with_o(text: &str) -> bool {
    let mut c = Cursor::new(text);
    c.eat(b'/');
    if c.eat(b'n') {
        let _ = c.number();
    }
    c.peek() == Some(b'o')
}

struct Parser<'a> {
    c: Cursor<'a>,
    max_depth: usize,
}

fn err<T>(col: u32, msg: impl Into<String>) -> Result<T, ParseError> {
    Err((col, msg.into()))
}

impl Parser<'_> {
    fn line(&mut self, line: &mut Line) -> Result<(), ParseError> {
        if self.c.eat(b'/') {
            line.block_delete = true;
        }
        if self.c.peek() == Some(b'n') {
            let col = self.c.col();
            self.c.next_char();
            if self.c.number().is_none() {
                return err(col, "Bad format unsigned integer");
            }
        }
        if self.c.peek() == Some(b'o') {
            line.o = Some(self.ostmt()?);
        }
        while let Some(ch) = self.c.peek() {
            let col = self.c.col_here();
            match ch {
                b'(' => {
                    self.c.next_char();
                    let Some(body) = self.c.raw_until(b')') else {
                        return err(col, "Unclosed comment found");
                    };
                    if body.contains('(') {
                        return err(col, "Nested comment found");
                    }
                    line.comments.push(Comment {
                        text: body.into(),
                        col,
                    });
                }
                b';' => {
                    self.c.rest();
                    break;
                }
                _ if line.o.is_some() => {
                    return err(
                        col,
                        format!("Unexpected text after O-word: '{}'", ch as char),
                    );
                }
                b'#' => {
                    self.c.next_char();
                    let target = if self.c.eat(b'<') {
                        Target::Named(self.name(col)?)
                    } else {
                        Target::Numbered(self.value(0)?)
                    };
                    if !self.c.eat(b'=') {
                        return err(self.c.col(), "Equal sign missing in parameter setting");
                    }
                    let value = self.value(0)?;
                    line.assigns.push(Assign { target, value, col });
                }
                b'a'..=b'm' | b'p'..=b't' | b'x'..=b'z' | b'@' | b'^' => {
                    self.c.bump();
                    let value = match self.c.signed_number_fast() {
                        Some(v) => Expr::Num(v),
                        None => self.value(0)?,
                    };
                    line.words.push(Word {
                        letter: ch,
                        value,
                        col,
                    });
                }
                b'n' => return err(col, "Line number (N word) must come first on the line"),
                b'o' => return err(col, "O-word must come first on the line"),
                _ => {
                    let shown = self.c.rest().chars().next().unwrap_or('?');
                    return err(col, format!("Bad character '{shown}' used"));
                }
            }
        }
        Ok(())
    }

    fn name(&mut self, col: u32) -> Result<Box<str>, ParseError> {
        let Some(raw) = self.c.raw_until(b'>') else {
            return err(col, "Named parameter not terminated by '>'");
        };
        let name: String = raw
            .chars()
            .filter(|c| !c.is_whitespace())
            .map(|c| c.to_ascii_lowercase())
            .collect();
        if name.is_empty() {
            return err(col, "Empty name in named parameter or O-word");
        }
        Ok(name.into())
    }

    fn ostmt(&mut self) -> Result<OStmt, ParseError> {
        let col = self.c.col();
        self.c.next_char();
        let mut label_expr = None;
        let label: Box<str> = if self.c.eat(b'<') {
            self.name(col)?
        } else if matches!(self.c.peek(), Some(b'[' | b'#')) {
            label_expr = Some(self.value(0)?);
            "".into()
        } else {
            match self.c.number() {
                Some(n) if n.fract() == 0.0 => format!("{}", n as u64).into(),
                _ => return err(col, "Bad O-word label: expected o<name> or o<number>"),
            }
        };
        let kcol = self.c.col();
        let kw = self.c.word();
        let kind = match OKind::from_name(&kw) {
            Some(k) => k,
            // `O32123` or `O<name>` alone (or with a comment): a program number or name
            // heading the program (or a Fanuc subprogram), as rs274 accepts it.
            None if kw.is_empty()
                && label_expr.is_none()
                && matches!(self.c.peek(), None | Some(b'(' | b';')) =>
            {
                OKind::ProgramNumber
            }
            None => return err(kcol, format!("Unknown O-word keyword '{kw}'")),
        };
        let mut args = Vec::new();
        loop {
            // Comments may stand between call arguments, as rs274 allows; comments on an
            // O-word line are not executed.
            if kind == OKind::Call && self.c.peek() == Some(b'(') {
                let ccol = self.c.col();
                self.c.next_char();
                match self.c.raw_until(b')') {
                    Some(body) if body.contains('(') => return err(ccol, "Nested comment found"),
                    Some(_) => continue,
                    None => return err(ccol, "Unclosed comment found"),
                }
            }
            if self.c.peek() != Some(b'[') {
                break;
            }
            self.c.next_char();
            args.push(self.expr_after_bracket(1)?);
            if kind != OKind::Call {
                break;
            }
        }
        Ok(OStmt {
            label,
            label_expr,
            kind,
            args,
            col,
        })
    }

    /// A real value: number, `[expr]`, `#param`, function call or signed value.
    fn value(&mut self, depth: usize) -> Result<Expr, ParseError> {
        let col = self.c.col();
        if depth > self.max_depth {
            return err(
                col,
                format!("Expression nested too deeply (limit {})", self.max_depth),
            );
        }
        match self.c.peek() {
            Some(b'[') => {
                self.c.next_char();
                self.expr_after_bracket(depth + 1)
            }
            Some(b'#') => {
                self.c.next_char();
                if self.c.eat(b'<') {
                    Ok(Expr::Named(self.name(col)?))
                } else {
                    Ok(Expr::Param(Box::new(self.value(depth + 1)?)))
                }
            }
            Some(b'-') => {
                self.c.next_char();
                if let Some(n) = self.c.number() {
                    return Ok(Expr::Num(-n));
                }
                Ok(Expr::Neg(Box::new(self.value(depth + 1)?)))
            }
            Some(b'+') => {
                self.c.next_char();
                if let Some(n) = self.c.number() {
                    return Ok(Expr::Num(n));
                }
                self.value(depth + 1)
            }
            Some(c) if c.is_ascii_digit() || c == b'.' => match self.c.number() {
                Some(n) => Ok(Expr::Num(n)),
                None => err(col, "Bad number format"),
            },
            Some(c) if c.is_ascii_alphabetic() => {
                let name = self.c.word();
                if name == "exists" {
                    if !(self.c.eat(b'[') && self.c.eat(b'#')) {
                        return err(
                            col,
                            "EXISTS argument must be a parameter: exists[#<name>] or exists[#n]",
                        );
                    }
                    // rs274 also takes a numbered parameter (`EXISTS[#1]`, `EXISTS[##2]`):
                    // it exists when its index is in the parameter table's range.
                    let e = if self.c.eat(b'<') {
                        Expr::Exists(self.name(col)?)
                    } else {
                        Expr::ExistsNumbered(Box::new(self.value(depth + 1)?))
                    };
                    if !self.c.eat(b']') {
                        return err(self.c.col(), "Missing closing bracket");
                    }
                    return Ok(e);
                }
                let is_atan = name == "atan";
                let f = Func::from_name(&name);
                if f.is_none() && !is_atan {
                    return err(
                        col,
                        format!(
                            "Unknown word starting with {}",
                            name.get(..1).unwrap_or("?").to_ascii_uppercase()
                        ),
                    );
                }
                if !self.c.eat(b'[') {
                    return err(
                        self.c.col(),
                        "Left bracket missing after unary operation name",
                    );
                }
                let arg = self.expr_after_bracket(depth + 1)?;
                if is_atan {
                    if !self.c.eat(b'/') {
                        return err(self.c.col(), "Slash missing after first ATAN argument");
                    }
                    if !self.c.eat(b'[') {
                        return err(self.c.col(), "Left bracket missing after slash with ATAN");
                    }
                    let x = self.expr_after_bracket(depth + 1)?;
                    return Ok(Expr::Atan(Box::new(arg), Box::new(x)));
                }
                match f {
                    Some(f) => Ok(Expr::Call(f, Box::new(arg))),
                    None => err(col, "Unknown operation"),
                }
            }
            Some(_) => err(col, "Bad number format"),
            None => err(col, "Bad number format"),
        }
    }

    fn binop(&mut self) -> Result<Option<BinOp>, ParseError> {
        let col = self.c.col();
        let op = match self.c.peek() {
            Some(b'*') => {
                self.c.next_char();
                if self.c.eat(b'*') {
                    BinOp::Pow
                } else {
                    BinOp::Mul
                }
            }
            Some(b'/') => {
                self.c.next_char();
                BinOp::Div
            }
            Some(b'+') => {
                self.c.next_char();
                BinOp::Add
            }
            Some(b'-') => {
                self.c.next_char();
                BinOp::Sub
            }
            Some(b']') => return Ok(None),
            Some(c) if c.is_ascii_alphabetic() => {
                let ops: [(&str, BinOp); 10] = [
                    ("mod", BinOp::Mod),
                    ("eq", BinOp::Eq),
                    ("ne", BinOp::Ne),
                    ("gt", BinOp::Gt),
                    ("ge", BinOp::Ge),
                    ("lt", BinOp::Lt),
                    ("le", BinOp::Le),
                    ("and", BinOp::And),
                    ("or", BinOp::Or),
                    ("xor", BinOp::Xor),
                ];
                match ops.iter().find(|(k, _)| self.c.eat_keyword(k)) {
                    Some((_, op)) => *op,
                    None => return err(col, "Unknown operation"),
                }
            }
            None => return err(col, "Unclosed expression"),
            Some(_) => return err(col, "Unknown operation"),
        };
        Ok(Some(op))
    }

    /// Reads `expr ]` (the `[` is consumed) with precedence climbing, left-associative.
    fn expr_after_bracket(&mut self, depth: usize) -> Result<Expr, ParseError> {
        let col = self.c.col();
        if depth > self.max_depth {
            return err(
                col,
                format!("Expression nested too deeply (limit {})", self.max_depth),
            );
        }
        let mut vals = vec![self.value(depth + 1)?];
        let mut ops: Vec<BinOp> = Vec::new();
        let mut n_ops = 0usize;
        while let Some(op) = self.binop()? {
            while let Some(&top) = ops.last() {
                if top.precedence() >= op.precedence() {
                    reduce(&mut vals, &mut ops);
                } else {
                    break;
                }
            }
            ops.push(op);
            vals.push(self.value(depth + 1)?);
            // Left-associative chains build trees as deep as they are long; bound them so
            // evaluation cannot exhaust the stack.
            n_ops += 1;
            if ops.len() > self.max_depth || n_ops >= MAX_OPERANDS {
                return err(
                    col,
                    format!("Expression too long (limit {MAX_OPERANDS} operands)"),
                );
            }
        }
        self.c.next_char(); // ']'
        while !ops.is_empty() {
            reduce(&mut vals, &mut ops);
        }
        Ok(vals.pop().unwrap_or(Expr::Num(0.0)))
    }
}

fn reduce(vals: &mut Vec<Expr>, ops: &mut Vec<BinOp>) {
    if let (Some(op), Some(b), Some(a)) = (ops.pop(), vals.pop(), vals.pop()) {
        vals.push(Expr::Bin(op, Box::new(a), Box::new(b)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_comments_and_assignments() {
        let l = parse_line("/N10 g1 x 1.5 (hi) #1=[2*3] ; rest", 32).unwrap_or_default();
        assert!(l.block_delete);
        assert_eq!(l.words.len(), 2);
        assert_eq!(l.words[1].value, Expr::Num(1.5));
        assert_eq!(l.words[1].col, 9);
        assert_eq!(&*l.comments[0].text, "hi");
        assert_eq!(l.assigns.len(), 1);
    }

    #[test]
    fn precedence_is_linuxcnc() {
        let l = parse_line("x[1+2*3**2]", 32).unwrap_or_default();
        let want = Expr::Bin(
            BinOp::Add,
            Box::new(Expr::Num(1.0)),
            Box::new(Expr::Bin(
                BinOp::Mul,
                Box::new(Expr::Num(2.0)),
                Box::new(Expr::Bin(
                    BinOp::Pow,
                    Box::new(Expr::Num(3.0)),
                    Box::new(Expr::Num(2.0)),
                )),
            )),
        );
        assert_eq!(l.words[0].value, want);
    }

    #[test]
    fn ostatements() {
        let l = parse_line("o<My Sub> call [1] [2]", 32).unwrap_or_default();
        let o = l.o.unwrap_or(OStmt {
            label: "".into(),
            label_expr: None,
            kind: OKind::Do,
            args: vec![],
            col: 0,
        });
        assert_eq!(&*o.label, "mysub");
        assert_eq!(o.kind, OKind::Call);
        assert_eq!(o.args.len(), 2);
        assert!(parse_line("o100 frob", 32).is_err());
    }

    #[test]
    fn ostatements_from_cam_posts() {
        let o = |t: &str| parse_line(t, 32).ok().and_then(|l| l.o);
        let call = o("o[#2*10] call [1] (first) [2]");
        assert!(call
            .as_ref()
            .is_some_and(|c| c.label_expr.is_some() && c.args.len() == 2));
        assert_eq!(o("O32123").map(|c| c.kind), Some(OKind::ProgramNumber));
        assert_eq!(
            o("O32123 (part)").map(|c| c.kind),
            Some(OKind::ProgramNumber)
        );
        assert!(parse_line("O32123 G0 X1", 32).is_err());
        assert_eq!(
            o("O<MyProgram> (named)").map(|c| c.kind),
            Some(OKind::ProgramNumber)
        );
        assert!(parse_line("O<MyProgram> G0 X1", 32).is_err());
        assert!(o("o[10] sub").is_some_and(|c| c.kind == OKind::Sub && c.label_expr.is_some()));
        assert!(parse_line("o100 call [1] (open [2]", 32).is_err());
    }

    #[test]
    fn errors_name_the_column() {
        assert_eq!(parse_line("G1 X1 (open", 32).err().map(|e| e.0), Some(7));
        assert!(parse_line("G1 X[1", 32).is_err());
        assert!(parse_line("G1 X[[[[[1]]]]]", 3).is_err());
    }
}
