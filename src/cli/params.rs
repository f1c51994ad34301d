//! `fieldprobe params`: the parameter registry (every P-AXIS / P-CHAN / P-MANU of the seeds).

use super::EXIT_OK;
use fieldprobe::params::{find, registry, DefaultValue, ParamDef};

/// Arguments of `fieldprobe params`.
#[derive(Debug, clap::Args)]
pub struct ParamsArgs {
    /// Show one parameter (ID or name path) in full.
    key: Option<String>,
}

fn default_text(d: &ParamDef) -> String {
    match d.default {
        DefaultValue::Int(v) => v.to_string(),
        DefaultValue::Text(t) => format!("\"{t}\""),
    }
}

/// Run the command; returns the exit code.
pub fn run(a: ParamsArgs) -> anyhow::Result<i32> {
    if let Some(k) = a.key {
        let d = find(&k).ok_or_else(|| {
            let hint = fieldprobe::params::suggest(&k)
                .map(|s| format!("; did you mean '{}' ({})?", s.path, s.id))
                .unwrap_or_default();
            anyhow::anyhow!("unknown parameter '{k}'{hint}")
        })?;
        outln!(
            "{}  {}\n  {}\n  type {:?}, default {}\n  range: {}\n  dimension: {}\n  source: {}",
            d.id,
            d.path,
            d.title,
            d.ty,
            default_text(d),
            d.range_text,
            d.dimension,
            d.source
        );
        return Ok(EXIT_OK);
    }
    for d in registry() {
        outln!(
            "{:<13} {:<55} {:<8} {:>12}  {}",
            d.id,
            d.path,
            format!("{:?}", d.ty),
            default_text(d),
            d.range_text
        );
    }
    Ok(EXIT_OK)
}
