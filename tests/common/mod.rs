//! Helpers shared by integration tests (`mod common;` in a test file).
#![allow(dead_code)]

/// Numeric rows of a reference CSV table. Blank lines and `#` comment lines
/// are skipped, and so is one header line (the first that is not numbers);
/// any other non-numeric line is a broken reference file and panics.
pub fn numeric_rows(path: &str) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let mut header_seen = false;
    let mut rows = Vec::new();
    for (i, l) in text.lines().enumerate() {
        let l = l.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let parsed: Option<Vec<f64>> = l.split(',').map(|x| x.trim().parse().ok()).collect();
        match parsed {
            Some(v) => rows.push(v),
            None if !header_seen && rows.is_empty() => header_seen = true,
            None => panic!("{path}:{}: not a numeric row: {l}", i + 1),
        }
    }
    rows
}
