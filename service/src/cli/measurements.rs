//! Measurements as a spreadsheet writes them: `calibrate --observations FILE.csv` reads one
//! observation per row, the header naming each column after an observation's field
//! (`impact_velocity_m_s,first_bounce_s,total_bounce_s`, in any order, any subset); an empty cell
//! is a quantity not measured in that row. The rows become the request's `observations`, so every
//! rule and every error is the calibration's own, named by its pointer
//! (`/observations/ROW/FIELD`, rows counted from 0 below the header).

use super::CliError;
use bouncewear_model::{FieldError, InvalidInput, Pointer};
use serde_json::{Map, Value};

/// The observations of CSV `text` as JSON: an array of objects, one per data row. Every cell
/// that is not a number and every row of the wrong length is named at its pointer
/// (`/observations/ROW/FIELD`, `/observations/ROW`), all of them at once.
/// A cell as written, without the spaces around it and the double quotes a spreadsheet may put
/// around any cell (`"0.2"`).
fn cell(text: &str) -> &str {
    let text = text.trim();
    text.strip_prefix('"')
        .and_then(|inner| inner.strip_suffix('"'))
        .map_or(text, str::trim)
}

/// Where each data row of a measurements file was: its line in the file (blank lines are skipped).
#[derive(Debug)]
pub struct RowLines {
    path: String,
    lines: Vec<usize>,
}

impl RowLines {
    /// `error` with each fault of an observation told at its line in the file too: the
    /// calibration's own rules name `/observations/ROW`, counted past blank lines.
    pub fn locate(&self, error: InvalidInput) -> InvalidInput {
        if error.is_syntax() {
            return error;
        }
        let errors = error.errors().iter().map(|fault| {
            let row = (fault.pointer.strip_prefix("/observations/"))
                .and_then(|rest| rest.split('/').next()?.parse::<usize>().ok());
            match row.and_then(|row| Some((row, self.lines.get(row)?))) {
                Some((row, line)) if !fault.detail.starts_with(&self.path) => FieldError {
                    pointer: fault.pointer.clone(),
                    detail: format!(
                        "{}: line {line} (data row {row}): {}",
                        self.path, fault.detail
                    ),
                },
                _ => fault.clone(),
            }
        });
        InvalidInput::new(errors.collect())
    }
}

