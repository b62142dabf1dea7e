//! The one error type of parameter handling.

/// What a stage reports about its parameters: the offending property (None =
/// the whole section), what is wrong and what is expected, and an optional
/// suggestion. The experiment layer locates it at the property's
/// `file:line:col` (its name, or its value when `on_value`).
#[derive(Clone, Debug, PartialEq)]
pub struct ParamError {
    pub name: Option<String>,
    pub message: String,
    pub help: Option<String>,
    /// Point at the property's value rather than its name.
    pub on_value: bool,
}

impl ParamError {
    pub fn new(name: Option<&str>, message: impl Into<String>) -> Self {
        Self {
            name: name.map(str::to_string),
            message: message.into(),
            help: None,
            on_value: false,
        }
    }
    /// An error about the value of property `name`.
    pub fn value(name: &str, message: impl Into<String>) -> Self {
        Self::new(Some(name), message).at_value()
    }
    /// An error about the whole section.
    pub fn section(message: impl Into<String>) -> Self {
        Self::new(None, message)
    }
    pub fn with_help(mut self, h: impl Into<String>) -> Self {
        self.help = Some(h.into());
        self
    }
    /// Report at the property's value (e.g. an unknown spectrum name).
    pub fn at_value(mut self) -> Self {
        self.on_value = true;
        self
    }
    /// Unknown name `name` among `known`, with a did-you-mean suggestion.
    pub fn unknown(name: &str, known: &[&str]) -> Self {
        let mut e = Self::new(
            Some(name),
            format!(
                "unknown property '{name}'; expected one of: {}",
                known.join(", ")
            ),
        );
        e.help = crate::diag::did_you_mean(name, known.iter().copied())
            .map(|s| format!("did you mean '{s}'?"));
        e
    }
}

impl std::fmt::Display for ParamError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.message)?;
        if let Some(h) = &self.help {
            write!(f, " ({h})")?;
        }
        Ok(())
    }
}

impl From<ParamError> for crate::Error {
    fn from(e: ParamError) -> Self {
        crate::Error::invalid(e.to_string())
    }
}
