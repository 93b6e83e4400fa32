//! Measurements as a spreadsheet writes them: `calibrate --observations FILE.csv` reads one
//! observation per row, the header naming each column after an observation's field
//! (`impact_velocity_m_s,first_bounce_s,total_bounce_s`, in any order, any subset); an empty cell
//! is a quantity not measured in that row. The rows become the request's `observations`, so every
//! rule and every error is the calibration's own, named by its pointer
//! (`/observations/ROW/FIELD`, rows counted from 0 below the header).

use super::CliError;
use bouncewear_model::{InvalidInput, Pointer};
use serde_json::{Map, Value};

/// The observations of CSV `text` as JSON: an array of objects, one per data row.
pub fn observations_from_csv(text: &str, path: &str) -> Result<Value, CliError> {
    let mut lines = text
        .lines()
        .map(|line| line.trim_end_matches('\r'))
        .filter(|line| !line.trim().is_empty());
    let header: Vec<&str> = lines
        .next()
        .ok_or_else(|| invalid(path, "the file has no header row".to_owned()))?
        .split(',')
        .map(str::trim)
        .collect();
    let mut rows = Vec::new();
    for (row, line) in lines.enumerate() {
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        if cells.len() != header.len() {
            return Err(invalid(
                path,
                format!(
                    "data row {row} has {} cells, the header {} columns",
                    cells.len(),
                    header.len()
                ),
            ));
        }
        let mut observation = Map::new();
        for (column, cell) in header.iter().zip(cells) {
            if cell.is_empty() {
                continue;
            }
            let number = cell
                .parse::<u64>()
                .map(Value::from)
                .or_else(|_| cell.parse::<f64>().map(Value::from))
                .map_err(|_| {
                    invalid(
                        path,
                        format!("data row {row}, column `{column}`: `{cell}` is not a number"),
                    )
                })?;
            observation.insert((*column).to_owned(), number);
        }
        rows.push(Value::Object(observation));
    }
    Ok(Value::Array(rows))
}

fn invalid(path: &str, detail: String) -> CliError {
    CliError::Invalid(InvalidInput::single(
        &Pointer::root().child("observations"),
        format!("{path}: {detail}"),
    ))
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
        assert_eq!(
            observations_from_csv(csv, "m.csv").unwrap(),
            json!([
                {"operation": 0, "impact_velocity_m_s": 0.2, "first_bounce_s": 0.0086, "total_bounce_s": 0.0108},
                {"operation": 500, "impact_velocity_m_s": 0.3, "total_bounce_s": 0.0121}
            ])
        );
    }

    #[test]
    fn a_cell_that_is_no_number_or_a_short_row_is_named() {
        let bad = observations_from_csv("e1,first_bounce_s\n0.4,abc\n", "m.csv").unwrap_err();
        assert!(
            bad.to_string()
                .contains("m.csv: data row 0, column `first_bounce_s`: `abc` is not a number"),
            "{bad}"
        );
        let short = observations_from_csv("e1,first_bounce_s\n0.4\n", "m.csv").unwrap_err();
        assert!(
            short
                .to_string()
                .contains("data row 0 has 1 cells, the header 2 columns")
        );
        assert!(observations_from_csv("", "m.csv").is_err());
    }
}
