//! The one list of a stage's properties: names, types, defaults and what they
//! do. The language reference's property tables (`camsim params --markdown`)
//! and the parameter-reach test are both generated from these lists, and a
//! [`super::ParamDict`] refuses to read a name its schema does not list, so a
//! property cannot exist in the code without being documented and tested.

/// The type of a property's value as written in KDL.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// A finite number (its unit is the name's suffix).
    Number,
    /// A whole number.
    Integer,
    /// A string.
    Text,
    /// One of the listed strings.
    Choice(&'static [&'static str]),
    /// `#true` / `#false`.
    Bool,
    /// A list of numbers `(a b …)`.
    Numbers,
    /// Three numbers `(x y z)`.
    Vec3,
    /// A spectrum: a shipped name or `file.csv#column`.
    Spectrum,
    /// A file path, relative to the file that names it (or its parents).
    File,
    /// A number or one of the listed strings (e.g. `exposure-s="auto"`).
    NumberOr(&'static [&'static str]),
}

impl Kind {
    /// How the type reads in the reference.
    pub fn describe(&self) -> String {
        match self {
            Kind::Number => "number".into(),
            Kind::Integer => "integer".into(),
            Kind::Text => "string".into(),
            Kind::Choice(c) => c
                .iter()
                .map(|s| format!("\"{s}\""))
                .collect::<Vec<_>>()
                .join(" \\| "),
            Kind::Bool => "#true/#false".into(),
            Kind::Numbers => "(numbers)".into(),
            Kind::Vec3 => "(x y z)".into(),
            Kind::Spectrum => "spectrum".into(),
            Kind::File => "file".into(),
            Kind::NumberOr(c) => format!(
                "number \\| {}",
                c.iter()
                    .map(|s| format!("\"{s}\""))
                    .collect::<Vec<_>>()
                    .join(" \\| ")
            ),
        }
    }
}

/// One property of a stage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamSpec {
    pub name: &'static str,
    pub kind: Kind,
    /// The value used when the property is absent, as text ("" = required or none).
    pub default: &'static str,
    /// What it does, in one line.
    pub doc: &'static str,
    /// A distinctive valid value as written in KDL (the reach test sets it and
    /// checks that the built stage holds it).
    pub example: &'static str,
}

impl ParamSpec {
    /// A property (for `static` schemas).
    pub const fn new(
        name: &'static str,
        kind: Kind,
        default: &'static str,
        doc: &'static str,
        example: &'static str,
    ) -> Self {
        Self {
            name,
            kind,
            default,
            doc,
            example,
        }
    }
}

/// All properties of one node kind (e.g. `measure "sfr"`, `sensor`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Schema {
    /// The node as a user writes it, e.g. `measure "sfr"`.
    pub node: &'static str,
    pub params: &'static [ParamSpec],
}

impl Schema {
    pub fn names(&self) -> Vec<&'static str> {
        self.params.iter().map(|p| p.name).collect()
    }
    pub fn get(&self, name: &str) -> Option<&'static ParamSpec> {
        self.params.iter().find(|p| p.name == name)
    }
    /// The reference table (Markdown) of this node's properties.
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "#### `{}`\n\n| property | type | default | meaning |\n|---|---|---|---|\n",
            self.node
        );
        for p in self.params {
            s.push_str(&format!(
                "| `{}` | {} | {} | {} |\n",
                p.name,
                p.kind.describe(),
                if p.default.is_empty() {
                    "—".to_string()
                } else {
                    format!("`{}`", p.default)
                },
                p.doc
            ));
        }
        s
    }
}
