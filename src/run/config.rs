//! Parameters from the user's text: config files, `--set KEY=VALUE`, `--grid KEY=V1,V2`. The one
//! KEY=VALUE parser of the program, and the one place that turns a table of values into
//! [`Params`] with errors that name the parameter, what it got and what it takes.

use std::path::Path;

use crate::model::Params;
use crate::run::error::RunError;

/// A value typed on the command line: TOML syntax (`0.3`, `true`, `"x"`), and where that fails a
/// number as Rust reads it (`.5`, `1e999`, `NaN`: the checks below then say what is wrong with
/// it), else a bare word as a string (`passive_force=grad_mu`).
pub fn parse_value(text: &str) -> toml::Value {
    let text = text.trim();
    if let Ok(mut t) = format!("x = {text}").parse::<toml::Table>() {
        if let Some(v) = t.remove("x") {
            return v;
        }
    }
    match text.parse::<f64>() {
        Ok(x) => toml::Value::Float(x),
        Err(_) => toml::Value::String(text.to_string()),
    }
}

/// `KEY=VALUE` as given to `flag` (e.g. `--set`).
pub fn parse_assignment(flag: &str, arg: &str) -> Result<(String, toml::Value), RunError> {
    let (k, v) = split(flag, arg, "VALUE")?;
    Ok((k, parse_value(v)))
}

/// `K1=V1,K2=V2,…` as given to `flag` (e.g. `--point`): one value per key, a key given twice
/// refused.
pub fn parse_assignments(flag: &str, arg: &str) -> Result<toml::Table, RunError> {
    let mut table = toml::Table::new();
    for pair in arg.split(',') {
        let (k, v) = parse_assignment(flag, pair)?;
        if table.insert(k.clone(), v).is_some() {
            return Err(RunError::Options(format!("{flag} {arg}: sets `{k}` twice")));
        }
    }
    Ok(table)
}

/// `KEY=V1,V2,…` as given to `flag` (e.g. `--grid`).
pub fn parse_list(flag: &str, arg: &str) -> Result<(String, Vec<toml::Value>), RunError> {
    let (k, vs) = split(flag, arg, "V1,V2,…")?;
    Ok((k, vs.split(',').map(parse_value).collect()))
}

fn split<'a>(flag: &str, arg: &'a str, what: &str) -> Result<(String, &'a str), RunError> {
    match arg.split_once('=') {
        Some((k, v)) if !k.trim().is_empty() => Ok((k.trim().to_string(), v)),
        _ => Err(RunError::Parse(format!("{flag} {arg}: expected KEY={what}, e.g. {flag} zeta=0.4"))),
    }
}

fn show(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => format!("\"{s}\""),
        toml::Value::Float(x) => crate::model::number_text(*x),
        other => other.to_string(),
    }
}

/// The value of one parameter brought to the type its default has, or an error naming it. Whole
/// numbers are taken where reals are wanted and reals with no fraction where counts are wanted
/// (`active_steps = 1e5`); anything that is not a finite number is refused where a number is.
fn coerce(key: &str, v: &toml::Value, default: &toml::Value) -> Result<toml::Value, RunError> {
    use toml::Value as V;
    let bad = |what: String| Err(RunError::Parse(format!("parameter `{key}` = {}: {what}", show(v))));
    match (default, v) {
        (V::Float(_), V::Float(x)) if x.is_finite() => Ok(V::Float(*x)),
        (V::Float(_), V::Integer(i)) => Ok(V::Float(*i as f64)),
        (V::Float(_), _) => bad("must be a finite number".into()),
        (V::Integer(_), V::Integer(i)) if *i >= 0 => Ok(V::Integer(*i)),
        (V::Integer(_), V::Float(x)) if x.is_finite() && *x >= 0.0 && x.fract() == 0.0 && *x < 9.2e18 => {
            Ok(V::Integer(*x as i64))
        }
        (V::Integer(_), V::Float(x)) if x.is_finite() && *x >= 9.2e18 => {
            bad(format!("a whole number too large for any count here (at most {})", i64::MAX))
        }
        (V::Integer(_), _) => bad("must be a whole number ≥ 0".into()),
        (V::String(_), V::String(_)) => Ok(v.clone()),
        (V::String(_), _) => {
            // The variant names are in serde's message for a string that is none of them.
            let e = single(key, V::String(String::new())).unwrap_err().to_string();
            bad(e.rsplit_once("expected ").map(|(_, names)| format!("expected {names}")).unwrap_or(e))
        }
        _ => Ok(v.clone()),
    }
}

