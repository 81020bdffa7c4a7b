//! Monitor expressions: `min(denning.sonar.range[0..3]) < 0.254 and not bumper.hit.any`.
//!
//! Grammar (lowest precedence first):
//! ```text
//! expr    := and ('or' and)*
//! and     := not ('and' not)*
//! not     := 'not' not | cmp
//! cmp     := sum (('<' | '<=' | '>' | '>=' | '==' | '!=') sum)?
//! sum     := product (('+' | '-') product)*
//! product := unary (('*' | '/') unary)*
//! unary   := '-' unary | atom
//! atom    := number | 'true' | 'false' | ('min' | 'max') '(' path ')' | path | '(' expr ')'
//! path    := skill '.' output ('.' field | '[' index ']' | '[' a '..' b ']' | '[' a '..=' b ']')*
//! ```
//! A `-` inside a name is part of it when a letter follows (`work-async.out.value`); write
//! `x - 1` or `x-1` for subtraction. The whole expression must be a condition (boolean);
//! comparisons take numbers; `and`/`or`/`not` take conditions. A path without `min`/`max`
//! must name one number; inside them it names an array or a range.

/// A reference to a value of a skill's output (the one path parser is proto's).
pub use skillfab_proto::value::OutputPath as PathRef;

/// Arithmetic operators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Arith {
    /// `+`
    Add,
    /// `-`
    Sub,
    /// `*`
    Mul,
    /// `/`
    Div,
}

/// Comparison operators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cmp {
    /// `<`
    Lt,
    /// `<=`
    Le,
    /// `>`
    Gt,
    /// `>=`
    Ge,
    /// `==`
    Eq,
    /// `!=`
    Ne,
}

/// A parsed expression.
#[derive(Debug, Clone, PartialEq)]
pub enum Expr {
    /// A number literal.
    Num(f64),
    /// `true` or `false`.
    Bool(bool),
    /// A value of a skill's output (`skill.port.field`).
    Path(PathRef),
    /// `min(skill.port.field)`: the least number in an array field.
    Min(PathRef),
    /// `max(skill.port.field)`: the greatest number in an array field.
    Max(PathRef),
    /// `-e`
    Neg(Box<Expr>),
    /// `a + b`, `a - b`, `a * b`, `a / b`
    Arith(Arith, Box<Expr>, Box<Expr>),
    /// `a < b` and the other comparisons.
    Cmp(Cmp, Box<Expr>, Box<Expr>),
    /// `a && b`
    And(Box<Expr>, Box<Expr>),
    /// `a || b`
    Or(Box<Expr>, Box<Expr>),
    /// `!e`
    Not(Box<Expr>),
}

pub use skillfab_proto::control::{ExprError, ExprProblem};

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(f64),
    Ident(String),
    Path(String),
    Op(&'static str),
    LParen,
    RParen,
}

