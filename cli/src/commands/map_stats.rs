//! `photomat map-stats PATH… [--json]`: the spread of material maps (`photomat_core::map_stats`)
//! for every material folder at or under the given paths: a `material.json` folder, a
//! `photomat sample` output (its `seed-*/material/`) or a `photomat simulate` output (its
//! `truth/*/`). Prints per folder the normal-angle spread and each map's standard deviation,
//! then the mean over the folders, so that generated materials can be compared with the
//! ground truth of the families they learned from.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use photomat_core::map_files::{MANIFEST_FILE, load_maps};
use photomat_core::map_stats::{MapSpread, map_spread};
use serde_json::json;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Material folders, or folders to search (two levels deep) for material folders.
    #[arg(value_name = "PATH", required = true)]
    pub paths: Vec<PathBuf>,

    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let mut folders = Vec::new();
    for path in &args.paths {
        let found = material_folders(path)?;
        if found.is_empty() {
            bail!(
                "'{}' holds no material folder (a folder with {MANIFEST_FILE}) within two levels",
                path.display()
            );
        }
        folders.extend(found);
    }
    let mut rows = Vec::new();
    for folder in &folders {
        let material = load_maps(folder, None)?;
        let spread = map_spread(&material.brdf, &material.maps)
            .with_context(|| format!("cannot measure the maps in '{}'", folder.display()))?;
        rows.push((folder.clone(), material.brdf.name(), spread));
    }
    let names = map_names(&rows);
    if args.json {
        let materials: Vec<_> = rows
            .iter()
            .map(|(f, brdf, s)| json!({ "folder": f, "brdf": brdf, "spread": s }))
            .collect();
        let mean: serde_json::Map<String, serde_json::Value> = names
            .iter()
            .map(|n| (format!("{n}_std"), json!(mean_of(&rows, |s| map_std(s, n)))))
            .collect();
        let value = json!({
            "materials": materials,
            "mean": {
                "normal_angle_rms_deg": mean_of(&rows, |s| s.normal_angle_rms_deg),
                "maps": mean,
            },
        });
        writeln!(out, "{}", serde_json::to_string_pretty(&value)?)?;
        return Ok(());
    }
    let header: Vec<String> = names.iter().map(|n| format!("{n} std")).collect();
    writeln!(
        out,
        "{:<40} {:>13} {}",
        "material",
        "normal rms °",
        header
            .iter()
            .map(|h| format!(" {h:>14}"))
            .collect::<String>()
    )?;
    let cell = |v: Option<f64>| v.map_or(format!(" {:>14}", "–"), |v| format!(" {v:>14.4}"));
    for (folder, _, spread) in &rows {
        let cells: String = names.iter().map(|n| cell(map_std(spread, n))).collect();
        writeln!(
            out,
            "{:<40} {:>13} {cells}",
            short(folder),
            spread
                .normal_angle_rms_deg
                .map_or("–".into(), |v| format!("{v:.2}"))
        )?;
    }
    let cells: String = names
        .iter()
        .map(|n| cell(mean_of(&rows, |s| map_std(s, n))))
        .collect();
    writeln!(
        out,
        "{:<40} {:>13} {cells}",
        format!("mean of {}", rows.len()),
        mean_of(&rows, |s| s.normal_angle_rms_deg).map_or("–".into(), |v| format!("{v:.2}"))
    )?;
    Ok(())
}

/// The folder holding `material.json` at `path`, or those one or two levels below it, sorted.
fn material_folders(path: &Path) -> anyhow::Result<Vec<PathBuf>> {
    if path.join(MANIFEST_FILE).is_file() {
        return Ok(vec![path.to_path_buf()]);
    }
    if !path.is_dir() {
        bail!("'{}' is not a folder", path.display());
    }
    let mut found = Vec::new();
    let mut level = vec![path.to_path_buf()];
    for _ in 0..2 {
        let mut next = Vec::new();
        for dir in &level {
            let entries = std::fs::read_dir(dir)
                .with_context(|| format!("cannot list '{}'", dir.display()))?;
            for entry in entries.flatten() {
                let p = entry.path();
                if !p.is_dir() {
                    continue;
                }
                if p.join(MANIFEST_FILE).is_file() {
                    found.push(p);
                } else {
                    next.push(p);
                }
            }
        }
        level = next;
    }
    found.sort();
    Ok(found)
}

/// The maps of every row, in first-seen order.
fn map_names(rows: &[(PathBuf, String, MapSpread)]) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for (_, _, s) in rows {
        for m in &s.maps {
            if !names.contains(&m.name) {
                names.push(m.name.clone());
            }
        }
    }
    names
}

/// Mean over the channels of map `name`'s std, if the material has that map.
fn map_std(spread: &MapSpread, name: &str) -> Option<f64> {
    let m = spread.maps.iter().find(|m| m.name == name)?;
    Some(m.std.iter().sum::<f64>() / m.std.len() as f64)
}

/// Mean of `value` over the rows that have it.
fn mean_of(
    rows: &[(PathBuf, String, MapSpread)],
    value: impl Fn(&MapSpread) -> Option<f64>,
) -> Option<f64> {
    let values: Vec<f64> = rows.iter().filter_map(|(_, _, s)| value(s)).collect();
    (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
}

/// The last two components of a folder, for the table.
fn short(folder: &Path) -> String {
    let parts: Vec<_> = folder.components().rev().take(2).collect();
    parts
        .iter()
        .rev()
        .map(|c| c.as_os_str().to_string_lossy())
        .collect::<Vec<_>>()
        .join("/")
}
