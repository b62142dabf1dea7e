//! Generic parameter maps: the typed values an experiment passes to stages
//! (sensor and lens overrides, measurement options). Names carry their unit
//! (`exposure-s`, `film-distance-mm`); getters check presence and type.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A parameter value as written in a KDL file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Value {
    Bool(bool),
    Number(f64),
    String(String),
    List(Vec<Value>),
}

impl std::fmt::Display for Value {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Value::Bool(b) => write!(f, "{b}"),
            Value::Number(x) => write!(f, "{x}"),
            Value::String(s) => write!(f, "{s}"),
            Value::List(v) => {
                write!(f, "(")?;
                for (i, x) in v.iter().enumerate() {
                    if i > 0 {
                        write!(f, " ")?;
                    }
                    write!(f, "{x}")?;
                }
                write!(f, ")")
            }
        }
    }
}

/// Ordered name → value map.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Params(pub BTreeMap<String, Value>);

impl Params {
    pub fn new() -> Self {
        Self::default()
    }
    pub fn set(&mut self, name: impl Into<String>, v: Value) {
        self.0.insert(name.into(), v);
    }
    pub fn get(&self, name: &str) -> Option<&Value> {
        self.0.get(name)
    }
    pub fn f64(&self, name: &str) -> Result<Option<f64>, String> {
        match self.0.get(name) {
            None => Ok(None),
            Some(Value::Number(x)) => Ok(Some(*x)),
            Some(v) => Err(format!("'{name}': expected a number, found {v}")),
        }
    }
    pub fn str(&self, name: &str) -> Result<Option<&str>, String> {
        match self.0.get(name) {
            None => Ok(None),
            Some(Value::String(s)) => Ok(Some(s)),
            Some(v) => Err(format!("'{name}': expected a string, found {v}")),
        }
    }
    pub fn bool(&self, name: &str) -> Result<Option<bool>, String> {
        match self.0.get(name) {
            None => Ok(None),
            Some(Value::Bool(b)) => Ok(Some(*b)),
            Some(v) => Err(format!("'{name}': expected #true or #false, found {v}")),
        }
    }
    /// A list of numbers (e.g. `position-m=(0 0.1 0.2)` arrives as a list).
    pub fn f64s(&self, name: &str) -> Result<Option<Vec<f64>>, String> {
        match self.0.get(name) {
            None => Ok(None),
            Some(Value::Number(x)) => Ok(Some(vec![*x])),
            Some(Value::List(v)) => v
                .iter()
                .map(|x| match x {
                    Value::Number(n) => Ok(*n),
                    o => Err(format!("'{name}': expected numbers, found {o}")),
                })
                .collect::<Result<Vec<_>, _>>()
                .map(Some),
            Some(v) => Err(format!("'{name}': expected a list of numbers, found {v}")),
        }
    }
    /// Names not in `known` (for strict validation with suggestions).
    pub fn unknown<'a>(&'a self, known: &[&str]) -> Vec<&'a str> {
        self.0
            .keys()
            .filter(|k| !known.contains(&k.as_str()))
            .map(|k| k.as_str())
            .collect()
    }
}