pub fn observations_from_csv(text: &str, path: &str) -> Result<(Value, RowLines), CliError> {
    // Each line with its number in the file, as a spreadsheet numbers its rows.
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(index, line)| (index + 1, line.trim_end_matches('\r')))
        .filter(|(_, line)| !line.trim().is_empty());
    let observations = Pointer::root().child("observations");
    let header: Vec<&str> = lines
        .next()
        .ok_or_else(|| {
            let detail = format!("{path}: the file has no header row");
            CliError::Invalid(InvalidInput::single(&observations, detail))
        })?
        .1
        .split(',')
        .map(cell)
        .collect();
    let (mut rows, mut errors, mut row_lines) = (Vec::new(), Vec::new(), Vec::new());
    let mut fault = |pointer: Pointer, detail: String| {
        errors.push(FieldError {
            pointer: pointer.to_string(),
            detail: format!("{path}: {detail}"),
        });
    };
    for (index, column) in header.iter().enumerate() {
        // Said once, at its second place, however often it is named.
        if header[..index].iter().filter(|c| *c == column).count() == 1 {
            let detail = format!("the header names column `{column}` twice");
            fault(observations.clone(), detail);
        }
    }
    for (row, (line_number, line)) in lines.enumerate() {
        row_lines.push(line_number);
        let at = observations.child(row);
        let cells: Vec<&str> = line.split(',').map(cell).collect();
        if cells.len() != header.len() {
            let detail = format!(
                "line {line_number} (data row {row}) has {} cells, the header {} columns",
                cells.len(),
                header.len()
            );
            fault(at, detail);
            continue;
        }
        let mut observation = Map::new();
        for (column, cell) in header.iter().zip(cells).filter(|(_, c)| !c.is_empty()) {
            // Rust reads `NaN`, `inf` and `1e400` (as infinity) as numbers; JSON has none of
            // them, and a measurement is finite.
            let number = cell.parse::<u64>().map(Value::from).ok().or_else(|| {
                let number = cell.parse::<f64>().ok().filter(|x| x.is_finite())?;
                Some(Value::from(number))
            });
            match number {
                Some(number) => {
                    observation.insert((*column).to_owned(), number);
                }
                None => fault(
                    at.child(column),
                    format!(
                        "line {line_number} (data row {row}), column `{column}`: `{cell}` is not a \
                         finite number"
                    ),
                ),
            }
        }
        rows.push(Value::Object(observation));
    }
    if !errors.is_empty() {
        return Err(CliError::Invalid(InvalidInput::new(errors)));
    }
    let lines = RowLines {
        path: path.to_owned(),
        lines: row_lines,
    };
    Ok((Value::Array(rows), lines))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn rows_become_observations_with_empty_cells_left_out() {
        let csv = "operation,impact_velocity_m_s,first_bounce_s,total_bounce_s\r\n\
                   0,0.2,0.0086,0.0108\n\n\
                   500, 0.3 ,,0.0121\n";
        let (rows, lines) = observations_from_csv(csv, "m.csv").unwrap();
        assert_eq!(
            rows,
            json!([
                {"operation": 0, "impact_velocity_m_s": 0.2, "first_bounce_s": 0.0086, "total_bounce_s": 0.0108},
                {"operation": 500, "impact_velocity_m_s": 0.3, "total_bounce_s": 0.0121}
            ])
        );
        // A rule of the calibration's own is told at the row's line too, past the blank line
        // (it named `/observations/1` alone: a probe).
        let row = Pointer::root().child("observations").child(1);
        let fault = InvalidInput::single(&row.child("e1"), "measures nothing");
        assert_eq!(
            lines.locate(fault).errors()[0].detail,
            "m.csv: line 4 (data row 1): measures nothing"
        );
        let elsewhere = InvalidInput::single(&Pointer::root().child("fit"), "unknown");
        assert_eq!(lines.locate(elsewhere).errors()[0].detail, "unknown");
    }

    #[test]
    fn every_cell_that_is_no_number_and_every_short_row_is_named_at_its_pointer() {
        let bad = observations_from_csv("e1,first_bounce_s\n0.4,abc\n0.5\n,x\n", "m.csv");
        let CliError::Invalid(bad) = bad.unwrap_err() else {
            panic!("invalid input")
        };
        assert_eq!(
            bad.pointers(),
            [
                "/observations/0/first_bounce_s",
                "/observations/1",
                "/observations/2/first_bounce_s"
            ]
        );
        assert!(
            bad.to_string().contains(
                "m.csv: line 2 (data row 0), column `first_bounce_s`: `abc` is not a finite number"
            ),
            "{bad}"
        );
        assert!(
            bad.to_string()
                .contains("line 3 (data row 1) has 1 cells, the header 2 columns")
        );
        // Quoted cells and header names, as spreadsheets write them, read as the plain ones.
        let quoted =
            observations_from_csv("\"e1\",\"first_bounce_s\"\n\"0.4\",\" 0.0086\"\n", "q.csv");
        assert_eq!(
            quoted.unwrap().0,
            serde_json::json!([{"e1": 0.4, "first_bounce_s": 0.0086}])
        );
        assert!(observations_from_csv("", "m.csv").is_err());
    }

    /// Rust's `f64` parser takes `NaN`, `inf` and an overflow such as `1e400` (infinity), which
    /// became JSON's `null`, "not measured": three of four bounce times left out without a word.
    /// A column named twice let the last one win.
    #[test]
    fn a_cell_that_is_not_finite_and_a_column_named_twice_are_refused() {
        let bad = observations_from_csv(
            "impact_velocity_m_s,first_bounce_s\nNaN,0.01\n0.4,inf\n0.3,-inf\n0.2,1e400\n0.5,0.012\n",
            "m.csv",
        );
        let CliError::Invalid(bad) = bad.unwrap_err() else {
            panic!("invalid input")
        };
        assert_eq!(
            bad.pointers(),
            [
                "/observations/0/impact_velocity_m_s",
                "/observations/1/first_bounce_s",
                "/observations/2/first_bounce_s",
                "/observations/3/first_bounce_s"
            ]
        );
        assert!(
            bad.to_string().contains("`inf` is not a finite number"),
            "{bad}"
        );
        let twice = observations_from_csv("e1,first_bounce_s,e1\n0.4,0.01,0.4\n", "m.csv");
        let CliError::Invalid(twice) = twice.unwrap_err() else {
            panic!("invalid input")
        };
        assert_eq!(twice.pointers(), ["/observations"]);
        assert!(
            twice.to_string().contains("names column `e1` twice"),
            "{twice}"
        );
    }
}
