//! Parser for model specification strings: `ggx`, `height(ggx)`, `height(coated, scale=0.05)`,
//! `ggx(shadowing=correlated)`.
//!
//! Grammar (whitespace ignored):
//! ```text
//! spec := NAME [ "(" arg { "," arg } ")" ]
//! arg  := NAME "=" NUMBER        a numeric argument of the model
//!       | NAME "=" NAME          a choice argument (one of the words the model lists)
//!       | spec                   a nested model (adapters take exactly one)
//! NAME := [A-Za-z_][A-Za-z0-9_-]*
//! ```

use std::fmt;

use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// The value of one argument: a number (`scale=0.02`) or a word (`shadowing=correlated`).
/// Untagged in JSON, so a number is written as a JSON number and a word as a string.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ArgValue {
    Number(f64),
    Word(String),
}

impl fmt::Display for ArgValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ArgValue::Number(v) => write!(f, "{v}"),
            ArgValue::Word(w) => f.write_str(w),
        }
    }
}

/// A parsed specification.
#[derive(Debug, Clone, PartialEq)]
pub struct PluginSpec {
    /// Registered model name.
    pub name: String,
    /// Nested model specifications, in order.
    pub nested: Vec<PluginSpec>,
    /// Arguments, in the order written.
    pub values: Vec<(String, ArgValue)>,
}

impl PluginSpec {
    /// Parse a whole specification string.
    pub fn parse(text: &str) -> Result<Self> {
        let mut parser = Parser { text, pos: 0 };
        let spec = parser.spec()?;
        parser.skip_ws();
        if parser.pos != text.len() {
            return Err(parser.error("unexpected text after the specification"));
        }
        Ok(spec)
    }
}

impl fmt::Display for PluginSpec {
    /// Canonical form: nested models first, then `key=value` in the order stored.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.name)?;
        if self.nested.is_empty() && self.values.is_empty() {
            return Ok(());
        }
        let args: Vec<String> = self
            .nested
            .iter()
            .map(|n| n.to_string())
            .chain(self.values.iter().map(|(k, v)| format!("{k}={v}")))
            .collect();
        write!(f, "({})", args.join(", "))
    }
}

/// Splits a comma-separated list of specifications at the commas outside parentheses:
/// `"lambert, height(ggx, scale=0.05)"` → `["lambert", "height(ggx, scale=0.05)"]` (each
/// trimmed; an empty item or unbalanced parentheses are an error naming the list).
pub fn split_list(text: &str) -> Result<Vec<String>> {
    let bad = |reason: &str| Error::BadSpec {
        spec: text.to_string(),
        reason: reason.to_string(),
    };
    let mut items = Vec::new();
    let mut depth = 0usize;
    let mut start = 0;
    for (i, c) in text.char_indices() {
        match c {
            '(' => depth += 1,
            ')' => depth = depth.checked_sub(1).ok_or_else(|| bad("unbalanced ')'"))?,
            ',' if depth == 0 => {
                items.push(text[start..i].trim().to_string());
                start = i + 1;
            }
            _ => {}
        }
    }
    if depth != 0 {
        return Err(bad("unbalanced '('"));
    }
    items.push(text[start..].trim().to_string());
    if items.iter().any(String::is_empty) {
        return Err(bad("empty item in the list"));
    }
    Ok(items)
}

struct Parser<'a> {
    text: &'a str,
    pos: usize,
}

