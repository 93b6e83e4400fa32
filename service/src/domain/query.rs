//! A query after the run (docs/contract.md "HTTP API", distributions): which quantile levels and
//! which thresholds to answer from a metric's stored groups, read from the query string's
//! `quantiles=0.5,0.999` and `exceedance=above:0.005,below:0.002`.

use bouncewear_model::error::underflow;
use bouncewear_model::stats::Threshold;
use std::fmt;

/// At most this many levels, and this many thresholds, in one query.
pub const MAX_ITEMS: usize = 20;

/// Bins of a distribution from which reading it (its rows' summaries parsed, its representation
/// written and tagged) runs on the blocking pool rather than on a thread that answers requests:
/// about 34 us a bin (a 1000-bin metric took 34 ms a request), so from 64 bins the work outlasts
/// the hop there and back.
pub const LARGE_DISTRIBUTION_BINS: usize = 64;

/// The levels and thresholds of one query, each valid: levels in `(0, 1)`, thresholds finite.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AfterRunQuery {
    pub levels: Vec<f64>,
    pub thresholds: Vec<Threshold>,
}

/// A query parameter at fault, and the rule it broke.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BadQuery {
    pub parameter: &'static str,
    pub rule: String,
}

impl fmt::Display for BadQuery {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "query parameter `{}`: {}", self.parameter, self.rule)
    }
}

impl std::error::Error for BadQuery {}

impl AfterRunQuery {
    /// The query the two parameters ask for; `None` when neither is given.
    pub fn parse(
        quantiles: Option<&str>,
        exceedance: Option<&str>,
    ) -> Result<Option<Self>, BadQuery> {
        if quantiles.is_none() && exceedance.is_none() {
            return Ok(None);
        }
        let levels = items("quantiles", quantiles, level)?;
        let thresholds = items("exceedance", exceedance, threshold)?;
        Ok(Some(Self { levels, thresholds }))
    }
}

/// The comma-separated items of `parameter`, each read by `read` (an absent parameter has none),
/// at most [`MAX_ITEMS`] of them, each once in the order first given (`b_lives=0.1,0.1` was
/// answered twice); the error names the parameter, the item and its rule.
pub fn items<T: PartialEq>(
    parameter: &'static str,
    text: Option<&str>,
    read: fn(&str) -> Result<T, String>,
) -> Result<Vec<T>, BadQuery> {
    let Some(text) = text else {
        return Ok(Vec::new());
    };
    let bad = |rule: String| BadQuery { parameter, rule };
    let items: Vec<&str> = text.split(',').collect();
    if items.len() > MAX_ITEMS {
        return Err(bad(format!(
            "at most {MAX_ITEMS} comma-separated items, got {}",
            items.len()
        )));
    }
    let mut read_once = Vec::with_capacity(items.len());
    for item in items {
        let value = read(item).map_err(|rule| bad(format!("`{}`: {rule}", shown(item))))?;
        if !read_once.contains(&value) {
            read_once.push(value);
        }
    }
    Ok(read_once)
}

/// A level: a number strictly between 0 and 1.
fn level(item: &str) -> Result<f64, String> {
    let rule = || "a quantile level must be a number strictly between 0 and 1".to_owned();
    number(item, rule).and_then(|q| (q > 0.0 && q < 1.0).then_some(q).ok_or_else(rule))
}

/// A fraction: a number strictly between 0 and 1, spaces around it allowed.
pub fn fraction(item: &str) -> Result<f64, String> {
    let rule = || "a fraction must be a number strictly between 0 and 1".to_owned();
    number(item.trim(), rule).and_then(|p| (p > 0.0 && p < 1.0).then_some(p).ok_or_else(rule))
}

/// A threshold: `above:X` or `below:X` with X a finite number.
fn threshold(item: &str) -> Result<Threshold, String> {
    let rule = || "must be `above:X` or `below:X` with X a finite number".to_owned();
    let (side, value) = item.split_once(':').ok_or_else(rule)?;
    let value = number(value, rule)?;
    match side {
        "above" => Ok(Threshold::Above(value)),
        "below" => Ok(Threshold::Below(value)),
        _ => Err(rule()),
    }
}

