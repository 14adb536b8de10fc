//! Reading numbers from JSON input, including the non-standard `NaN`, `Infinity` and `-Infinity`
//! tokens that Python's `json` module writes, so that non-finite values reach the checks that
//! name them instead of failing as a parse error.

use serde_json::Value;

use super::{CliError, Result};

/// Parses `text` as JSON; bare `NaN`, `Infinity` and `-Infinity` outside strings are accepted and
/// read as the corresponding `f64` by [`as_number`]. `what` names the input in errors.
pub fn parse(text: &str, what: &str) -> Result<Value> {
    let mut out = String::with_capacity(text.len() + 16);
    let mut in_string = false;
    let mut escaped = false;
    let mut rest = text;
    while let Some(c) = rest.chars().next() {
        if in_string {
            out.push(c);
            if escaped {
                escaped = false;
            } else if c == '\\' {
                escaped = true;
            } else if c == '"' {
                in_string = false;
            }
            rest = &rest[c.len_utf8()..];
            continue;
        }
        if c == '"' {
            in_string = true;
        } else if let Some(token) = ["-Infinity", "Infinity", "NaN"]
            .into_iter()
            .find(|t| rest.starts_with(t))
        {
            out.push('"');
            out.push_str(token);
            out.push('"');
            rest = &rest[token.len()..];
            continue;
        }
        out.push(c);
        rest = &rest[c.len_utf8()..];
    }
    serde_json::from_str(&out).map_err(|e| CliError::input(what, format!("malformed JSON: {e}")))
}

/// The number `v` holds (a JSON number or one of the non-finite tokens), or `None`.
pub fn as_number(v: &Value) -> Option<f64> {
    match v {
        Value::Number(n) => n.as_f64(),
        Value::String(s) => match s.as_str() {
            "NaN" => Some(f64::NAN),
            "Infinity" => Some(f64::INFINITY),
            "-Infinity" => Some(f64::NEG_INFINITY),
            _ => None,
        },
        _ => None,
    }
}

/// A short description of a JSON value's kind, for error messages.
pub fn kind(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

/// `v` as an array of numbers, or an error naming `what` and the offending element.
pub fn numbers(v: &Value, what: &str) -> Result<Vec<f64>> {
    let arr = v.as_array().ok_or_else(|| {
        CliError::input(
            what,
            format!("expected an array of numbers, got {}", kind(v)),
        )
    })?;
    arr.iter()
        .enumerate()
        .map(|(i, x)| {
            as_number(x).ok_or_else(|| {
                CliError::input(what, format!("element {i} is {}, not a number", kind(x)))
            })
        })
        .collect()
}

/// Checks a computed output before it is written as JSON, where a non-finite number would turn
/// into `null`: `Ok` if every value is finite, otherwise an error naming `what` (the input, e.g.
/// `states file s.json: state 3`), the `quantity` and the first offending element.
pub fn check_output(what: &str, quantity: &str, values: &[f64]) -> Result<()> {
    match values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        None => Ok(()),
        Some((i, v)) => Err(CliError::Other(format!(
            "{what}: {quantity} is not finite (element {i} is {v}): the input drives the \
             computation beyond the range of f64"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_tokens_are_read_and_strings_left_alone() {
        let v = parse(r#"[1.5, NaN, -Infinity, Infinity, "NaN\" x"]"#, "t").unwrap();
        let a = v.as_array().unwrap();
        assert_eq!(as_number(&a[0]), Some(1.5));
        assert!(as_number(&a[1]).unwrap().is_nan());
        assert_eq!(as_number(&a[2]), Some(f64::NEG_INFINITY));
        assert_eq!(as_number(&a[3]), Some(f64::INFINITY));
        assert_eq!(a[4].as_str(), Some("NaN\" x"));
        assert!(parse("[1, 2", "t").is_err());
    }

    #[test]
    fn check_output_names_the_quantity_and_element() {
        assert!(check_output("s", "rnea", &[0.0, -1e308, 5.0]).is_ok());
        let e = check_output("state 2", "rnea", &[1.0, f64::NEG_INFINITY]).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.starts_with("state 2: rnea is not finite (element 1 is -inf)"),
            "{msg}"
        );
        assert!(check_output("s", "x", &[f64::NAN]).is_err());
    }
}