impl Parser<'_> {
    fn error(&self, reason: &str) -> Error {
        Error::BadSpec {
            spec: self.text.to_string(),
            reason: format!("{reason} at character {}", self.pos + 1),
        }
    }

    fn skip_ws(&mut self) {
        while self.text[self.pos..].starts_with(char::is_whitespace) {
            self.pos += 1;
        }
    }

    fn eat(&mut self, c: char) -> bool {
        self.skip_ws();
        if self.text[self.pos..].starts_with(c) {
            self.pos += 1;
            true
        } else {
            false
        }
    }

    fn name(&mut self) -> Result<String> {
        self.skip_ws();
        let rest = &self.text[self.pos..];
        let len = rest
            .char_indices()
            .find(|&(i, c)| {
                !(c.is_ascii_alphabetic()
                    || c == '_'
                    || (i > 0 && (c.is_ascii_digit() || c == '-')))
            })
            .map_or(rest.len(), |(i, _)| i);
        if len == 0 {
            return Err(self.error("expected a model or argument name"));
        }
        self.pos += len;
        Ok(rest[..len].to_string())
    }

    fn number(&mut self) -> Result<f64> {
        self.skip_ws();
        let rest = &self.text[self.pos..];
        let len = rest
            .find(|c: char| !(c.is_ascii_digit() || "+-.eE".contains(c)))
            .unwrap_or(rest.len());
        let value = rest[..len]
            .parse::<f64>()
            .map_err(|_| self.error("expected a number"))?;
        if !value.is_finite() {
            return Err(self.error("argument values must be finite"));
        }
        self.pos += len;
        Ok(value)
    }

    /// A word when the value starts with a letter or `_`, else a number.
    fn value(&mut self) -> Result<ArgValue> {
        self.skip_ws();
        if self.text[self.pos..].starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') {
            Ok(ArgValue::Word(self.name()?))
        } else {
            Ok(ArgValue::Number(self.number()?))
        }
    }

    fn spec(&mut self) -> Result<PluginSpec> {
        let name = self.name()?;
        let mut spec = PluginSpec {
            name,
            nested: Vec::new(),
            values: Vec::new(),
        };
        if !self.eat('(') {
            return Ok(spec);
        }
        loop {
            let start = self.pos;
            let arg = self.name()?;
            if self.eat('=') {
                if spec.values.iter().any(|(k, _)| *k == arg) {
                    return Err(self.error(&format!("argument '{arg}' given twice")));
                }
                let value = self.value()?;
                spec.values.push((arg, value));
            } else {
                self.pos = start;
                spec.nested.push(self.spec()?);
            }
            if self.eat(')') {
                return Ok(spec);
            }
            if !self.eat(',') {
                return Err(self.error("expected ',' or ')'"));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plugin_spec_parses_nested_and_values() {
        let s = PluginSpec::parse(" height( ggx , scale = 2.5e-2 ) ").unwrap();
        assert_eq!(s.name, "height");
        assert_eq!(s.nested, vec![PluginSpec::parse("ggx").unwrap()]);
        assert_eq!(
            s.values,
            vec![("scale".to_string(), ArgValue::Number(0.025))]
        );
        assert_eq!(s.to_string(), "height(ggx, scale=0.025)");
    }

    #[test]
    fn plugin_spec_parses_word_values() {
        let s = PluginSpec::parse("ggx( shadowing = correlated, fresnel=none )").unwrap();
        assert_eq!(
            s.values,
            vec![
                ("shadowing".to_string(), ArgValue::Word("correlated".into())),
                ("fresnel".to_string(), ArgValue::Word("none".into())),
            ]
        );
        assert_eq!(s.to_string(), "ggx(shadowing=correlated, fresnel=none)");
        assert_eq!(
            serde_json::to_string(&s.values.iter().map(|(_, v)| v).collect::<Vec<_>>()).unwrap(),
            r#"["correlated","none"]"#
        );
    }

    #[test]
    fn plugin_spec_round_trips_through_display() {
        for text in [
            "ggx",
            "height(coated)",
            "a(b(c, k=1), x=-2)",
            "a(b(w=x_y), k=-1)",
        ] {
            let s = PluginSpec::parse(text).unwrap();
            assert_eq!(PluginSpec::parse(&s.to_string()).unwrap(), s);
        }
    }

    #[test]
    fn spec_lists_split_at_top_level_commas_only() {
        assert_eq!(
            split_list(" lambert,ggx , height(ggx, scale=0.05),coated").unwrap(),
            ["lambert", "ggx", "height(ggx, scale=0.05)", "coated"]
        );
        assert_eq!(split_list("ggx").unwrap(), ["ggx"]);
        for bad in ["", "ggx,", "a(b,c", "a)b,c", "ggx,,coated"] {
            assert!(split_list(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn plugin_spec_rejects_malformed_text() {
        for text in [
            "",
            "height(",
            "height(ggx",
            "ggx)",
            "(ggx)",
            "h(s=)",
            "h(s=1, s=2)",
            "h(s=a b)",
            "h(s=1, s=w)",
            "1ggx",
        ] {
            let err = PluginSpec::parse(text).unwrap_err().to_string();
            assert!(err.contains("invalid BRDF specification"), "{text}: {err}");
        }
    }
}