/// Deserialises a table holding only `key` (the others default), so that serde's message is
/// about that key.
fn single(key: &str, v: toml::Value) -> Result<Params, RunError> {
    let mut t = toml::Table::new();
    t.insert(key.to_string(), v);
    t.try_into().map_err(|e: toml::de::Error| RunError::Parse(e.message().trim().to_string()))
}

/// [`Params`] from a table of values by parameter name (defaults fill the rest), checked one
/// key at a time; `origin` prefixes every error (the file, `--set`, or the run of a sweep). The
/// ranges are left to [`Params::validate`], once the caller has applied its own options.
pub fn params_from_table(table: &toml::Table, origin: &str) -> Result<Params, RunError> {
    params_from_table_at(table, origin, &|_| None)
}

/// [`params_from_table`] where `at(key)` says where a key's value was given, when known (a
/// config file's line and column), to name it in place of `origin`.
fn params_from_table_at(
    table: &toml::Table,
    origin: &str,
    at: &dyn Fn(&str) -> Option<String>,
) -> Result<Params, RunError> {
    let defaults = toml::Table::try_from(Params::default()).expect("the defaults serialise");
    let mut checked = toml::Table::new();
    for (k, v) in table {
        let origin = at(k).unwrap_or_else(|| origin.to_string());
        let Some(d) = defaults.get(k) else {
            let names: Vec<&str> = defaults.keys().map(String::as_str).collect();
            return Err(RunError::Parse(format!(
                "{origin}: unknown parameter `{k}` (the parameters: {})",
                names.join(", ")
            )));
        };
        let v = coerce(k, v, d).map_err(|e| e.context(origin.clone()))?;
        single(k, v.clone()).map_err(|e| e.context(format!("{origin}: parameter `{k}` = {}", show(&v))))?;
        checked.insert(k.clone(), v);
    }
    checked.try_into().map_err(|e: toml::de::Error| RunError::Parse(format!("{origin}: {}", e.message())))
}

/// A TOML document read into `T`; an error names `origin`, the line and the key (its path).
pub fn from_toml<T: serde::de::DeserializeOwned>(text: &str, origin: &str) -> Result<T, RunError> {
    let error = |e: &toml::de::Error, key: Option<String>| {
        let line =
            e.span().map(|s| text.as_bytes()[..s.start.min(text.len())].iter().filter(|&&b| b == b'\n').count() + 1);
        let at = line.map(|l| format!(", line {l}")).unwrap_or_default();
        let key = key.filter(|k| k != ".").map(|k| format!(" key `{k}`:")).unwrap_or_default();
        let mut message = e.message().trim().replace(
            " as i128, expected any valid TOML value",
            ": too large (a whole number here is at most 9223372036854775807)",
        );
        // A duplicate key: its name is what the span covers.
        if let Some(name) = e.span().and_then(|s| text.get(s)).filter(|n| message.contains("duplicate") && n.len() < 80)
        {
            message = format!("{message} `{}`", name.trim());
        }
        RunError::Parse(format!("{origin}{at}:{key} {message}"))
    };
    let de = toml::Deserializer::parse(text).map_err(|e| error(&e, None))?;
    serde_path_to_error::deserialize(de).map_err(|e| error(e.inner(), Some(e.path().to_string())))
}

/// A finite real number for a key that is not a parameter itself (a sweep's `chi`).
pub fn number(key: &str, v: &toml::Value) -> Result<f64, RunError> {
    match coerce(key, v, &toml::Value::Float(0.0))? {
        toml::Value::Float(x) => Ok(x),
        _ => unreachable!("coerce brings a number to the default's type"),
    }
}

/// Refuses a parameter given twice among the `KEY=VALUE`s of `flag` (`--set gamma=0.06 --set
/// gamma=0.07`): one of the two would be dropped unsaid.
pub fn check_distinct(flag: &str, sets: &[String]) -> Result<(), RunError> {
    let mut seen: Vec<(String, &String)> = Vec::new();
    for s in sets {
        let (k, _) = parse_assignment(flag, s)?;
        if let Some((_, first)) = seen.iter().find(|(key, _)| *key == k) {
            return Err(RunError::Options(format!("{flag} {first} and {flag} {s} both set `{k}`: give one of them")));
        }
        seen.push((k, s));
    }
    Ok(())
}

/// Parameters from an optional TOML file and `KEY=VALUE` overrides of its values, each
/// parameter given once among them ([`check_distinct`]).
pub fn load_params(config: Option<&Path>, overrides: &[String]) -> Result<Params, RunError> {
    check_distinct("--set", overrides)?;
    load_layers(config, overrides)
}

