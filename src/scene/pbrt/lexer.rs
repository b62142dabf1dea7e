//! Tokenizer for the pbrt scene format (v3 and v4 share the lexical syntax).
//!
//! Tokens are: bare words (directives, numbers, bare `true`/`false`), quoted
//! strings (with the escapes `\b \f \n \r \t \\ \' \"`), `[` and `]`. `#` starts a
//! comment to the end of the line. A comment of the form `#ObjectName NAME:…`
//! (written by the Cinema 4D exporter that produced the ISET scenes) becomes a
//! [`TokenKind::NameHint`] token carrying NAME, used for object labels.
//!
//! Every token carries its byte span in its file; a number word is parsed once,
//! here, so large meshes never allocate per number.

/// Index of a source file in the parser's file table.
pub type FileId = u32;

/// Byte range `[start, end)` in file `file`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Span {
    pub file: FileId,
    pub start: usize,
    pub end: usize,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TokenKind {
    /// A bare word: directive name, number, `true`/`false`.
    Word,
    /// A quoted string; the span covers the text between the quotes.
    Str {
        /// True when the string contains a backslash escape (see [`unescape`]).
        escaped: bool,
    },
    LBracket,
    RBracket,
    /// `#ObjectName NAME:…` comment; the span covers NAME.
    NameHint,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Token {
    pub kind: TokenKind,
    pub span: Span,
    /// For a `Word` that reads as a finite number, its value.
    pub num: Option<f64>,
}

/// A lexical error at a byte offset.
#[derive(Clone, Debug, PartialEq)]
pub struct LexError {
    pub offset: usize,
    pub len: usize,
    pub message: String,
}

/// Cursor over one file's bytes.
#[derive(Clone, Debug)]
pub struct Lexer {
    pub file: FileId,
    pub pos: usize,
}

fn is_delim(b: u8) -> bool {
    matches!(
        b,
        b' ' | b'\t' | b'\n' | b'\r' | b'\x0c' | b'\x0b' | b'"' | b'[' | b']' | b'#'
    )
}

impl Lexer {
    pub fn new(file: FileId) -> Self {
        Self { file, pos: 0 }
    }

    /// The next token of `src`, or None at the end of the file.
    pub fn next_token(&mut self, src: &[u8]) -> Result<Option<Token>, LexError> {
        let n = src.len();
        loop {
            // skip white space
            while self.pos < n
                && matches!(
                    src[self.pos],
                    b' ' | b'\t' | b'\n' | b'\r' | b'\x0c' | b'\x0b'
                )
            {
                self.pos += 1;
            }
            if self.pos >= n {
                return Ok(None);
            }
            let start = self.pos;
            let span = |s: usize, e: usize| Span {
                file: self.file,
                start: s,
                end: e,
            };
            match src[start] {
                b'#' => {
                    let mut e = start;
                    while e < n && src[e] != b'\n' && src[e] != b'\r' {
                        e += 1;
                    }
                    self.pos = e;
                    let text = &src[start..e];
                    const HINT: &[u8] = b"#ObjectName ";
                    if text.len() > HINT.len() && text.starts_with(HINT) {
                        let s = start + HINT.len();
                        let mut end = s;
                        while end < e && src[end] != b':' {
                            end += 1;
                        }
                        // trim white space
                        let mut a = s;
                        let mut b = end;
                        while a < b && src[a].is_ascii_whitespace() {
                            a += 1;
                        }
                        while b > a && src[b - 1].is_ascii_whitespace() {
                            b -= 1;
                        }
                        if b > a {
                            return Ok(Some(Token {
                                kind: TokenKind::NameHint,
                                span: span(a, b),
                                num: None,
                            }));
                        }
                    }
                    continue;
                }
                b'[' => {
                    self.pos += 1;
                    return Ok(Some(Token {
                        kind: TokenKind::LBracket,
                        span: span(start, start + 1),
                        num: None,
                    }));
                }
                b']' => {
                    self.pos += 1;
                    return Ok(Some(Token {
                        kind: TokenKind::RBracket,
                        span: span(start, start + 1),
                        num: None,
                    }));
                }
                b'"' => {
                    let mut i = start + 1;
                    let mut escaped = false;
                    loop {
                        if i >= n {
                            return Err(LexError {
                                offset: start,
                                len: 1,
                                message: "unterminated string: end of file before the closing '\"'"
                                    .into(),
                            });
                        }
                        match src[i] {
                            b'"' => break,
                            b'\n' | b'\r' => {
                                return Err(LexError {
                                    offset: start,
                                    len: i - start,
                                    message:
                                        "unterminated string: new line before the closing '\"'"
                                            .into(),
                                });
                            }
                            b'\\' => {
                                escaped = true;
                                if i + 1 >= n {
                                    return Err(LexError {
                                        offset: start,
                                        len: 1,
                                        message: "unterminated string: end of file after '\\'"
                                            .into(),
                                    });
                                }
                                match src[i + 1] {
                                    b'b' | b'f' | b'n' | b'r' | b't' | b'\\' | b'\'' | b'"' => {
                                        i += 2
                                    }
                                    c => {
                                        return Err(LexError {
                                            offset: i,
                                            len: 2,
                                            message: format!(
                                                "unknown escape sequence '\\{}' in string (allowed: \\b \\f \\n \\r \\t \\\\ \\' \\\")",
                                                c as char
                                            ),
                                        });
                                    }
                                }
                            }
                            _ => i += 1,
                        }
                    }
                    self.pos = i + 1;
                    return Ok(Some(Token {
                        kind: TokenKind::Str { escaped },
                        span: span(start + 1, i),
                        num: None,
                    }));
                }
                _ => {
                    let mut e = start;
                    while e < n && !is_delim(src[e]) {
                        e += 1;
                    }
                    self.pos = e;
                    let first = src[start];
                    let num = if first.is_ascii_digit() || matches!(first, b'+' | b'-' | b'.') {
                        fast_decimal(&src[start..e]).or_else(|| {
                            std::str::from_utf8(&src[start..e])
                                .ok()
                                .and_then(parse_number)
                        })
                    } else {
                        None
                    };
                    return Ok(Some(Token {
                        kind: TokenKind::Word,
                        span: span(start, e),
                        num,
                    }));
                }
            }
        }
    }
}

/// Parse a pbrt number (`1`, `-2`, `+3.`, `.5`, `1e-3`, `2.5E+4`); None for
/// anything else, including `inf`/`nan`.
pub fn parse_number(s: &str) -> Option<f64> {
    let b = s.as_bytes();
    if let Some(v) = fast_decimal(b) {
        return Some(v);
    }
    // Rust's parser accepts "inf"/"nan"/"infinity"; pbrt does not.
    if !b
        .iter()
        .all(|c| c.is_ascii_digit() || matches!(c, b'+' | b'-' | b'.' | b'e' | b'E'))
    {
        return None;
    }
    let v: f64 = s.parse().ok()?;
    v.is_finite().then_some(v)
}

/// Exact fast path for plain decimals (`-12`, `0.125`, `3.`) with at most 15
/// significant digits and no exponent: the digits form an integer m < 10^15 < 2^53
/// and 10^k (k ≤ 22) is exact, so m / 10^k is one correctly rounded division — the
/// same value the general parser returns (Clinger's fast path). None otherwise.
fn fast_decimal(b: &[u8]) -> Option<f64> {
    const POW10: [f64; 23] = [
        1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
        1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
    ];
    let (neg, digits) = match b.first()? {
        b'-' => (true, &b[1..]),
        b'+' => (false, &b[1..]),
        _ => (false, b),
    };
    let mut m: u64 = 0;
    let mut n_digits = 0usize;
    let mut frac: Option<usize> = None;
    for &c in digits {
        match c {
            b'0'..=b'9' => {
                m = m * 10 + (c - b'0') as u64;
                n_digits += 1;
                if let Some(f) = frac.as_mut() {
                    *f += 1;
                }
                if n_digits > 15 {
                    return None;
                }
            }
            b'.' if frac.is_none() => frac = Some(0),
            _ => return None,
        }
    }
    if n_digits == 0 {
        return None;
    }
    let v = m as f64 / POW10[frac.unwrap_or(0)];
    Some(if neg { -v } else { v })
}

/// Resolve the escapes of a quoted string's contents.
pub fn unescape(raw: &[u8]) -> String {
    let mut out = Vec::with_capacity(raw.len());
    let mut i = 0;
    while i < raw.len() {
        if raw[i] == b'\\' && i + 1 < raw.len() {
            out.push(match raw[i + 1] {
                b'b' => 0x08,
                b'f' => 0x0c,
                b'n' => b'\n',
                b'r' => b'\r',
                b't' => b'\t',
                c => c,
            });
            i += 2;
        } else {
            out.push(raw[i]);
            i += 1;
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all(src: &str) -> Vec<(TokenKind, String, Option<f64>)> {
        let mut l = Lexer::new(0);
        let mut v = vec![];
        while let Some(t) = l.next_token(src.as_bytes()).unwrap() {
            v.push((t.kind, src[t.span.start..t.span.end].to_string(), t.num));
        }
        v
    }

    #[test]
    fn tokens_and_numbers() {
        let t = all("Shape \"sphere\" \"float radius\" [ 1.5e1 -.5 +3. 7 ] # comment\n 2");
        assert_eq!(t[0], (TokenKind::Word, "Shape".into(), None));
        assert_eq!(t[1].1, "sphere");
        assert_eq!(t[3].0, TokenKind::LBracket);
        assert_eq!(t[4].2, Some(15.0));
        assert_eq!(t[5].2, Some(-0.5));
        assert_eq!(t[6].2, Some(3.0));
        assert_eq!(t[7].2, Some(7.0));
        assert_eq!(t[8].0, TokenKind::RBracket);
        assert_eq!(t[9].2, Some(2.0));
        assert_eq!(t.len(), 10);
    }

    #[test]
    fn brackets_need_no_spaces_and_hints_are_tokens() {
        let t = all("[1 2][\"a\"]#ObjectName Box:Vector(1)\n");
        assert_eq!(t.len(), 8);
        assert_eq!(t[7], (TokenKind::NameHint, "Box".into(), None));
    }

    #[test]
    fn escapes_and_errors() {
        let src = r#""a\"b\\c\n""#;
        let mut l = Lexer::new(0);
        let t = l.next_token(src.as_bytes()).unwrap().unwrap();
        assert_eq!(t.kind, TokenKind::Str { escaped: true });
        assert_eq!(
            unescape(&src.as_bytes()[t.span.start..t.span.end]),
            "a\"b\\c\n"
        );
        let mut l = Lexer::new(0);
        let e = l.next_token(b"  \"abc\nx").unwrap_err();
        assert_eq!(e.offset, 2);
        assert!(e.message.contains("unterminated"));
        assert!(Lexer::new(0).next_token(b"\"abc").is_err());
        assert!(Lexer::new(0).next_token(b"\"a\\qb\"").is_err());
        assert_eq!(parse_number("inf"), None);
        assert_eq!(parse_number("1e400"), None);
        assert_eq!(parse_number("1."), Some(1.0));
        assert_eq!(parse_number("."), None);
        assert_eq!(parse_number("-"), None);
        assert_eq!(parse_number("1.2.3"), None);
    }

    #[test]
    fn fast_path_agrees_with_the_general_parser() {
        // Deterministic sample of decimals of up to 15 digits, both signs, all positions of '.'.
        let mut x: u64 = 0x2545_F491_4F6C_DD1D;
        for _ in 0..200_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let digits = (x % 1_000_000_000_000_000) as u128;
            let mut s = digits.to_string();
            let dot = (x >> 50) as usize % (s.len() + 1);
            s.insert(dot, '.');
            if x & 1 == 1 {
                s.insert(0, '-');
            }
            let want: f64 = s.parse().unwrap();
            assert_eq!(
                parse_number(&s).map(f64::to_bits),
                Some(want.to_bits()),
                "{s}"
            );
        }
    }
}
