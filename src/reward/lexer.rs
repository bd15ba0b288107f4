//! The lexer: program text to tokens with positions. `#` starts a comment to the end of the line.
//! Strings take double or single quotes with `\"`, `\'`, `\\`, `\n` and `\t` escapes.

use super::error::{ErrorCategory, Pos, RewardError};

/// A token's kind (and value).
#[derive(Debug, Clone, PartialEq)]
pub enum Tok {
    /// A name: function, keyword argument, `None`, `True`, `False`.
    Ident(String),
    /// A string literal (unescaped).
    Str(String),
    /// A number literal.
    Num(f64),
    /// `(`
    LParen,
    /// `)`
    RParen,
    /// `{`
    LBrace,
    /// `}`
    RBrace,
    /// `[`
    LBracket,
    /// `]`
    RBracket,
    /// `,`
    Comma,
    /// `:`
    Colon,
    /// `=`
    Eq,
    /// End of input.
    Eof,
}

impl Tok {
    /// How the token reads in an error message.
    pub fn describe(&self) -> String {
        match self {
            Tok::Ident(s) => format!("name `{s}`"),
            Tok::Str(s) => format!("string {s:?}"),
            Tok::Num(n) => format!("number {n}"),
            Tok::LParen => "`(`".into(),
            Tok::RParen => "`)`".into(),
            Tok::LBrace => "`{`".into(),
            Tok::RBrace => "`}`".into(),
            Tok::LBracket => "`[`".into(),
            Tok::RBracket => "`]`".into(),
            Tok::Comma => "`,`".into(),
            Tok::Colon => "`:`".into(),
            Tok::Eq => "`=`".into(),
            Tok::Eof => "end of input".into(),
        }
    }
}

/// A token and where it starts; `end` is the byte offset just past it.
#[derive(Debug, Clone, PartialEq)]
pub struct Token {
    /// The token.
    pub tok: Tok,
    /// Its first character.
    pub pos: Pos,
    /// Byte offset just past it.
    pub end: usize,
}

/// Largest program the lexer accepts (bytes); longer text is a syntax error, not a slow parse.
pub const MAX_PROGRAM_BYTES: usize = 256 * 1024;

struct Cursor<'a> {
    text: &'a str,
    chars: std::iter::Peekable<std::str::CharIndices<'a>>,
    line: u32,
    col: u32,
}

impl Cursor<'_> {
    fn pos(&mut self) -> Pos {
        let offset = self
            .chars
            .peek()
            .map(|(i, _)| *i)
            .unwrap_or(self.text.len());
        Pos {
            line: self.line,
            col: self.col,
            offset,
        }
    }
    fn peek(&mut self) -> Option<char> {
        self.chars.peek().map(|(_, c)| *c)
    }
    fn bump(&mut self) -> Option<char> {
        let (_, c) = self.chars.next()?;
        if c == '\n' {
            self.line += 1;
            self.col = 1;
        } else {
            self.col += 1;
        }
        Some(c)
    }
    fn offset(&mut self) -> usize {
        self.chars
            .peek()
            .map(|(i, _)| *i)
            .unwrap_or(self.text.len())
    }
}

fn syntax(pos: Pos, message: impl Into<String>) -> RewardError {
    RewardError::new(ErrorCategory::Syntax, pos, message)
}

