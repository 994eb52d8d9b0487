//! Loading a configuration: the defaults, the TOML file, each `--set KEY=VALUE` in
//! order, merged as TOML tables and read once; an error names the key and blames
//! the file or the `--set` it came from.

use super::former::{Former, former};
use super::{ConfigError, DaemonConfig};
use std::path::Path;

impl DaemonConfig {
    /// The defaults, over them the TOML file `file` (if any), over that each
    /// `KEY=VALUE` of `sets` in order (a dotted key; the value is read as TOML, and
    /// as a string if it is not TOML, so `prefix=lab/` needs no quotes). Values are
    /// not range-checked yet: see [`DaemonConfig::validate`].
    pub fn load(file: Option<&Path>, sets: &[impl AsRef<str>]) -> Result<DaemonConfig, ConfigError> {
        let mut table = toml::Table::new();
        if let Some(path) = file {
            let text =
                std::fs::read_to_string(path).map_err(|source| ConfigError::Read { path: path.into(), source })?;
            table = text.parse().map_err(|e: toml::de::Error| ConfigError::Syntax {
                path: path.into(),
                message: e.to_string().trim_end().to_string(),
            })?;
            // The file alone first, so that its mistakes are blamed on it.
            from_table(table.clone(), &|_| path.display().to_string())?;
        }
        let mut keys = Vec::new();
        for set in sets {
            let set = set.as_ref();
            let (key, value) = set.split_once('=').ok_or_else(|| ConfigError::Set(set.to_string()))?;
            let path: Vec<&str> = key.split('.').collect();
            if path.iter().any(|p| p.is_empty() || !p.bytes().all(|b| b.is_ascii_lowercase() || b == b'_')) {
                return Err(ConfigError::Set(set.to_string()));
            }
            let value = toml_value(value);
            insert(&mut table, &path, value).map_err(|parent| ConfigError::Key {
                origin: format!("--set {set}"),
                key: parent,
                message: "is not a table".into(),
            })?;
            keys.push((key.to_string(), set.to_string()));
        }
        // Blame the last `--set` of the key in error, or of a table holding it.
        let origin = |key: &str| {
            keys.iter()
                .rev()
                .find(|(k, _)| key == k || key.starts_with(&format!("{k}.")) || k.starts_with(&format!("{key}.")))
                .map_or_else(|| "--set".to_string(), |(_, set)| format!("--set {set}"))
        };
        from_table(table, &origin)
    }
}

/// `text` as a TOML value, or as a string if it is not one.
fn toml_value(text: &str) -> toml::Value {
    match format!("v = {text}").parse::<toml::Table>() {
        Ok(mut t) => t.remove("v").unwrap_or_else(|| toml::Value::String(text.to_string())),
        Err(_) => toml::Value::String(text.to_string()),
    }
}

/// Puts `value` at the dotted `path` of `table`, making tables on the way; the
/// error is the key on the way that holds something else.
fn insert(table: &mut toml::Table, path: &[&str], value: toml::Value) -> Result<(), String> {
    let (last, parents) = path.split_last().expect("a key has one part at least");
    let mut at = table;
    for (i, p) in parents.iter().enumerate() {
        let next = at.entry(p.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
        at = next.as_table_mut().ok_or_else(|| path[..=i].join("."))?;
    }
    at.insert(last.to_string(), value);
    Ok(())
}

/// `table` as a configuration, the defaults under it; an error is blamed on
/// `origin(key)`.
fn from_table(table: toml::Table, origin: &dyn Fn(&str) -> String) -> Result<DaemonConfig, ConfigError> {
    serde_path_to_error::deserialize(toml::Value::Table(table)).map_err(|e| {
        let key = e.path().to_string();
        let mut message = dyfos_shared::scenario::suggest(e.inner().message().to_string());
        if message.starts_with("unknown field") {
            let name = key.rsplit('.').next().unwrap_or(&key);
            message = match former(name) {
                Some(Former::Moved(new)) => format!("is now `{new}`: write that instead"),
                Some(Former::Removed(why)) => format!("was removed: {why}; leave it out"),
                None => format!("is not a key: {message}"),
            };
        }
        ConfigError::Key { origin: origin(&key), key, message }
    })
}
