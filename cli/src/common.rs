//! What several commands share and no library owns: the progress-bar style, the Ctrl-C stop
//! flag of the training commands, argument parsers used by more than one command, the
//! orbit lights of `--orbit N --radius R`, and the shortest decimal form of f32 constants.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use photomat_core::LightSet;
use photomat_data::highlight::DetectorKind;

/// A progress bar of `len` units on stderr; `template` is indicatif's, with `{bar:W}`.
pub fn progress_bar(len: u64, template: &str) -> ProgressBar {
    ProgressBar::new(len).with_style(
        ProgressStyle::with_template(template)
            .expect("the templates of this crate are valid")
            .progress_chars("=> "),
    )
}

/// The progress bar of a training run over `total` steps, starting at `start`.
pub fn steps_bar(total: u64, start: u64) -> ProgressBar {
    let bar = progress_bar(
        total,
        "{elapsed_precise} [{bar:30}] {pos}/{len} steps ({eta} left) {msg}",
    );
    bar.set_position(start);
    bar
}

/// Set by the Ctrl-C handler; the training loops stop after the current step.
static STOP: OnceLock<Arc<AtomicBool>> = OnceLock::new();

/// The stop flag, cleared, installing the Ctrl-C handler on first use (once per process).
pub fn stop_flag() -> anyhow::Result<Arc<AtomicBool>> {
    if let Some(flag) = STOP.get() {
        flag.store(false, Ordering::SeqCst);
        return Ok(flag.clone());
    }
    let flag = Arc::new(AtomicBool::new(false));
    let handler_flag = flag.clone();
    ctrlc::set_handler(move || {
        // A second Ctrl-C while the step finishes exits at once: checkpoints are written
        // atomically, so the last one stays intact (130 = 128 + SIGINT, the shell's code).
        if handler_flag.swap(true, Ordering::SeqCst) {
            eprintln!("\ninterrupted twice: exiting without saving the current step");
            std::process::exit(130);
        }
        eprintln!("\nCtrl-C: finishing the current step, then saving (Ctrl-C again to quit now)");
    })
    .context("cannot install the Ctrl-C handler")?;
    Ok(STOP.get_or_init(|| flag).clone())
}

/// `--detector NAME` of `prepare` and `eval-detector`.
pub fn parse_detector(name: &str) -> Result<DetectorKind, String> {
    name.parse()
        .map_err(|e: photomat_core::Error| e.to_string())
}

/// The lights of `--orbit N --radius R`, the error naming `--radius`.
pub fn orbit_lights(count: u32, radius: f64) -> anyhow::Result<LightSet> {
    LightSet::orbit(count as usize, radius).map_err(|e| anyhow::anyhow!("--radius: {e}"))
}

/// The f64 with the f32's shortest decimal form: spec constants written `0.04` in a plugin
/// show (and evaluate in f64) as 0.04 rather than 0.03999999910593033, the f32's exact value.
pub fn shortest(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(v as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shortest_keeps_the_written_decimal() {
        assert_eq!(shortest(0.04), 0.04);
        assert_ne!(0.04f32 as f64, 0.04);
    }

    #[test]
    fn orbit_errors_name_the_flag() {
        let err = orbit_lights(3, -1.0).unwrap_err().to_string();
        assert!(err.contains("--radius") && err.contains("-1"), "{err}");
        assert_eq!(orbit_lights(4, 0.35).unwrap().len(), 4);
    }
}
