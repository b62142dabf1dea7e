//! The spectral CSV format of `data/`: `#` comment lines (provenance, units),
//! one header row whose first column is `wavelength_nm`, then numeric rows.

use super::Spectrum;
use std::path::Path;

/// A parsed spectral table: wavelengths plus named columns.
#[derive(Clone, Debug)]
pub struct SpectralTable {
    pub source: String,
    pub comments: Vec<String>,
    pub wavelengths_nm: Vec<f64>,
    pub columns: Vec<(String, Vec<f64>)>,
}

impl SpectralTable {
    /// Parse CSV text; `source` names the file in error messages (`file:line:col: …`).
    pub fn parse(text: &str, source: &str) -> Result<Self, String> {
        let mut comments = Vec::new();
        let mut header: Option<Vec<String>> = None;
        let mut wl = Vec::new();
        let mut cols: Vec<Vec<f64>> = Vec::new();
        for (ln, raw) in text.lines().enumerate() {
            let line_no = ln + 1;
            let line = raw.trim();
            if line.is_empty() {
                continue;
            }
            if let Some(c) = line.strip_prefix('#') {
                comments.push(c.trim().to_string());
                continue;
            }
            let fields: Vec<&str> = line.split(',').map(|f| f.trim()).collect();
            match &header {
                None => {
                    if fields[0] != "wavelength_nm" {
                        return Err(format!(
                            "{source}:{line_no}:1: expected a header row starting with 'wavelength_nm', found '{}'",
                            fields[0]
                        ));
                    }
                    cols = vec![Vec::new(); fields.len() - 1];
                    header = Some(fields.iter().map(|s| s.to_string()).collect());
                }
                Some(h) => {
                    if fields.len() != h.len() {
                        return Err(format!(
                            "{source}:{line_no}:1: expected {} fields, found {}",
                            h.len(),
                            fields.len()
                        ));
                    }
                    let mut col = 1;
                    for (i, f) in fields.iter().enumerate() {
                        let v: f64 = f.parse().map_err(|_| {
                            format!("{source}:{line_no}:{col}: expected a number in column '{}', found '{f}'", h[i])
                        })?;
                        if !v.is_finite() {
                            return Err(format!(
                                "{source}:{line_no}:{col}: value '{f}' is not finite"
                            ));
                        }
                        if i == 0 {
                            if let Some(&prev) = wl.last()
                                && v <= prev
                            {
                                return Err(format!(
                                    "{source}:{line_no}:{col}: wavelengths must increase ({prev} then {v})"
                                ));
                            }
                            wl.push(v);
                        } else {
                            cols[i - 1].push(v);
                        }
                        col += f.len() + 1;
                    }
                }
            }
        }
        let header = header
            .ok_or_else(|| format!("{source}: no header row (expected 'wavelength_nm,…')"))?;
        if wl.is_empty() {
            return Err(format!("{source}: no data rows"));
        }
        Ok(Self {
            source: source.to_string(),
            comments,
            wavelengths_nm: wl,
            columns: header[1..].iter().cloned().zip(cols).collect(),
        })
    }

    pub fn load(path: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
        Self::parse(&text, &path.display().to_string())
    }

    pub fn column_names(&self) -> Vec<&str> {
        self.columns.iter().map(|(n, _)| n.as_str()).collect()
    }

    /// The units declared in a `# units:` comment, if any.
    pub fn units(&self) -> Option<&str> {
        self.comments
            .iter()
            .find_map(|c| c.strip_prefix("units:").map(|u| u.trim()))
    }

    /// One column as a spectrum; unknown names get a did-you-mean suggestion.
    pub fn spectrum(&self, column: &str) -> Result<Spectrum, String> {
        match self.columns.iter().find(|(n, _)| n == column) {
            Some((n, v)) => Spectrum::new(n.clone(), self.wavelengths_nm.clone(), v.clone()),
            None => {
                let names = self.column_names();
                let hint = crate::diag::did_you_mean(column, names.iter().copied())
                    .map(|s| format!(" (did you mean '{s}'?)"))
                    .unwrap_or_default();
                Err(format!(
                    "{}: no column '{column}'{hint}; columns are: {}",
                    self.source,
                    names.join(", ")
                ))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn parses_comments_header_and_columns() {
        let t = SpectralTable::parse("# units: W\nwavelength_nm,a,b\n400,1,2\n410,3,4\n", "x.csv")
            .unwrap();
        assert_eq!(t.units(), Some("W"));
        assert_eq!(t.spectrum("b").unwrap().values, vec![2.0, 4.0]);
        let e = t.spectrum("bb").unwrap_err();
        assert!(e.contains("did you mean 'b'"), "{e}");
    }
    #[test]
    fn errors_name_line_and_column() {
        let e = SpectralTable::parse("wavelength_nm,a\n400,x\n", "f.csv").unwrap_err();
        assert!(e.starts_with("f.csv:2:5:"), "{e}");
        assert!(
            SpectralTable::parse("nm,a\n", "f.csv")
                .unwrap_err()
                .contains("f.csv:1:1")
        );
        assert!(SpectralTable::parse("wavelength_nm,a\n410,1\n400,1\n", "f.csv").is_err());
    }
}
