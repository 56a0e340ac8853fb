//! Parser of script files on top of the PLC parser: declarations, expressions and ordinary
//! statements are parsed by `plc::parser` itself; this adds PROGRAM bodies with script
//! statements and STATE_MACHINE blocks. Script words (WAIT, TRY, STATE, ...) are not PLC
//! keywords, so they are recognised by position (`START x;` is a statement, `start := 1;`
//! an assignment) and stay usable as variable names.

use super::ast::*;
use crate::plc::ast::{Pou, PouKind, Stmt, StmtKind};
use crate::plc::diag::{Diag, Span};
use crate::plc::expr::{Ident, Parser};
use crate::plc::lexer::{lex, Tok};
use crate::plc::parser::{PouKindTag, BLOCK_END};

/// Parses a script file; every syntax error found.
pub fn parse(src: &str) -> (ScriptFile, Vec<Diag>) {
    let mut diags = Vec::new();
    let toks = lex(src, &mut diags);
    let mut p = SParser {
        p: Parser::new(toks, diags),
    };
    let file = p.file();
    (file, p.p.diags)
}

/// Words ending a statement list in scripts, besides the PLC's ([`BLOCK_END`]).
const SCRIPT_ENDS: &[&str] = &[
    "END_ENTRY",
    "END_RUN",
    "END_EXIT",
    "CATCH",
    "END_TRY",
    "END_STATE",
    "END_STATE_MACHINE",
];

struct SParser {
    p: Parser,
}

/// The upper-cased word of a token (keyword or identifier).
fn word(t: &Tok) -> Option<String> {
    match t {
        Tok::Kw(k) => Some((*k).to_string()),
        Tok::Ident(s) => Some(s.to_ascii_uppercase()),
        _ => None,
    }
}

impl SParser {
    fn at(&self, w: &str) -> bool {
        word(self.p.peek()).is_some_and(|x| x == w)
    }
    /// At a word that ends a statement list (the PLC's or a script's).
    fn at_list_end(&self) -> bool {
        self.at_any(BLOCK_END) || self.at_any(SCRIPT_ENDS)
    }
    fn at_any(&self, set: &[&str]) -> bool {
        word(self.p.peek()).is_some_and(|x| set.contains(&x.as_str()))
    }
    fn eat(&mut self, w: &str) -> bool {
        let y = self.at(w);
        if y {
            self.p.bump();
        }
        y
    }
    fn expect(&mut self, w: &str) -> bool {
        if self.eat(w) {
            return true;
        }
        let msg = format!("expected {w}, found {}", self.p.describe());
        self.p.error(msg);
        false
    }
    /// Skips to just after the next `;` or to an end word; always makes progress.
    fn recover(&mut self, start: usize) {
        while !self.p.at_eof() && !self.at_list_end() {
            if matches!(self.p.bump(), Tok::P(";")) {
                return;
            }
        }
        if self.p.pos() == start && !self.p.at_eof() {
            self.p.bump();
        }
    }
    /// `a.b.c` as one name.
    fn dotted(&mut self) -> Option<(String, Span)> {
        let span = self.p.span();
        let mut s = self.p.ident()?.name;
        while self.p.is_p(".") && matches!(self.p.peek_at(1), Tok::Ident(_)) {
            self.p.bump();
            s.push('.');
            s.push_str(&self.p.ident()?.name);
        }
        Some((s, span))
    }

    fn file(&mut self) -> ScriptFile {
        let mut f = ScriptFile::default();
        while !self.p.at_eof() {
            let start = self.p.pos();
            match self.p.peek() {
                Tok::Kw("PROGRAM") => self.program(&mut f),
                Tok::Kw("FUNCTION_BLOCK") => f.unit.pous.push(self.p.pou(PouKindTag::Fb)),
                Tok::Kw("FUNCTION") => f.unit.pous.push(self.p.pou(PouKindTag::Function)),
                Tok::Kw("TYPE") => self.p.types(&mut f.unit.types),
                Tok::Kw("VAR_GLOBAL") => {
                    if let Some(b) = self.p.var_block() {
                        f.unit.globals.push(b);
                    }
                }
                _ if self.at("STATE_MACHINE") => self.machine(&mut f),
                _ => {
                    let msg = format!(
                        "expected PROGRAM, STATE_MACHINE, FUNCTION, FUNCTION_BLOCK, TYPE or \
                         VAR_GLOBAL, found {}",
                        self.p.describe()
                    );
                    self.p.error(msg);
                    self.p.bump();
                }
            }
            if self.p.pos() == start {
                self.p.bump();
            }
        }
        f
    }