/// A finite decimal number (not `inf`, `NaN` or beyond f64; `rule` otherwise), and not one
/// nearer 0 than any (`1e-400`, which reads as 0 and was taken as a threshold of 0; refused as a
/// job's body refuses it).
fn number(text: &str, rule: impl FnOnce() -> String) -> Result<f64, String> {
    let plain = text
        .bytes()
        .all(|b| b.is_ascii_digit() || b"+-.eE".contains(&b));
    let mantissa = text.split(['e', 'E']).next().unwrap_or_default();
    let written_zero = !mantissa.bytes().any(|b| (b'1'..=b'9').contains(&b));
    match text.parse::<f64>() {
        Ok(x) if plain && x == 0.0 && !written_zero => Err(underflow(text)),
        Ok(x) if plain && x.is_finite() => Ok(x),
        _ => Err(rule()),
    }
}

/// An item as repeated in an error: at most 40 characters of it.
fn shown(item: &str) -> String {
    item.chars().take(40).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(quantiles: Option<&str>, exceedance: Option<&str>) -> Result<AfterRunQuery, String> {
        AfterRunQuery::parse(quantiles, exceedance)
            .map(Option::unwrap_or_default)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn levels_and_thresholds_are_read_in_order() {
        let query = parse(Some("0.5,0.999"), Some("above:0.005,below:2e-3")).unwrap();
        assert_eq!(query.levels, [0.5, 0.999]);
        assert_eq!(
            query.thresholds,
            [Threshold::Above(0.005), Threshold::Below(0.002)]
        );
        assert_eq!(AfterRunQuery::parse(None, None), Ok(None));
        assert!(parse(None, Some("above:-1")).unwrap().levels.is_empty());
        // Zero written as zero, in any form, is a threshold.
        assert_eq!(
            parse(None, Some("above:0,below:-0.0e5"))
                .unwrap()
                .thresholds
                .len(),
            2
        );
    }

    #[test]
    fn bad_items_name_the_parameter_and_the_rule() {
        for (quantiles, exceedance, parameter) in [
            (Some("0"), None, "quantiles"),
            (Some("1"), None, "quantiles"),
            (Some("0.5,"), None, "quantiles"),
            (Some(""), None, "quantiles"),
            (Some("NaN"), None, "quantiles"),
            (Some("inf"), None, "quantiles"),
            (None, Some("above:1e400"), "exceedance"),
            (None, Some("above:1e-400"), "exceedance"),
            (Some("1e-400"), None, "quantiles"),
            (None, Some("above:inf"), "exceedance"),
            (None, Some("over:1"), "exceedance"),
            (None, Some("above"), "exceedance"),
            (None, Some("above:"), "exceedance"),
        ] {
            let error = AfterRunQuery::parse(quantiles, exceedance).unwrap_err();
            assert_eq!(error.parameter, parameter, "{quantiles:?} {exceedance:?}");
        }
        let many = vec!["0.5"; MAX_ITEMS + 1].join(",");
        assert_eq!(
            parse(Some(&many), None).unwrap_err(),
            "query parameter `quantiles`: at most 20 comma-separated items, got 21"
        );
        assert_eq!(
            parse(Some("0.5,2"), None).unwrap_err(),
            "query parameter `quantiles`: `2`: a quantile level must be a number strictly between 0 and 1"
        );
        // A number nearer 0 than any is told so, as in a body ("finite number" said of 1e-400).
        assert_eq!(
            parse(None, Some("above:1e-400")).unwrap_err(),
            "query parameter `exceedance`: `above:1e-400`: `1e-400` is not 0, but nearer 0 than \
             any number (the least is 4.9e-324) and would read as 0: write 0, or a number within \
             range"
        );
    }
}