/// [`load_params`] of the user's `overrides` over `base` assignments a command sets itself (a
/// figures scale's), which they replace.
pub fn load_params_over(base: &[String], overrides: &[String]) -> Result<Params, RunError> {
    check_distinct("--set", overrides)?;
    load_layers(None, &[base, overrides].concat())
}

/// Parameters from an optional TOML file and `KEY=VALUE` overrides (later ones win).
fn load_layers(config: Option<&Path>, overrides: &[String]) -> Result<Params, RunError> {
    // Where each key of the file is: a wrong value is named by its line and column.
    let mut places = std::collections::BTreeMap::new();
    let (mut table, origin) = match config {
        Some(path) => {
            let text = crate::run::files::read_text_input(path, "a config file (--config)")?;
            let table: toml::Table = from_toml(&text, &path.display().to_string())?;
            let spans: std::collections::BTreeMap<String, toml::Spanned<toml::Value>> =
                toml::from_str(&text).unwrap_or_default();
            for (k, v) in spans {
                let start = v.span().start.min(text.len());
                let before = &text[..start];
                let line = before.matches('\n').count() + 1;
                let column = before.rsplit('\n').next().unwrap_or("").chars().count() + 1;
                places.insert(k, format!("{}, line {line}, column {column}", path.display()));
            }
            (table, path.display().to_string())
        }
        None => (toml::Table::new(), "--set".to_string()),
    };
    for o in overrides {
        let (k, v) = parse_assignment("--set", o)?;
        places.insert(k.clone(), "--set".to_string());
        table.insert(k, v);
    }
    let origin = if config.is_some() && !overrides.is_empty() { format!("{origin} and --set") } else { origin };
    params_from_table_at(&table, &origin, &|k| places.get(k).cloned())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;

    fn set(args: &[&str]) -> Result<Params, String> {
        load_params(None, &args.iter().map(|s| s.to_string()).collect::<Vec<_>>()).map_err(|e| e.to_string())
    }

    #[test]
    fn overrides_and_unknown_keys() {
        let p = set(&["zeta=0.3", "passive_force=grad_mu"]).unwrap();
        assert_eq!(p.zeta, 0.3);
        assert_eq!(p.passive_force, crate::model::PassiveForce::GradMu);
        let e = set(&["zeta_typo=0.3"]).unwrap_err();
        assert!(e.contains("zeta_typo"), "{e}");
        let e = set(&["zeta"]).unwrap_err();
        assert!(e.contains("KEY=VALUE"), "{e}");
    }

    /// Every wrong value names its parameter, and no number is reported as a string.
    #[test]
    fn bad_values_name_the_parameter() {
        for (arg, expect) in [
            ("zeta=abc", "parameter `zeta` = \"abc\": must be a finite number"),
            ("zeta=1e999", "parameter `zeta` = inf: must be a finite number"),
            ("zeta=NaN", "parameter `zeta` = NaN: must be a finite number"),
            ("zeta=nan", "parameter `zeta` = NaN: must be a finite number"),
            ("active_steps=-3", "parameter `active_steps` = -3: must be a whole number ≥ 0"),
            ("active_steps=2.5", "parameter `active_steps` = 2.5: must be a whole number ≥ 0"),
            ("active_steps=18446744073709551615", "parameter `active_steps`"),
            ("passive_force=3", "parameter `passive_force` = 3: expected `grad_mu` or `phi_grad_mu`"),
            ("passive_force=grad", "parameter `passive_force` = \"grad\": unknown variant `grad`"),
        ] {
            let e = set(&[arg]).unwrap_err();
            assert!(e.contains(expect), "{arg}: {e}");
        }
        assert_eq!(set(&["zeta=.5"]).unwrap().zeta, 0.5);
        assert_eq!(set(&["active_steps=1e3"]).unwrap().active_steps, 1000);
        assert_eq!(set(&["radius=9"]).unwrap().radius, 9.0);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.toml");
        fs::write(&path, "zeta = \"abc\"\n").unwrap();
        let e = load_params(Some(&path), &[]).unwrap_err().to_string();
        assert!(e.contains("c.toml") && e.contains("parameter `zeta` = \"abc\""), "{e}");
    }

    #[test]
    fn lists_and_assignments() {
        let (k, v) = parse_list("--grid", "zeta=0.3, 0.5,grad_mu").unwrap();
        assert_eq!(k, "zeta");
        assert_eq!(v, vec![toml::Value::Float(0.3), toml::Value::Float(0.5), toml::Value::String("grad_mu".into())]);
        assert!(parse_assignment("--set", "=3").is_err());
        assert_eq!(parse_assignment("--set", "seed = 3").unwrap(), ("seed".into(), toml::Value::Integer(3)));
    }
}
