//! The parser: tokens to a syntax tree of calls, literals, lists and parameter maps. It knows nothing
//! about which functions exist (the checker does), so goal verification rules reuse it.
//!
//! Grammar (`#` comments and whitespace are skipped):
//!
//! ```text
//! expr  := call | STRING | NUMBER | list | map | NAME      (NAME: None, True, False)
//! call  := NAME "(" [arg ("," arg)* [","]] ")"
//! arg   := NAME "=" expr | expr
//! list  := "[" [expr ("," expr)* [","]] "]"
//! map   := "{" [key ":" expr ("," key ":" expr)* [","]] "}"      key: STRING or NAME
//! ```

use super::error::{ErrorCategory, Pos, RewardError};
use super::lexer::{Tok, Token, lex};

/// Deepest nesting the parser accepts; deeper input is a syntax error, never a stack overflow.
pub const MAX_DEPTH: usize = 64;

/// A node of the syntax tree with its position and source span.
#[derive(Debug, Clone, PartialEq)]
pub struct Expr {
    /// What it is.
    pub kind: ExprKind,
    /// Where it starts.
    pub pos: Pos,
    /// Byte span `[start, end)` in the program text.
    pub span: (usize, usize),
}

/// The kinds of syntax nodes.
#[derive(Debug, Clone, PartialEq)]
pub enum ExprKind {
    /// `NAME(args)`.
    Call {
        /// Function name as written.
        name: String,
        /// Arguments in order.
        args: Vec<Arg>,
    },
    /// A string.
    Str(String),
    /// A number.
    Num(f64),
    /// `True` / `False`.
    Bool(bool),
    /// `None`.
    None,
    /// `[a, b]`.
    List(Vec<Expr>),
    /// `{"k": v}` (keys in order, with their positions).
    Map(Vec<(String, Pos, Expr)>),
}

/// One argument of a call.
#[derive(Debug, Clone, PartialEq)]
pub struct Arg {
    /// `name=` of a keyword argument, with its position.
    pub name: Option<(String, Pos)>,
    /// The value.
    pub value: Expr,
}

impl Expr {
    /// The expression's text in `source` (the program it was parsed from).
    pub fn text<'a>(&self, source: &'a str) -> &'a str {
        source.get(self.span.0..self.span.1).unwrap_or("")
    }

    /// A short name of the node's type for messages.
    pub fn type_name(&self) -> &'static str {
        match &self.kind {
            ExprKind::Call { .. } => "a call",
            ExprKind::Str(_) => "a string",
            ExprKind::Num(_) => "a number",
            ExprKind::Bool(_) => "a boolean",
            ExprKind::None => "None",
            ExprKind::List(_) => "a list",
            ExprKind::Map(_) => "a parameter map",
        }
    }
}

struct Parser {
    toks: Vec<Token>,
    i: usize,
}

fn syntax(pos: Pos, message: impl Into<String>) -> RewardError {
    RewardError::new(ErrorCategory::Syntax, pos, message)
}

/// Parses one expression; anything after it (other than comments and whitespace) is an error.
pub fn parse(text: &str) -> Result<Expr, RewardError> {
    let toks = lex(text)?;
    let mut p = Parser { toks, i: 0 };
    if p.peek().tok == Tok::Eof {
        return Err(syntax(
            p.peek().pos,
            "empty program: expected an expression",
        ));
    }
    let e = p.expr(0)?;
    let t = p.peek();
    if t.tok != Tok::Eof {
        return Err(syntax(
            t.pos,
            format!(
                "unexpected {} after the end of the expression (a program is one expression; combine clauses with AND(...))",
                t.tok.describe()
            ),
        ));
    }
    Ok(e)
}

impl Parser {
    fn peek(&self) -> &Token {
        // The token list always ends with Eof and `i` never passes it.
        &self.toks[self.i.min(self.toks.len() - 1)]
    }
    fn next(&mut self) -> Token {
        let t = self.peek().clone();
        if t.tok != Tok::Eof {
            self.i += 1;
        }
        t
    }
    fn prev_end(&self) -> usize {
        if self.i == 0 {
            0
        } else {
            self.toks[self.i - 1].end
        }
    }
    fn expect(&mut self, tok: Tok, what: &str) -> Result<Token, RewardError> {
        let t = self.next();
        if t.tok == tok {
            Ok(t)
        } else {
            Err(syntax(
                t.pos,
                format!("expected {what}, found {}", t.tok.describe()),
            ))
        }
    }