    /// The item's name and variable blocks, as an empty PLC PROGRAM.
    fn header(&mut self, f: &mut ScriptFile) -> (Ident, usize) {
        self.p.bump();
        let name = self.p.ident().unwrap_or_else(|| Ident {
            name: "?".into(),
            span: self.p.span(),
        });
        let mut vars = Vec::new();
        while matches!(self.p.peek(), Tok::Kw(k) if k.starts_with("VAR")) {
            if let Some(b) = self.p.var_block() {
                vars.push(b);
            }
        }
        f.unit.pous.push(Pou {
            kind: PouKind::Program,
            name: name.clone(),
            vars,
            body: Vec::new(),
        });
        (name, f.unit.pous.len() - 1)
    }

    fn program(&mut self, f: &mut ScriptFile) {
        let (name, pou) = self.header(f);
        let body = self.stmts();
        self.expect("END_PROGRAM");
        f.items.push(Item {
            name,
            pou,
            kind: ItemKind::Program(body),
        });
    }

    fn machine(&mut self, f: &mut ScriptFile) {
        let (name, pou) = self.header(f);
        let mut states = Vec::new();
        while !self.p.at_eof() && !self.at("END_STATE_MACHINE") {
            let start = self.p.pos();
            let kind = if self.eat("INITIAL") {
                StateKind::Initial
            } else if self.eat("FINAL") {
                StateKind::Final
            } else if self.eat("ERROR") {
                StateKind::Error
            } else {
                StateKind::Normal
            };
            if !self.expect("STATE") {
                self.recover(start);
                continue;
            }
            if let Some(s) = self.state(kind) {
                states.push(s);
            } else {
                self.recover(start);
            }
        }
        self.expect("END_STATE_MACHINE");
        f.items.push(Item {
            name,
            pou,
            kind: ItemKind::Machine(states),
        });
    }

    fn state(&mut self, kind: StateKind) -> Option<State> {
        let name = self.p.ident()?;
        let mut s = State {
            name,
            kind,
            pre: Vec::new(),
            entry: Vec::new(),
            run: None,
            exit: Vec::new(),
            transitions: Vec::new(),
        };
        while !self.p.at_eof() && !self.at("END_STATE") && !self.at("END_STATE_MACHINE") {
            let start = self.p.pos();
            if self.eat("PRECONDITION") {
                if let Some(e) = self.p.expr() {
                    s.pre.push(e);
                }
                self.p.expect_p(";");
            } else if self.eat("ENTRY") {
                s.entry = self.stmts();
                self.expect("END_ENTRY");
            } else if self.eat("RUN") {
                s.run = Some(self.stmts());
                self.expect("END_RUN");
            } else if self.eat("EXIT") {
                s.exit = self.stmts();
                self.expect("END_EXIT");
            } else if self.at("TRANSITION") {
                match self.transition() {
                    Some(t) => s.transitions.push(t),
                    None => self.recover(start),
                }
            } else {
                let msg = format!(
                    "expected PRECONDITION, ENTRY, RUN, EXIT, TRANSITION or END_STATE, found {}",
                    self.p.describe()
                );
                self.p.error(msg);
                self.recover(start);
            }
        }
        self.expect("END_STATE");
        self.p.eat_p(";");
        Some(s)
    }

    fn transition(&mut self) -> Option<Transition> {
        let span = self.p.span();
        self.p.bump();
        let event = if self.eat("ON") {
            Some(self.dotted()?)
        } else {
            None
        };
        let cond = if self.eat("WHEN") {
            Some(self.p.expr()?)
        } else {
            None
        };
        self.expect("TO");
        let target = self.p.ident()?;
        self.p.expect_p(";");
        Some(Transition {
            event,
            cond,
            target,
            span,
        })
    }

    fn stmts(&mut self) -> Vec<SStmt> {
        let mut out = Vec::new();
        while !self.p.at_eof() && !self.at_list_end() && !self.at_top_level() {
            if self.p.eat_p(";") {
                continue;
            }
            let start = self.p.pos();
            match self.stmt() {
                Some(s) => out.push(s),
                None => self.recover(start),
            }
        }
        out
    }

    fn at_top_level(&self) -> bool {
        matches!(
            self.p.peek(),
            Tok::Kw("PROGRAM" | "FUNCTION" | "FUNCTION_BLOCK" | "TYPE" | "VAR_GLOBAL")
        ) || self.at("STATE_MACHINE")
    }

    /// `WORD name;` shape (so `stop := x;` stays an assignment).
    fn word_then_name(&self) -> bool {
        matches!(self.p.peek_at(1), Tok::Ident(_))
    }