fn lex(src: &str) -> Result<Vec<(usize, Tok)>, ExprError> {
    let b = src.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    let err = |position, problem: ExprProblem| ExprError { position, problem };
    while i < b.len() {
        let c = b[i];
        if c.is_ascii_whitespace() {
            i += 1;
        } else if c.is_ascii_digit() || (c == b'.' && b.get(i + 1).is_some_and(u8::is_ascii_digit))
        {
            let start = i;
            while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') {
                i += 1;
            }
            if i < b.len() && (b[i] == b'e' || b[i] == b'E') {
                i += 1;
                if i < b.len() && (b[i] == b'+' || b[i] == b'-') {
                    i += 1;
                }
                while i < b.len() && b[i].is_ascii_digit() {
                    i += 1;
                }
            }
            let text = &src[start..i];
            let v: f64 = text.parse().map_err(|_| {
                err(
                    start,
                    ExprProblem::BadNumber {
                        text: text.to_string(),
                    },
                )
            })?;
            out.push((start, Tok::Num(v)));
        } else if c.is_ascii_alphabetic() || c == b'_' {
            let start = i;
            let mut dotted = false;
            loop {
                while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                    i += 1;
                }
                let next = b.get(i + 1).copied().unwrap_or(0);
                match b.get(i) {
                    Some(b'-') if next.is_ascii_alphabetic() || next == b'_' => i += 1,
                    Some(b'.') if next.is_ascii_alphabetic() || next == b'_' => {
                        dotted = true;
                        i += 1;
                    }
                    Some(b'[') if dotted => {
                        let end = src[i..]
                            .find(']')
                            .ok_or_else(|| err(i, ExprProblem::UnclosedIndex))?;
                        i += end + 1;
                    }
                    _ => break,
                }
            }
            let text = src[start..i].to_string();
            out.push((
                start,
                if dotted {
                    Tok::Path(text)
                } else {
                    Tok::Ident(text)
                },
            ));
        } else {
            let two = src.get(i..i + 2).unwrap_or("");
            let (tok, n) = match two {
                "<=" => (Tok::Op("<="), 2),
                ">=" => (Tok::Op(">="), 2),
                "==" => (Tok::Op("=="), 2),
                "!=" => (Tok::Op("!="), 2),
                "&&" => (Tok::Op("and"), 2),
                "||" => (Tok::Op("or"), 2),
                _ => match c {
                    b'<' => (Tok::Op("<"), 1),
                    b'>' => (Tok::Op(">"), 1),
                    b'+' => (Tok::Op("+"), 1),
                    b'-' => (Tok::Op("-"), 1),
                    b'*' => (Tok::Op("*"), 1),
                    b'/' => (Tok::Op("/"), 1),
                    b'!' => (Tok::Op("not"), 1),
                    b'(' => (Tok::LParen, 1),
                    b')' => (Tok::RParen, 1),
                    _ => {
                        let ch = src[i..].chars().next().unwrap_or('?');
                        return Err(err(i, ExprProblem::UnexpectedChar { ch }));
                    }
                },
            };
            out.push((i, tok));
            i += n;
        }
    }
    Ok(out)
}

struct Parser {
    toks: Vec<(usize, Tok)>,
    pos: usize,
    end: usize,
}

