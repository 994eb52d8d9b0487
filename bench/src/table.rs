//! The Markdown tables of the benchmark reports: a header with its alignment rule,
//! then one row per line.

use std::fmt::Write;

/// How a column's cells align.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Align {
    /// Text.
    Left,
    /// Numbers.
    Right,
}

/// Appends the header row of `columns` (title, alignment) and its rule.
pub fn header(out: &mut String, columns: &[(&str, Align)]) {
    let titles: Vec<&str> = columns.iter().map(|(t, _)| *t).collect();
    row(out, &titles);
    let rule: String = columns.iter().map(|(_, a)| if *a == Align::Right { "---:|" } else { "---|" }).collect();
    let _ = writeln!(out, "|{rule}");
}

/// Appends one row of `cells`.
pub fn row(out: &mut String, cells: &[impl AsRef<str>]) {
    out.push('|');
    for cell in cells {
        let _ = write!(out, " {} |", cell.as_ref());
    }
    out.push('\n');
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_header_its_rule_and_a_row() {
        let mut out = String::new();
        header(&mut out, &[("name", Align::Left), ("µs", Align::Right)]);
        row(&mut out, &["dyfos".to_string(), format!("{:.1}", 12.34)]);
        assert_eq!(out, "| name | µs |\n|---|---:|\n| dyfos | 12.3 |\n");
    }
}