    fn stmt(&mut self) -> Option<SStmt> {
        let span = self.p.span();
        let w = word(self.p.peek()).unwrap_or_default();
        let kind = match w.as_str() {
            "IF" => {
                self.p.bump();
                let mut arms = Vec::new();
                let c = self.p.expr()?;
                self.p.expect_kw("THEN");
                arms.push((c, self.stmts()));
                let mut els = None;
                loop {
                    if self.p.eat_kw("ELSIF") {
                        let c = self.p.expr()?;
                        self.p.expect_kw("THEN");
                        arms.push((c, self.stmts()));
                    } else if self.p.eat_kw("ELSE") {
                        els = Some(self.stmts());
                    } else {
                        break;
                    }
                }
                self.p.expect_kw("END_IF");
                self.p.eat_p(";");
                SKind::If(arms, els)
            }
            "WHILE" => {
                self.p.bump();
                let c = self.p.expr()?;
                self.p.expect_kw("DO");
                let body = self.stmts();
                self.p.expect_kw("END_WHILE");
                self.p.eat_p(";");
                SKind::While(c, body)
            }
            "REPEAT" => {
                self.p.bump();
                let body = self.stmts();
                self.p.expect_kw("UNTIL");
                let c = self.p.expr()?;
                self.p.expect_kw("END_REPEAT");
                self.p.eat_p(";");
                SKind::Repeat(body, c)
            }
            "FOR" => {
                self.p.bump();
                let var = self.p.ident()?;
                self.p.expect_p(":=");
                let from = self.p.expr()?;
                self.p.expect_kw("TO");
                let to = self.p.expr()?;
                let by = if self.p.eat_kw("BY") {
                    Some(self.p.expr()?)
                } else {
                    None
                };
                self.p.expect_kw("DO");
                let body = self.stmts();
                self.p.expect_kw("END_FOR");
                self.p.eat_p(";");
                SKind::For {
                    var,
                    from,
                    to,
                    by,
                    body,
                }
            }
            "EXIT" | "CONTINUE" | "RETURN" => {
                self.p.bump();
                self.p.expect_p(";");
                match w.as_str() {
                    "EXIT" => SKind::Exit,
                    "CONTINUE" => SKind::Continue,
                    _ => SKind::Return,
                }
            }
            "DO" => {
                self.p.bump();
                let (path, _) = self.dotted()?;
                let Some((peer, op)) = path.rsplit_once('.') else {
                    self.p
                        .error_at(span, "DO needs peer.operation(arguments)".to_string());
                    return None;
                };
                let op_span = Span {
                    line: span.line,
                    col: span.col + 3 + peer.len() as u32 + 1,
                };
                let mut args = Vec::new();
                self.p.expect_p("(");
                if !self.p.eat_p(")") {
                    loop {
                        if let Tok::Str(s) = self.p.peek() {
                            let s = s.clone();
                            self.p.bump();
                            args.push(DoArg::Str(s));
                        } else {
                            args.push(DoArg::Expr(self.p.expr()?));
                        }
                        if !self.p.eat_p(",") {
                            break;
                        }
                    }
                    self.p.expect_p(")");
                }
                self.p.expect_p(";");
                SKind::Do {
                    peer: peer.to_string(),
                    op: Ident {
                        name: op.to_string(),
                        span: op_span,
                    },
                    args,
                }
            }
            "TRY" if !self.assignment_ahead() => {
                self.p.bump();
                let body = self.stmts();
                self.expect("CATCH");
                let catch = self.stmts();
                self.expect("END_TRY");
                self.p.eat_p(";");
                SKind::Try(body, catch)
            }
            "WAIT" if self.word_then_name() || self.p.peek_at(1) == &Tok::Kw("UNTIL") => {
                self.p.bump();
                let until = self.p.eat_kw("UNTIL");
                let cond = if until { Some(self.p.expr()?) } else { None };
                let name = if until { None } else { Some(self.dotted()?.0) };
                let timeout = if self.eat("TIMEOUT") {
                    Some(self.p.expr()?)
                } else {
                    None
                };
                self.p.expect_p(";");
                match (cond, name) {
                    (Some(c), _) => SKind::WaitUntil(c, timeout),
                    (None, Some(n)) => SKind::Wait(n, timeout),
                    _ => return None,
                }
            }
            "START" | "STOP" if self.word_then_name() => {
                self.p.bump();
                let n = self.p.ident()?;
                self.p.expect_p(";");
                if w == "START" {
                    SKind::Start(n)
                } else {
                    SKind::Stop(n)
                }
            }
            "EMIT" if self.word_then_name() => {
                self.p.bump();
                let (n, _) = self.dotted()?;
                self.p.expect_p(";");
                SKind::Emit(n)
            }
            _ => SKind::Plain(self.p.stmt()?),
        };
        let s = SStmt { kind, span };
        Some(match to_plain(&s, false) {
            Some(p) => SStmt {
                kind: SKind::Plain(p),
                span,
            },
            None => s,
        })
    }

