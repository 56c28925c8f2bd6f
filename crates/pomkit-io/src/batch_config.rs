//! The rules file of a batch bake, `pomkit bake ... --config FILE.toml` (README, "Baking a
//! library"): `[[rule]]` tables that set options per folder or per file-name pattern.
//!
//! This module reads and checks the file as far as it can without knowing the verbs' options:
//! the TOML, the keys, the `match` pattern, the `folder` and the `scale`. The names of filters,
//! edge modes, channels and encodings are kept as written; the command line checks them against
//! its own (and says which names it knows).

use std::path::{Component, Path, PathBuf};

use serde::Deserialize;

use crate::read::{MAX_SCENE_BYTES, read_capped};

/// Why a config file was refused. The message names the file, and the rule and key where there
/// is one: `config rules.toml, [[rule]] 2, scale: inf is not a finite number ...`.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct ConfigError(String);

/// One `[[rule]]`, checked as far as this module can (see the module documentation).
#[derive(Clone, Debug, Default)]
pub struct ConfigRule {
    /// The `match` pattern on file names.
    pub pattern: Option<glob::Pattern>,
    /// The `folder`, relative to the folder argument with `.` and `..` parts dropped: empty for
    /// the whole folder (`folder = "."`).
    pub folder: Option<PathBuf>,
    /// `scale`: finite, at most `pomkit_core::bake::MAX_SCALE` in magnitude.
    pub scale: Option<f32>,
    /// `filter`, as written.
    pub filter: Option<String>,
    /// `edges`, as written.
    pub edges: Option<String>,
    /// `y_down`.
    pub y_down: Option<bool>,
    /// `depth_map`.
    pub depth_map: Option<bool>,
    /// `channel`, as written.
    pub channel: Option<String>,
    /// `normalize`.
    pub normalize: Option<bool>,
    /// `encoding`, as written.
    pub encoding: Option<String>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RuleFile {
    #[serde(rename = "match")]
    pattern: Option<String>,
    folder: Option<String>,
    scale: Option<f32>,
    filter: Option<String>,
    edges: Option<String>,
    y_down: Option<bool>,
    depth_map: Option<bool>,
    channel: Option<String>,
    normalize: Option<bool>,
    encoding: Option<String>,
}

/// Reads the config file `path` (at most 64 MiB, UTF-8) and parses it ([`parse_config`]).
///
/// # Errors
/// [`ConfigError`] naming `path`: unreadable, not UTF-8, or as [`parse_config`].
pub fn load_config(path: &Path) -> Result<Vec<ConfigRule>, ConfigError> {
    let bytes = read_capped(path, MAX_SCENE_BYTES, "a config file")
        .map_err(|e| ConfigError(format!("cannot read the config {}: {e}", path.display())))?;
    let text =
        String::from_utf8(bytes).map_err(|e| ConfigError(format!("config {}: not UTF-8 text: {e}", path.display())))?;
    parse_config(&text, path)
}

/// Parses the text of a config file; `path` names it in errors. The rules come in the file's
/// order.
///
/// # Errors
/// [`ConfigError`] naming `path` (and the rule and key): not TOML, a key other than `rule`, a
/// `rule` that is not an array of tables, an unknown key or a value of the wrong type in a
/// rule, a `match` that is not a glob pattern, a `scale` that is not finite or too large.
pub fn parse_config(text: &str, path: &Path) -> Result<Vec<ConfigRule>, ConfigError> {
    let shown = path.display();
    let table: toml::Table = toml::from_str(text).map_err(|e| ConfigError(format!("config {shown}: {e}")))?;
    if let Some(key) = table.keys().find(|k| k.as_str() != "rule") {
        return Err(ConfigError(format!("config {shown}: unknown key `{key}` (a config holds [[rule]] tables only)")));
    }
    let raw_rules = match table.get("rule") {
        None => Vec::new(),
        Some(toml::Value::Array(rules)) => rules.clone(),
        Some(_) => return Err(ConfigError(format!("config {shown}: `rule` must be written as [[rule]] tables"))),
    };
    let mut rules = Vec::with_capacity(raw_rules.len());
    for (i, raw) in raw_rules.into_iter().enumerate() {
        let at = |key: &str| format!("config {shown}, [[rule]] {}, {key}", i + 1);
        let r: RuleFile =
            raw.try_into().map_err(|e| ConfigError(format!("config {shown}, [[rule]] {}: {e}", i + 1)))?;
        if let Some(scale) = r.scale
            && !(scale.is_finite() && scale.abs() <= pomkit_core::bake::MAX_SCALE)
        {
            return Err(ConfigError(format!(
                "{}: {scale} is not a finite number of texel widths from -{max:e} to {max:e}",
                at("scale"),
                max = pomkit_core::bake::MAX_SCALE
            )));
        }
        let pattern = r
            .pattern
            .as_deref()
            .map(glob::Pattern::new)
            .transpose()
            .map_err(|e| ConfigError(format!("{}: {e}", at("match"))))?;
        // Relative to the folder argument: "." (or "") is all of it, "./rocks" is "rocks".
        let folder = r
            .folder
            .as_deref()
            .map(|f| Path::new(f).components().filter(|c| matches!(c, Component::Normal(_))).collect::<PathBuf>());
        rules.push(ConfigRule {
            pattern,
            folder,
            scale: r.scale,
            filter: r.filter,
            edges: r.edges,
            y_down: r.y_down,
            depth_map: r.depth_map,
            channel: r.channel,
            normalize: r.normalize,
            encoding: r.encoding,
        });
    }
    Ok(rules)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rules_keep_their_order_and_folders_drop_dot_parts() {
        let text = "[[rule]]\nfolder = \".\"\nscale = 2.0\n\n[[rule]]\nmatch = \"*_rock*\"\nfolder = \"./a/../b\"\nencoding = \"rg8\"\n";
        let rules = parse_config(text, Path::new("r.toml")).unwrap();
        assert_eq!(rules.len(), 2);
        assert_eq!(rules[0].folder.as_deref(), Some(Path::new("")));
        assert_eq!(rules[0].scale, Some(2.0));
        assert!(rules[1].pattern.as_ref().unwrap().matches("big_rock.png"));
        assert_eq!(rules[1].folder.as_deref(), Some(Path::new("a/b")));
        assert_eq!(rules[1].encoding.as_deref(), Some("rg8"));
    }

    #[test]
    fn every_refusal_names_the_file_the_rule_and_the_key() {
        let cases = [
            ("rule = 3", "config r.toml: `rule` must be written as [[rule]] tables"),
            ("[other]\n", "config r.toml: unknown key `other`"),
            ("[[rule]]\nscale = inf\n", "config r.toml, [[rule]] 1, scale: inf is not a finite number"),
            ("[[rule]]\n[[rule]]\nmatch = \"[\"\n", "config r.toml, [[rule]] 2, match:"),
            ("[[rule]]\nsize = 3\n", "config r.toml, [[rule]] 1: unknown field `size`"),
            ("[[rule]", "config r.toml:"),
        ];
        for (text, want) in cases {
            let err = parse_config(text, Path::new("r.toml")).unwrap_err().to_string();
            assert!(err.starts_with(want), "{text:?}: {err}");
        }
    }
}
