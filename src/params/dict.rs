//! [`ParamDict`]: typed look-ups of a node's properties that mark each one
//! used; [`ParamDict::finish`] reports what no look-up consumed.

use super::{Kind, ParamError, Params, Schema, Value};
use std::cell::RefCell;
use std::collections::BTreeSet;

/// A node's properties as one stage reads them.
pub struct ParamDict<'a> {
    params: &'a Params,
    schema: &'static Schema,
    used: RefCell<BTreeSet<String>>,
}

fn describe(v: &Value) -> String {
    match v {
        Value::Bool(b) => format!("the boolean #{b}"),
        Value::Number(x) => format!("the number {x}"),
        Value::String(s) => format!("the string \"{s}\""),
        Value::List(l) => format!("a list of {}", l.len()),
    }
}

impl<'a> ParamDict<'a> {
    pub fn new(params: &'a Params, schema: &'static Schema) -> Self {
        Self {
            params,
            schema,
            used: RefCell::new(BTreeSet::new()),
        }
    }

    pub fn schema(&self) -> &'static Schema {
        self.schema
    }

    /// The raw value of `name` (marked used); an error when the schema does
    /// not list `name` (a stage must not read undocumented properties).
    pub fn raw(&self, name: &str) -> Result<Option<&'a Value>, ParamError> {
        if self.schema.get(name).is_none() {
            return Err(ParamError::section(format!(
                "internal error: {} reads '{name}', which its schema does not list",
                self.schema.node
            )));
        }
        self.used.borrow_mut().insert(name.to_string());
        Ok(self.params.get(name))
    }

    /// Is `name` written? (Does not mark it used.)
    pub fn has(&self, name: &str) -> bool {
        self.params.get(name).is_some()
    }

    pub fn f64(&self, name: &str) -> Result<Option<f64>, ParamError> {
        match self.raw(name)? {
            None => Ok(None),
            Some(Value::Number(x)) if x.is_finite() => Ok(Some(*x)),
            Some(v) => Err(ParamError::value(
                name,
                format!("'{name}': expected a finite number, found {}", describe(v)),
            )),
        }
    }

    /// A number > 0.
    pub fn positive(&self, name: &str) -> Result<Option<f64>, ParamError> {
        match self.f64(name)? {
            Some(x) if x <= 0.0 => Err(ParamError::value(
                name,
                format!("'{name}' must be > 0, found {x}"),
            )),
            o => Ok(o),
        }
    }

    /// A number ≥ 0.
    pub fn nonneg(&self, name: &str) -> Result<Option<f64>, ParamError> {
        match self.f64(name)? {
            Some(x) if x < 0.0 => Err(ParamError::value(
                name,
                format!("'{name}' must be ≥ 0, found {x}"),
            )),
            o => Ok(o),
        }
    }

    /// A number in `lo..=hi`.
    pub fn in_range(&self, name: &str, lo: f64, hi: f64) -> Result<Option<f64>, ParamError> {
        match self.f64(name)? {
            Some(x) if !(lo..=hi).contains(&x) => Err(ParamError::value(
                name,
                format!("'{name}' = {x} is out of range; expected {lo}…{hi}"),
            )),
            o => Ok(o),
        }
    }

    /// A whole number in `lo..=hi`.
    pub fn int(&self, name: &str, lo: u64, hi: u64) -> Result<Option<u64>, ParamError> {
        match self.raw(name)? {
            None => Ok(None),
            Some(Value::Number(x)) if x.is_finite() && x.fract() == 0.0 => {
                if *x < lo as f64 || *x > hi as f64 {
                    Err(ParamError::value(
                        name,
                        format!("'{name}' = {x} is out of range; expected {lo}…{hi}"),
                    ))
                } else {
                    Ok(Some(*x as u64))
                }
            }
            Some(v) => Err(ParamError::value(
                name,
                format!("'{name}': expected a whole number, found {}", describe(v)),
            )),
        }
    }

    pub fn str(&self, name: &str) -> Result<Option<&'a str>, ParamError> {
        match self.raw(name)? {
            None => Ok(None),
            Some(Value::String(s)) => Ok(Some(s.as_str())),
            Some(v) => Err(ParamError::value(
                name,
                format!("'{name}': expected a string, found {}", describe(v)),
            )),
        }
    }

    /// One of the strings of the schema's `Kind::Choice` for `name`.
    pub fn choice(&self, name: &str) -> Result<Option<&'a str>, ParamError> {
        let Some(s) = self.str(name)? else {
            return Ok(None);
        };
        let options: &[&str] = match self.schema.get(name).map(|p| p.kind) {
            Some(Kind::Choice(c)) => c,
            _ => {
                return Err(ParamError::section(format!(
                    "internal error: '{name}' of {} is not a choice",
                    self.schema.node
                )));
            }
        };
        if options.contains(&s) {
            return Ok(Some(s));
        }
        let mut e = ParamError::value(
            name,
            format!(
                "'{name}' = \"{s}\"; expected one of: {}",
                options
                    .iter()
                    .map(|o| format!("\"{o}\""))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        );
        e.help = crate::diag::did_you_mean(s, options.iter().copied())
            .map(|x| format!("did you mean \"{x}\"?"));
        Err(e)
    }

    pub fn bool(&self, name: &str) -> Result<Option<bool>, ParamError> {
        match self.raw(name)? {
            None => Ok(None),
            Some(Value::Bool(b)) => Ok(Some(*b)),
            Some(v) => Err(ParamError::value(
                name,
                format!("'{name}': expected #true or #false, found {}", describe(v)),
            )),
        }
    }

    /// A number or a list of numbers.
    pub fn f64s(&self, name: &str) -> Result<Option<Vec<f64>>, ParamError> {
        let bad = |v: &Value| {
            ParamError::value(
                name,
                format!(
                    "'{name}': expected a list of numbers, found {}",
                    describe(v)
                ),
            )
            .with_help(format!("write {name}=(a b c)"))
        };
        match self.raw(name)? {
            None => Ok(None),
            Some(Value::Number(x)) if x.is_finite() => Ok(Some(vec![*x])),
            Some(Value::List(l)) => l
                .iter()
                .map(|x| match x {
                    Value::Number(n) if n.is_finite() => Ok(*n),
                    o => Err(bad(o)),
                })
                .collect::<Result<Vec<_>, _>>()
                .map(Some),
            Some(v) => Err(bad(v)),
        }
    }

    /// Three numbers `(x y z)`.
    pub fn vec3(&self, name: &str) -> Result<Option<[f64; 3]>, ParamError> {
        match self.f64s(name)? {
            None => Ok(None),
            Some(v) if v.len() == 3 => Ok(Some([v[0], v[1], v[2]])),
            Some(v) => Err(ParamError::value(
                name,
                format!("'{name}': expected 3 numbers (x y z), found {}", v.len()),
            )),
        }
    }

    /// Every written property the schema does not list is an error naming the
    /// accepted ones (call first, so a misspelt required property is reported
    /// as misspelt, not as missing).
    pub fn check_names(&self) -> Result<(), ParamError> {
        self.unread(|k| self.schema.get(k).is_some())
    }

    /// Every written property no look-up read is an error naming the accepted ones.
    pub fn finish(&self) -> Result<(), ParamError> {
        let used = self.used.borrow().clone();
        self.unread(|k| used.contains(k))
    }

    fn unread(&self, ok: impl Fn(&str) -> bool) -> Result<(), ParamError> {
        {
            for k in self.params.0.keys() {
                if ok(k) {
                    continue;
                }
                let names = self.schema.names();
                let mut e = ParamError::unknown(k, &names);
                e.message = format!(
                    "unknown property '{k}' on {}; expected one of: {}",
                    self.schema.node,
                    names.join(", ")
                );
                return Err(e);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::ParamSpec;

    static S: Schema = Schema {
        node: "measure \"t\"",
        params: &[
            ParamSpec {
                name: "channel",
                kind: Kind::Choice(&["lum", "g"]),
                default: "lum",
                doc: "",
                example: "\"g\"",
            },
            ParamSpec {
                name: "size-px",
                kind: Kind::Integer,
                default: "",
                doc: "",
                example: "7",
            },
        ],
    };

    fn p(kv: &[(&str, Value)]) -> Params {
        let mut p = Params::new();
        for (k, v) in kv {
            p.set(*k, v.clone());
        }
        p
    }

    #[test]
    fn unread_properties_are_unknown_with_a_suggestion() {
        let params = p(&[("chanel", Value::String("g".into()))]);
        let d = ParamDict::new(&params, &S);
        assert_eq!(d.choice("channel").unwrap(), None);
        let e = d.finish().unwrap_err();
        assert_eq!(e.name.as_deref(), Some("chanel"));
        assert!(
            e.message.contains("expected one of: channel, size-px"),
            "{e}"
        );
        assert_eq!(e.help.as_deref(), Some("did you mean 'channel'?"));
    }

    #[test]
    fn typed_lookups_check_values() {
        let params = p(&[
            ("channel", Value::String("x".into())),
            ("size-px", Value::Number(2.5)),
        ]);
        let d = ParamDict::new(&params, &S);
        let e = d.choice("channel").unwrap_err();
        assert!(e.on_value && e.message.contains("\"lum\", \"g\""), "{e}");
        assert!(d.int("size-px", 1, 10).is_err());
        assert!(
            d.raw("other").is_err(),
            "a name outside the schema is refused"
        );
        let params = p(&[("size-px", Value::Number(7.0))]);
        let d = ParamDict::new(&params, &S);
        assert_eq!(d.int("size-px", 1, 10).unwrap(), Some(7));
        assert!(d.finish().is_ok());
    }
}