/// Splits `text` into tokens, ending with [`Tok::Eof`].
pub fn lex(text: &str) -> Result<Vec<Token>, RewardError> {
    if text.len() > MAX_PROGRAM_BYTES {
        return Err(syntax(
            Pos {
                line: 1,
                col: 1,
                offset: 0,
            },
            format!(
                "program is {} bytes; the limit is {MAX_PROGRAM_BYTES}",
                text.len()
            ),
        ));
    }
    let mut c = Cursor {
        text,
        chars: text.char_indices().peekable(),
        line: 1,
        col: 1,
    };
    let mut out = Vec::new();
    loop {
        while let Some(ch) = c.peek() {
            if ch.is_whitespace() {
                c.bump();
            } else if ch == '#' {
                while let Some(ch) = c.peek() {
                    if ch == '\n' {
                        break;
                    }
                    c.bump();
                }
            } else {
                break;
            }
        }
        let pos = c.pos();
        let Some(ch) = c.peek() else {
            out.push(Token {
                tok: Tok::Eof,
                pos,
                end: text.len(),
            });
            return Ok(out);
        };
        let tok = match ch {
            '(' | ')' | '{' | '}' | '[' | ']' | ',' | ':' | '=' => {
                c.bump();
                match ch {
                    '(' => Tok::LParen,
                    ')' => Tok::RParen,
                    '{' => Tok::LBrace,
                    '}' => Tok::RBrace,
                    '[' => Tok::LBracket,
                    ']' => Tok::RBracket,
                    ',' => Tok::Comma,
                    ':' => Tok::Colon,
                    _ => Tok::Eq,
                }
            }
            '"' | '\'' => Tok::Str(string(&mut c, ch, pos)?),
            '0'..='9' | '-' | '+' | '.' => Tok::Num(number(&mut c, pos)?),
            ch if ch.is_alphabetic() || ch == '_' => {
                let start = c.offset();
                while c.peek().is_some_and(|ch| ch.is_alphanumeric() || ch == '_') {
                    c.bump();
                }
                Tok::Ident(text[start..c.offset()].to_string())
            }
            other => {
                return Err(syntax(pos, format!("unexpected character {other:?}")));
            }
        };
        let end = c.offset();
        out.push(Token { tok, pos, end });
    }
}

fn string(c: &mut Cursor<'_>, quote: char, pos: Pos) -> Result<String, RewardError> {
    c.bump();
    let mut s = String::new();
    loop {
        match c.bump() {
            None | Some('\n') => {
                return Err(syntax(
                    pos,
                    "string is not closed before the end of the line",
                ));
            }
            Some('\\') => {
                let at = c.pos();
                match c.bump() {
                    Some('n') => s.push('\n'),
                    Some('t') => s.push('\t'),
                    Some(e @ ('\\' | '"' | '\'')) => s.push(e),
                    Some(e) => {
                        return Err(syntax(at, format!("unknown escape `\\{e}` in a string")));
                    }
                    None => return Err(syntax(at, "string ends with a lone backslash")),
                }
            }
            Some(ch) if ch == quote => return Ok(s),
            Some(ch) => s.push(ch),
        }
    }
}

fn number(c: &mut Cursor<'_>, pos: Pos) -> Result<f64, RewardError> {
    let start = c.offset();
    if matches!(c.peek(), Some('-' | '+')) {
        c.bump();
    }
    let mut prev = ' ';
    while let Some(ch) = c.peek() {
        let ok = ch.is_ascii_digit()
            || ch == '.'
            || ch == 'e'
            || ch == 'E'
            || ((ch == '-' || ch == '+') && (prev == 'e' || prev == 'E'));
        if !ok {
            break;
        }
        prev = ch;
        c.bump();
    }
    let text = &c.text[start..c.offset()];
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(syntax(pos, format!("malformed number `{text}`"))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_and_positions() {
        let t = lex("AND(\n  PATTERN('a b', x=-1.5e1), # c\n [1])").unwrap();
        assert_eq!(t[0].tok, Tok::Ident("AND".into()));
        assert_eq!(t[2].tok, Tok::Ident("PATTERN".into()));
        assert_eq!((t[2].pos.line, t[2].pos.col), (2, 3));
        assert_eq!(t[4].tok, Tok::Str("a b".into()));
        assert_eq!(t[8].tok, Tok::Num(-15.0));
        assert_eq!(t.last().unwrap().tok, Tok::Eof);
    }

    #[test]
    fn errors_have_positions() {
        let e = lex("AND(\"abc").unwrap_err();
        assert_eq!((e.pos.line, e.pos.col), (1, 5));
        let e = lex("A(1.2.3)").unwrap_err();
        assert_eq!(e.category, ErrorCategory::Syntax);
        assert_eq!(e.pos.col, 3);
        let e = lex("A(@)").unwrap_err();
        assert_eq!(e.pos.col, 3);
    }
}
