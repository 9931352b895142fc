//! One rule for how a trainer's settings meet its saved configuration, fresh or resumed.
//!
//! A trainer declares its settings once, as a table of [`Setting`]s: the command-line flag,
//! the field of `train.json` it sets, whether a resume may change it ([`OnResume`]), and how to
//! read the given value, read the configuration's value and apply one to the other. [`merge`]
//! then builds the configuration a run trains with from a base (the defaults for a fresh run,
//! the saved `train.json` for a resumed one):
//!
//! - a fresh run takes every setting that was given;
//! - a resumed run refuses a [`OnResume::Fixed`] setting whose given value differs from the
//!   saved one (the error names every such flag and field), and takes an
//!   [`OnResume::MayChange`] one (where the data lives, the learning rate, the cadence of
//!   outputs) with a note saying what changed from here on.
//!
//! Values are compared as the text the configuration prints them with, so `--batch 4` agrees
//! with a saved `4` and `--lr 0.001` with a saved `0.001` (docs/robustness.md, "Interrupted training").

use std::path::Path;

/// Whether a resumed run may change a setting.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OnResume {
    /// Fixed when the run starts (architecture, batch, seed, losses): the resumed run would not
    /// continue the same training with another value.
    Fixed,
    /// May change when resuming; `why` is said with the note (e.g. what records the change).
    MayChange { why: &'static str },
}

/// One setting of a trainer whose given settings are `S` and whose configuration is `C`.
pub struct Setting<S, C> {
    /// The command-line flag, e.g. `--batch`.
    pub flag: &'static str,
    /// The field of the saved configuration it sets, e.g. `batch` or `generator.resolution`.
    pub field: &'static str,
    /// Whether a resume may change it.
    pub on_resume: OnResume,
    /// The given value as text, when it was given.
    pub given: fn(&S) -> Option<String>,
    /// The configuration's value as text.
    pub current: fn(&C) -> String,
    /// Writes the given value into the configuration; called only when `given` is `Some`.
    pub apply: fn(&S, &mut C),
}

/// The configuration a run trains with, and what to tell the user about it.
#[derive(Debug, Clone, PartialEq)]
pub struct Merged<C> {
    pub config: C,
    /// Lines for the user (`note: …`), one per setting a resume changed.
    pub notes: Vec<String>,
}

/// Applies the given `settings` to `base` by `table` (module docs). `resumed_from` is the saved
/// configuration's file for a resumed run (named in the error), `None` for a fresh run.
pub fn merge<S, C>(
    table: &[Setting<S, C>],
    settings: &S,
    mut base: C,
    resumed_from: Option<&Path>,
) -> anyhow::Result<Merged<C>> {
    let mut notes = Vec::new();
    let mut conflicts = Vec::new();
    for setting in table {
        let Some(given) = (setting.given)(settings) else {
            continue;
        };
        if let Some(_file) = resumed_from {
            let saved = (setting.current)(&base);
            if given != saved {
                match setting.on_resume {
                    OnResume::Fixed => {
                        conflicts.push(format!(
                            "{} {given} contradicts {} = {saved} of the run",
                            setting.flag, setting.field
                        ));
                        continue;
                    }
                    OnResume::MayChange { why } => notes.push(format!(
                        "note: {} {given} from here on (the run had {saved}{}{why})",
                        setting.flag,
                        if why.is_empty() { "" } else { "; " },
                    )),
                }
            }
        }
        (setting.apply)(settings, &mut base);
    }
    if let (Some(file), false) = (resumed_from, conflicts.is_empty()) {
        anyhow::bail!(
            "cannot resume {}: {} (leave the flag out to keep the run's value)",
            file.display(),
            conflicts.join("; ")
        );
    }
    Ok(Merged {
        config: base,
        notes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Default)]
    struct Given {
        batch: Option<usize>,
        lr: Option<f64>,
    }

    #[derive(Debug, Clone, PartialEq)]
    struct Config {
        batch: usize,
        lr: f64,
    }

    const TABLE: [Setting<Given, Config>; 2] = [
        Setting {
            flag: "--batch",
            field: "batch",
            on_resume: OnResume::Fixed,
            given: |s| s.batch.map(|v| v.to_string()),
            current: |c| c.batch.to_string(),
            apply: |s, c| c.batch = s.batch.unwrap_or(c.batch),
        },
        Setting {
            flag: "--lr",
            field: "lr",
            on_resume: OnResume::MayChange {
                why: "log.csv records it",
            },
            given: |s| s.lr.map(|v| v.to_string()),
            current: |c| c.lr.to_string(),
            apply: |s, c| c.lr = s.lr.unwrap_or(c.lr),
        },
    ];

    const SAVED: Config = Config { batch: 4, lr: 0.01 };

    #[test]
    fn a_fresh_run_takes_every_given_setting() {
        let given = Given {
            batch: Some(8),
            lr: Some(0.5),
        };
        let merged = merge(&TABLE, &given, SAVED, None).unwrap();
        assert_eq!(merged.config, Config { batch: 8, lr: 0.5 });
        assert!(merged.notes.is_empty());
    }

    #[test]
    fn a_resume_refuses_fixed_changes_and_notes_the_others() {
        let file = Path::new("run/train.json");
        let same = Given {
            batch: Some(4),
            lr: None,
        };
        let merged = merge(&TABLE, &same, SAVED, Some(file)).unwrap();
        assert_eq!((merged.config, merged.notes.len()), (SAVED, 0));
        let lower = Given {
            batch: None,
            lr: Some(0.001),
        };
        let merged = merge(&TABLE, &lower, SAVED, Some(file)).unwrap();
        assert_eq!(merged.config.lr, 0.001);
        assert_eq!(
            merged.notes,
            ["note: --lr 0.001 from here on (the run had 0.01; log.csv records it)"]
        );
        let other = Given {
            batch: Some(8),
            lr: Some(0.001),
        };
        let err = merge(&TABLE, &other, SAVED, Some(file))
            .unwrap_err()
            .to_string();
        assert_eq!(
            err,
            "cannot resume run/train.json: --batch 8 contradicts batch = 4 of the run \
             (leave the flag out to keep the run's value)"
        );
    }
}