    /// `TRY := ...` or `TRY(...)`: the word is used as a name.
    fn assignment_ahead(&self) -> bool {
        matches!(self.p.peek_at(1), Tok::P(":=" | "(" | "." | "["))
    }
}

fn plain_list(list: &[SStmt], in_loop: bool) -> Option<Vec<Stmt>> {
    list.iter().map(|s| to_plain(s, in_loop)).collect()
}

/// The statement as plain ST, when it needs nothing of the script engine: no script
/// statement inside, and no EXIT/CONTINUE/RETURN leaving it (those belong to a script loop
/// or end the script block).
pub(crate) fn to_plain(s: &SStmt, in_loop: bool) -> Option<Stmt> {
    let kind = match &s.kind {
        SKind::Plain(p) => return Some(p.clone()),
        SKind::If(arms, els) => {
            let mut out = Vec::new();
            for (c, b) in arms {
                out.push((c.clone(), plain_list(b, in_loop)?));
            }
            let els = match els {
                Some(b) => Some(plain_list(b, in_loop)?),
                None => None,
            };
            StmtKind::If(out, els)
        }
        SKind::While(c, b) => StmtKind::While(c.clone(), plain_list(b, true)?),
        SKind::Repeat(b, c) => StmtKind::Repeat(plain_list(b, true)?, c.clone()),
        SKind::For {
            var,
            from,
            to,
            by,
            body,
        } => StmtKind::For {
            var: var.clone(),
            from: from.clone(),
            to: to.clone(),
            by: by.clone(),
            body: plain_list(body, true)?,
        },
        SKind::Exit if in_loop => StmtKind::Exit,
        SKind::Continue if in_loop => StmtKind::Continue,
        _ => return None,
    };
    Some(Stmt { kind, span: s.span })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn program_body(src: &str) -> Vec<SStmt> {
        let (f, diags) = parse(src);
        assert!(diags.is_empty(), "{diags:?}");
        match &f.items[0].kind {
            ItemKind::Program(b) => b.clone(),
            ItemKind::Machine(_) => panic!("not a program"),
        }
    }

    #[test]
    fn plain_st_stays_plain_script_statements_do_not() {
        let b = program_body(
            "PROGRAM p\n  IF a THEN b := 1; END_IF;\n  WHILE a DO IF c THEN EXIT; END_IF; END_WHILE;\n  IF a THEN DO x.y(); END_IF;\n  WHILE a DO IF c THEN EXIT; END_IF; WAIT UNTIL c; END_WHILE;\nEND_PROGRAM\n",
        );
        assert!(matches!(b[0].kind, SKind::Plain(_)));
        assert!(matches!(b[1].kind, SKind::Plain(_)), "EXIT of its own loop");
        assert!(matches!(b[2].kind, SKind::If(..)));
        match &b[3].kind {
            SKind::While(_, body) => assert!(
                matches!(body[0].kind, SKind::If(..)),
                "an EXIT of a script loop is a script statement"
            ),
            k => panic!("{k:?}"),
        }
    }

    #[test]
    fn script_words_remain_usable_as_names() {
        let b = program_body("PROGRAM p\n  stop := start;\n  wait := 1;\n  STOP q;\nEND_PROGRAM\n");
        assert!(matches!(b[0].kind, SKind::Plain(_)));
        assert!(matches!(b[1].kind, SKind::Plain(_)));
        assert!(matches!(&b[2].kind, SKind::Stop(n) if n.name == "q"));
    }

    #[test]
    fn machine_parts_and_their_errors() {
        let (f, diags) = parse(
            "STATE_MACHINE m\n  INITIAL STATE a\n    PRECONDITION x > 0;\n    ENTRY DO r.go(1, 2.5); END_ENTRY\n    RUN y := 1; END_RUN\n    EXIT y := 0; END_EXIT\n    TRANSITION ON r.done WHEN y = 1 TO b;\n  END_STATE\n  FINAL STATE b BOGUS END_STATE\nEND_STATE_MACHINE\n",
        );
        let ItemKind::Machine(states) = &f.items[0].kind else {
            panic!("machine")
        };
        let a = &states[0];
        assert_eq!(
            (a.kind, a.pre.len(), a.entry.len()),
            (StateKind::Initial, 1, 1)
        );
        assert!(
            matches!(&a.entry[0].kind, SKind::Do { peer, op, args } if peer == "r" && op.name == "go" && args.len() == 2)
        );
        assert_eq!(
            a.transitions[0].event.as_ref().map(|e| e.0.as_str()),
            Some("r.done")
        );
        assert_eq!(states[1].kind, StateKind::Final);
        assert_eq!(diags.len(), 1);
        assert_eq!(diags[0].span, Span { line: 9, col: 17 });
    }
}