    fn expr(&mut self, depth: usize) -> Result<Expr, RewardError> {
        let t = self.next();
        if depth > MAX_DEPTH {
            return Err(syntax(
                t.pos,
                format!("expression nested deeper than {MAX_DEPTH} levels"),
            ));
        }
        let start = t.pos.offset;
        let kind = match t.tok {
            Tok::Str(s) => ExprKind::Str(s),
            Tok::Num(n) => ExprKind::Num(n),
            Tok::Ident(name) => {
                if self.peek().tok == Tok::LParen {
                    self.next();
                    let args = self.args(depth)?;
                    ExprKind::Call { name, args }
                } else {
                    match name.as_str() {
                        "None" | "null" => ExprKind::None,
                        "True" | "true" => ExprKind::Bool(true),
                        "False" | "false" => ExprKind::Bool(false),
                        _ => {
                            return Err(syntax(
                                t.pos,
                                format!(
                                    "bare name `{name}`: labels are strings (\"{name}\") and functions need parentheses ({name}(...))"
                                ),
                            ));
                        }
                    }
                }
            }
            Tok::LBracket => {
                let mut items = Vec::new();
                loop {
                    if self.peek().tok == Tok::RBracket {
                        self.next();
                        break;
                    }
                    items.push(self.expr(depth + 1)?);
                    let sep = self.next();
                    match sep.tok {
                        Tok::Comma => {}
                        Tok::RBracket => break,
                        other => {
                            return Err(syntax(
                                sep.pos,
                                format!(
                                    "expected `,` or `]` in a list, found {}",
                                    other.describe()
                                ),
                            ));
                        }
                    }
                }
                ExprKind::List(items)
            }
            Tok::LBrace => {
                let mut items = Vec::new();
                loop {
                    let k = self.next();
                    let key = match k.tok {
                        Tok::RBrace => break,
                        Tok::Str(s) | Tok::Ident(s) => s,
                        other => {
                            return Err(syntax(
                                k.pos,
                                format!(
                                    "expected a parameter name (a string) or `}}`, found {}",
                                    other.describe()
                                ),
                            ));
                        }
                    };
                    self.expect(Tok::Colon, "`:` after a parameter name")?;
                    let v = self.expr(depth + 1)?;
                    items.push((key, k.pos, v));
                    let sep = self.next();
                    match sep.tok {
                        Tok::Comma => {}
                        Tok::RBrace => break,
                        other => {
                            return Err(syntax(
                                sep.pos,
                                format!(
                                    "expected `,` or `}}` in a parameter map, found {}",
                                    other.describe()
                                ),
                            ));
                        }
                    }
                }
                ExprKind::Map(items)
            }
            other => {
                return Err(syntax(
                    t.pos,
                    format!("expected an expression, found {}", other.describe()),
                ));
            }
        };
        Ok(Expr {
            kind,
            pos: t.pos,
            span: (start, self.prev_end()),
        })
    }

    /// Arguments after `(`, through the closing `)`.
    fn args(&mut self, depth: usize) -> Result<Vec<Arg>, RewardError> {
        let mut args = Vec::new();
        loop {
            if self.peek().tok == Tok::RParen {
                self.next();
                return Ok(args);
            }
            let is_kw = matches!(self.peek().tok, Tok::Ident(_))
                && self.toks.get(self.i + 1).is_some_and(|t| t.tok == Tok::Eq);
            let name = if is_kw {
                let t = self.next();
                self.next();
                match t.tok {
                    Tok::Ident(n) => Some((n, t.pos)),
                    _ => None,
                }
            } else {
                None
            };
            let value = self.expr(depth + 1)?;
            args.push(Arg { name, value });
            let sep = self.next();
            match sep.tok {
                Tok::Comma => {}
                Tok::RParen => return Ok(args),
                Tok::Eof => {
                    return Err(syntax(sep.pos, "missing `)`: the input ends inside a call"));
                }
                other => {
                    return Err(syntax(
                        sep.pos,
                        format!(
                            "expected `,` or `)` after an argument, found {}",
                            other.describe()
                        ),
                    ));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_calls_maps_lists_and_keywords() {
        let src = r#"AND(PATTERN("a", {"k": 1, x: "y"}), AFTER("a", "b", min_delta=None, first_params={}), X(contains=["cue", "2"],))"#;
        let e = parse(src).unwrap();
        let ExprKind::Call { name, args } = &e.kind else {
            panic!()
        };
        assert_eq!(name, "AND");
        assert_eq!(args.len(), 3);
        assert_eq!(args[0].value.text(src), r#"PATTERN("a", {"k": 1, x: "y"})"#);
        let ExprKind::Call { args: a2, .. } = &args[1].value.kind else {
            panic!()
        };
        assert_eq!(a2[2].name.as_ref().unwrap().0, "min_delta");
        assert_eq!(a2[2].value.kind, ExprKind::None);
    }

    #[test]
    fn syntax_errors_name_the_position() {
        let e = parse("AND(PATTERN(\"a\"),\n  PATTERN(\"b\"").unwrap_err();
        assert_eq!(e.category, ErrorCategory::Syntax);
        assert_eq!(e.pos.line, 2);
        let e = parse("AND(a)").unwrap_err();
        assert_eq!((e.pos.line, e.pos.col), (1, 5));
        let e = parse("PATTERN(\"a\") PATTERN(\"b\")").unwrap_err();
        assert_eq!(e.pos.col, 14);
        let e = parse("").unwrap_err();
        assert_eq!(e.category, ErrorCategory::Syntax);
        let deep = "NOT(".repeat(200) + &")".repeat(200);
        assert_eq!(parse(&deep).unwrap_err().category, ErrorCategory::Syntax);
    }
}