impl Parser {
    fn peek(&self) -> Option<&Tok> {
        self.toks.get(self.pos).map(|(_, t)| t)
    }
    fn at(&self) -> usize {
        self.toks.get(self.pos).map_or(self.end, |(p, _)| *p)
    }
    fn err(&self, problem: ExprProblem) -> ExprError {
        ExprError {
            position: self.at(),
            problem,
        }
    }
    fn eat_op(&mut self, op: &str) -> bool {
        let word = matches!(self.peek(), Some(Tok::Ident(w)) if w == op);
        if matches!(self.peek(), Some(Tok::Op(o)) if *o == op) || word {
            self.pos += 1;
            true
        } else {
            false
        }
    }
    fn or(&mut self) -> Result<Expr, ExprError> {
        let mut l = self.and()?;
        while self.eat_op("or") {
            l = Expr::Or(Box::new(l), Box::new(self.and()?));
        }
        Ok(l)
    }
    fn and(&mut self) -> Result<Expr, ExprError> {
        let mut l = self.not()?;
        while self.eat_op("and") {
            l = Expr::And(Box::new(l), Box::new(self.not()?));
        }
        Ok(l)
    }
    fn not(&mut self) -> Result<Expr, ExprError> {
        if self.eat_op("not") {
            return Ok(Expr::Not(Box::new(self.not()?)));
        }
        self.cmp()
    }
    fn cmp(&mut self) -> Result<Expr, ExprError> {
        let l = self.sum()?;
        for (s, op) in [
            ("<=", Cmp::Le),
            (">=", Cmp::Ge),
            ("<", Cmp::Lt),
            (">", Cmp::Gt),
            ("==", Cmp::Eq),
            ("!=", Cmp::Ne),
        ] {
            if self.eat_op(s) {
                return Ok(Expr::Cmp(op, Box::new(l), Box::new(self.sum()?)));
            }
        }
        Ok(l)
    }
    fn sum(&mut self) -> Result<Expr, ExprError> {
        let mut l = self.product()?;
        loop {
            let op = if self.eat_op("+") {
                Arith::Add
            } else if self.eat_op("-") {
                Arith::Sub
            } else {
                return Ok(l);
            };
            l = Expr::Arith(op, Box::new(l), Box::new(self.product()?));
        }
    }
    fn product(&mut self) -> Result<Expr, ExprError> {
        let mut l = self.unary()?;
        loop {
            let op = if self.eat_op("*") {
                Arith::Mul
            } else if self.eat_op("/") {
                Arith::Div
            } else {
                return Ok(l);
            };
            l = Expr::Arith(op, Box::new(l), Box::new(self.unary()?));
        }
    }
    fn unary(&mut self) -> Result<Expr, ExprError> {
        if self.eat_op("-") {
            return Ok(Expr::Neg(Box::new(self.unary()?)));
        }
        self.atom()
    }
    fn path(&mut self, text: String, at: usize) -> Result<PathRef, ExprError> {
        PathRef::parse(&text).map_err(|e| ExprError {
            position: at,
            problem: e.into(),
        })
    }
    fn atom(&mut self) -> Result<Expr, ExprError> {
        let at = self.at();
        let tok = self
            .peek()
            .cloned()
            .ok_or_else(|| self.err(ExprProblem::EndsEarly))?;
        self.pos += 1;
        match tok {
            Tok::Num(v) => Ok(Expr::Num(v)),
            Tok::Path(p) => Ok(Expr::Path(self.path(p, at)?)),
            Tok::LParen => {
                let e = self.or()?;
                if self.peek() != Some(&Tok::RParen) {
                    return Err(self.err(ExprProblem::UnclosedParen));
                }
                self.pos += 1;
                Ok(e)
            }
            Tok::Ident(w) if w == "true" => Ok(Expr::Bool(true)),
            Tok::Ident(w) if w == "false" => Ok(Expr::Bool(false)),
            Tok::Ident(w) if w == "min" || w == "max" => {
                if self.peek() != Some(&Tok::LParen) {
                    return Err(self.err(ExprProblem::CallWithoutParen { function: w }));
                }
                self.pos += 1;
                let at = self.at();
                let Some(Tok::Path(p)) = self.peek().cloned() else {
                    return Err(self.err(ExprProblem::CallWithoutPath { function: w }));
                };
                self.pos += 1;
                let path = self.path(p, at)?;
                if self.peek() != Some(&Tok::RParen) {
                    return Err(self.err(ExprProblem::UnclosedParen));
                }
                self.pos += 1;
                Ok(if w == "min" {
                    Expr::Min(path)
                } else {
                    Expr::Max(path)
                })
            }
            Tok::Ident(w) => Err(ExprError {
                position: at,
                problem: ExprProblem::NotAValue { word: w },
            }),
            Tok::Op(o) => Err(ExprError {
                position: at,
                problem: ExprProblem::UnexpectedToken {
                    token: o.to_string(),
                },
            }),
            Tok::RParen => Err(ExprError {
                position: at,
                problem: ExprProblem::UnexpectedToken { token: ")".into() },
            }),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Ty {
    Num,
    Bool,
}

fn type_of(e: &Expr) -> Result<Ty, ExprProblem> {
    let want = |e: &Expr, t: Ty, what: &str| -> Result<(), ExprProblem> {
        let got = type_of(e)?;
        if got == t {
            Ok(())
        } else {
            Err(ExprProblem::WrongOperand {
                operator: what.into(),
                number: t == Ty::Num,
            })
        }
    };
    Ok(match e {
        Expr::Num(_) | Expr::Path(_) | Expr::Min(_) | Expr::Max(_) => Ty::Num,
        Expr::Bool(_) => Ty::Bool,
        Expr::Neg(x) => {
            want(x, Ty::Num, "'-'")?;
            Ty::Num
        }
        Expr::Arith(_, l, r) => {
            want(l, Ty::Num, "arithmetic")?;
            want(r, Ty::Num, "arithmetic")?;
            Ty::Num
        }
        Expr::Cmp(_, l, r) => {
            want(l, Ty::Num, "a comparison")?;
            want(r, Ty::Num, "a comparison")?;
            Ty::Bool
        }
        Expr::And(l, r) | Expr::Or(l, r) => {
            want(l, Ty::Bool, "'and'/'or'")?;
            want(r, Ty::Bool, "'and'/'or'")?;
            Ty::Bool
        }
        Expr::Not(x) => {
            want(x, Ty::Bool, "'not'")?;
            Ty::Bool
        }
    })
}

/// Parses a condition. Never panics, whatever the input.
pub fn parse(src: &str) -> Result<Expr, ExprError> {
    if src.len() > ExprProblem::MAX_LEN {
        return Err(ExprError {
            position: ExprProblem::MAX_LEN,
            problem: ExprProblem::TooLong {
                max: ExprProblem::MAX_LEN,
            },
        });
    }
    let toks = lex(src)?;
    let mut p = Parser {
        toks,
        pos: 0,
        end: src.len(),
    };
    let e = p.or_depth_checked()?;
    if p.pos != p.toks.len() {
        return Err(p.err(ExprProblem::TrailingText));
    }
    match type_of(&e) {
        Ok(Ty::Bool) => Ok(e),
        Ok(Ty::Num) => Err(ExprError {
            position: 0,
            problem: ExprProblem::NotACondition,
        }),
        Err(problem) => Err(ExprError {
            position: 0,
            problem,
        }),
    }
}

impl Parser {
    fn or_depth_checked(&mut self) -> Result<Expr, ExprError> {
        // Deep nesting would recurse deeply; 64 open parentheses is far past any monitor.
        let depth = self.toks.iter().filter(|(_, t)| *t == Tok::LParen).count();
        if depth > 64 {
            return Err(self.err(ExprProblem::TooDeep {
                what: "parentheses".into(),
                max: 64,
            }));
        }
        let nots = self
            .toks
            .iter()
            .filter(|(_, t)| matches!(t, Tok::Op("not" | "-")))
            .count();
        if nots > 64 {
            return Err(self.err(ExprProblem::TooDeep {
                what: "'not'/'-' operators".into(),
                max: 64,
            }));
        }
        self.or()
    }
}

/// Every path an expression reads.
pub fn paths(e: &Expr) -> Vec<&PathRef> {
    let mut out = Vec::new();
    fn walk<'a>(e: &'a Expr, out: &mut Vec<&'a PathRef>) {
        match e {
            Expr::Path(p) | Expr::Min(p) | Expr::Max(p) => out.push(p),
            Expr::Neg(x) | Expr::Not(x) => walk(x, out),
            Expr::Arith(_, l, r) | Expr::Cmp(_, l, r) | Expr::And(l, r) | Expr::Or(l, r) => {
                walk(l, out);
                walk(r, out);
            }
            Expr::Num(_) | Expr::Bool(_) => {}
        }
    }
    walk(e, &mut out);
    out
}

/// Evaluates a condition; `values` gives the numbers at a path (one for a scalar, all
/// elements for an array or range). A missing value makes the condition false.
pub fn eval(e: &Expr, values: &dyn Fn(&PathRef) -> Option<Vec<f64>>) -> bool {
    fn num(e: &Expr, v: &dyn Fn(&PathRef) -> Option<Vec<f64>>) -> Option<f64> {
        Some(match e {
            Expr::Num(x) => *x,
            Expr::Path(p) => *v(p)?.first()?,
            Expr::Min(p) => v(p)?.into_iter().reduce(f64::min)?,
            Expr::Max(p) => v(p)?.into_iter().reduce(f64::max)?,
            Expr::Neg(x) => -num(x, v)?,
            Expr::Arith(op, l, r) => {
                let (a, b) = (num(l, v)?, num(r, v)?);
                match op {
                    Arith::Add => a + b,
                    Arith::Sub => a - b,
                    Arith::Mul => a * b,
                    Arith::Div => a / b,
                }
            }
            _ => return None,
        })
    }
    match e {
        Expr::Bool(b) => *b,
        Expr::Cmp(op, l, r) => match (num(l, values), num(r, values)) {
            (Some(a), Some(b)) => match op {
                Cmp::Lt => a < b,
                Cmp::Le => a <= b,
                Cmp::Gt => a > b,
                Cmp::Ge => a >= b,
                Cmp::Eq => a == b,
                Cmp::Ne => a != b,
            },
            _ => false,
        },
        Expr::And(l, r) => eval(l, values) && eval(r, values),
        Expr::Or(l, r) => eval(l, values) || eval(r, values),
        Expr::Not(x) => !eval(x, values),
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vals(p: &PathRef) -> Option<Vec<f64>> {
        match p.text.as_str() {
            "d.sonar.range[0..3]" => Some(vec![0.5, 0.2, 0.9]),
            "t.tick.value" => Some(vec![51.0]),
            "work-async.out.value" => Some(vec![2.0]),
            "a.b" => Some(vec![1.0]),
            _ => None,
        }
    }

    #[test]
    fn paths_split_into_skill_output_field() {
        let e = parse("min(d.sonar.range[0..3]) < 0.254").unwrap();
        let p = paths(&e);
        assert_eq!(p[0].skill, "d");
        assert_eq!(p[0].output, "sonar");
        assert_eq!(p[0].field, "range[0..3]");
        let e = parse("a.b[2].x > 0").unwrap();
        assert_eq!(paths(&e)[0].field, "[2].x");
    }

    #[test]
    fn evaluates_with_precedence() {
        assert!(eval(
            &parse("min(d.sonar.range[0..3]) < 0.254").unwrap(),
            &vals
        ));
        assert!(!eval(
            &parse("max(d.sonar.range[0..3]) < 0.254").unwrap(),
            &vals
        ));
        assert!(eval(
            &parse("t.tick.value > 50 and not t.tick.value >= 52").unwrap(),
            &vals
        ));
        assert!(eval(
            &parse("t.tick.value - 1 == 50 or false").unwrap(),
            &vals
        ));
        assert!(eval(&parse("t.tick.value-1 == 2*25").unwrap(), &vals));
        assert!(eval(&parse("work-async.out.value == 2").unwrap(), &vals));
        assert!(eval(
            &parse("(a.b + 1) * 2 == 4 && !(a.b != 1)").unwrap(),
            &vals
        ));
        assert!(eval(&parse("-a.b < 0").unwrap(), &vals));
        assert!(
            !eval(&parse("missing.x.y > 0").unwrap(), &vals),
            "missing values are false"
        );
        assert!(eval(&parse("not missing.x.y > 0").unwrap(), &vals));
    }

    #[test]
    fn errors_have_positions() {
        let e = parse("t.tick.value > ").unwrap_err();
        assert_eq!(e.position, 15);
        assert!(
            parse("t.tick.value")
                .unwrap_err()
                .problem
                .to_string()
                .contains("condition")
        );
        assert!(
            parse("t.tick.value > 1 2")
                .unwrap_err()
                .problem
                .to_string()
                .contains("after")
        );
        assert!(
            parse("foo > 1")
                .unwrap_err()
                .problem
                .to_string()
                .contains("not a value")
        );
        assert!(
            parse("(a.b > 1) + 1 > 0")
                .unwrap_err()
                .problem
                .to_string()
                .contains("number")
        );
        assert!(
            parse("a.b > 1 and 3")
                .unwrap_err()
                .problem
                .to_string()
                .contains("condition")
        );
        assert!(parse("min(3) < 1").is_err());
        assert!(
            parse("a.b # 1")
                .unwrap_err()
                .problem
                .to_string()
                .contains("'#'")
        );
        assert!(parse(&"(".repeat(100)).is_err());
    }

    proptest::proptest! {
        #[test]
        fn any_text_parses_or_errors_without_panicking(s in ".{0,64}") {
            if let Ok(e) = parse(&s) {
                let _ = eval(&e, &vals);
            }
        }

        #[test]
        fn comparisons_agree_with_f64(a in -1e6f64..1e6, b in -1e6f64..1e6) {
            let lookup = |p: &PathRef| match p.text.as_str() {
                "x.y.a" => Some(vec![a]),
                "x.y.b" => Some(vec![b]),
                _ => None,
            };
            proptest::prop_assert_eq!(eval(&parse("x.y.a < x.y.b").unwrap(), &lookup), a < b);
            proptest::prop_assert_eq!(eval(&parse("x.y.a - x.y.b >= 0").unwrap(), &lookup), a - b >= 0.0);
            proptest::prop_assert_eq!(eval(&parse("not x.y.a == x.y.b").unwrap(), &lookup), a != b);
        }
    }

    #[test]
    fn arbitrary_bytes_never_panic() {
        // A deterministic sweep of generated inputs: every prefix of a set of tricky strings
        // and a pseudo-random stream over the grammar's alphabet.
        let alphabet: Vec<char> = "ab.[]0123456789-+*/<>=!()& |minaxotrue_ \u{e9}"
            .chars()
            .collect();
        let mut x: u64 = 0x2545_F491_4F6C_DD1D;
        for _ in 0..20_000 {
            let len = (x % 24) as usize;
            let s: String = (0..len)
                .map(|_| {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    alphabet[(x % alphabet.len() as u64) as usize]
                })
                .collect();
            if let Ok(e) = parse(&s) {
                let _ = eval(&e, &vals);
            }
        }
    }
}
