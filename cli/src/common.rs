//! What several commands share and no library owns: the progress-bar style, the stop flag
//! of the training commands (SIGINT, SIGTERM, SIGHUP) and their exit status, argument
//! parsers used by more than one command, the orbit lights of `--orbit N --radius R`, the
//! model folder a command uses by default (`--model`, `$PHOTOMAT_MODEL`, the bundled one), and
//! the shortest decimal form of f32 constants.

use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};
use std::sync::{Arc, OnceLock};

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use photomat_core::LightSet;
use photomat_data::highlight::DetectorKind;
use photomat_estimator::sample::missing_model_file;

/// Environment variable naming the default model folder.
pub const MODEL_ENV: &str = "PHOTOMAT_MODEL";

/// The bundled model folder of this source tree.
pub fn bundled_model_dir() -> PathBuf {
    let cli = Path::new(env!("CARGO_MANIFEST_DIR"));
    // The workspace root is the CLI crate's parent folder.
    cli.parent().unwrap_or(cli).join("models").join("demo")
}

/// The model folder to use: `--model`, else `$PHOTOMAT_MODEL`, else the bundled one; an error
/// naming the path tried and how to train a model if it holds none.
pub fn model_dir(arg: Option<&Path>) -> anyhow::Result<PathBuf> {
    let (dir, source) = match (arg, std::env::var_os(MODEL_ENV)) {
        (Some(dir), _) => (dir.to_path_buf(), "--model"),
        (None, Some(env)) => (PathBuf::from(env), "$PHOTOMAT_MODEL"),
        (None, None) => (bundled_model_dir(), "the bundled model folder"),
    };
    if let Some(missing) = missing_model_file(&dir) {
        bail!(
            "no trained model in '{}' ({source}): {missing} is missing. Train one with \
             `photomat train-gan --data DATASET --out RUN`, then `photomat train-estimator \
             --gan RUN --brdf 'height(ggx)' --out MODEL`, and pass --model MODEL (or set \
             ${MODEL_ENV})",
            dir.display()
        );
    }
    Ok(dir)
}

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

/// Set by the signal handler; the training loops stop after the current step.
static STOP: OnceLock<Arc<AtomicBool>> = OnceLock::new();

/// The number of the first SIGINT, SIGTERM or SIGHUP since [`stop_flag`] was last called (0:
/// none), so the command exits with 128 + that number, as a shell reports a process killed
/// by it.
static SIGNAL: AtomicI32 = AtomicI32::new(0);

/// SIGINT (Ctrl-C) on platforms without Unix signals.
const SIGINT: i32 = 2;

/// The stop flag, cleared, installing the handler of SIGINT, SIGTERM and SIGHUP (Ctrl-C only
/// off Unix) on first use, once per process: a scheduler's, container's or `timeout`'s stop
/// checkpoints like Ctrl-C. A second signal while the step finishes exits at once with
/// 128 + its number: checkpoints are written atomically, so the last one stays intact.
pub fn stop_flag() -> anyhow::Result<Arc<AtomicBool>> {
    SIGNAL.store(0, Ordering::SeqCst);
    if let Some(flag) = STOP.get() {
        flag.store(false, Ordering::SeqCst);
        return Ok(flag.clone());
    }
    let flag = STOP
        .get_or_init(|| Arc::new(AtomicBool::new(false)))
        .clone();
    install_handler()?;
    Ok(flag)
}

/// The `--help` note of the training commands on signals and exit status.
pub const STOP_HELP: &str = "Ctrl-C (SIGINT), SIGTERM and SIGHUP finish the current step, save the state and print \
the resume command; the exit status is then 130 (SIGINT) or 143 (SIGTERM; 129 SIGHUP), 128 + the \
signal number. A second signal exits at once, keeping the last checkpoint.";

/// The interruption of a training command whose stop flag was set: the signal that set it.
pub fn interruption() -> Interrupted {
    match SIGNAL.load(Ordering::SeqCst) {
        0 => Interrupted { signal: SIGINT },
        signal => Interrupted { signal },
    }
}

/// A training run stopped by a signal after checkpointing; `photomat_cli::run` exits with
/// [`Interrupted::exit_code`] (130 after SIGINT, 143 after SIGTERM, 129 after SIGHUP), so
/// `train-gan … && train-estimator …` does not go on with a half-trained model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Interrupted {
    /// The signal number (2 SIGINT, 15 SIGTERM, 1 SIGHUP).
    pub signal: i32,
}

impl Interrupted {
    /// 128 + the signal number, the shell's code for a process ended by that signal.
    pub fn exit_code(&self) -> u8 {
        (128 + self.signal).clamp(0, 255) as u8
    }

    fn name(&self) -> String {
        match self.signal {
            1 => "SIGHUP".into(),
            2 => "SIGINT".into(),
            15 => "SIGTERM".into(),
            n => format!("signal {n}"),
        }
    }
}

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "stopped by {} after saving the state (exit status {})",
            self.name(),
            self.exit_code()
        )
    }
}

impl std::error::Error for Interrupted {}

/// Unix: SIGINT, SIGTERM and SIGHUP through `sigaction`, the handler recording which one
/// arrived (the `ctrlc` crate's handler is not told). It only touches atomics and calls
/// `write(2)` and `_exit(2)`, both async-signal-safe (POSIX.1-2017 §2.4.3).
#[cfg(unix)]
fn install_handler() -> anyhow::Result<()> {
    extern "C" fn on_signal(signal: libc::c_int) {
        let Some(flag) = STOP.get() else { return };
        let message: &[u8] = if flag.swap(true, Ordering::SeqCst) {
            let text: &[u8] = b"\ninterrupted twice: exiting without saving the current step\n";
            // SAFETY: write(2) and _exit(2) are async-signal-safe; `text` is a static buffer.
            unsafe {
                libc::write(2, text.as_ptr().cast(), text.len());
                libc::_exit(128 + signal);
            }
        } else {
            let _ = SIGNAL.compare_exchange(0, signal, Ordering::SeqCst, Ordering::SeqCst);
            match signal {
                libc::SIGINT => {
                    b"\nCtrl-C: finishing the current step, then saving (Ctrl-C again to quit now)\n"
                }
                libc::SIGTERM => {
                    b"\nSIGTERM: finishing the current step, then saving (again to quit now)\n"
                }
                _ => b"\nSIGHUP: finishing the current step, then saving (again to quit now)\n",
            }
        };
        // SAFETY: as above.
        unsafe {
            libc::write(2, message.as_ptr().cast(), message.len());
        }
    }
    for signal in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
        // SAFETY: a zeroed sigaction is valid (empty mask, no flags); the handler is an
        // `extern "C" fn(c_int)`, what `sa_sigaction` holds without SA_SIGINFO.
        let failed = unsafe {
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
            action.sa_flags = libc::SA_RESTART;
            libc::sigemptyset(&mut action.sa_mask);
            libc::sigaction(signal, &action, std::ptr::null_mut()) != 0
        };
        if failed {
            return Err(std::io::Error::last_os_error())
                .with_context(|| format!("cannot install the handler of signal {signal}"));
        }
    }
    Ok(())
}

/// Elsewhere: Ctrl-C through the `ctrlc` crate.
#[cfg(not(unix))]
fn install_handler() -> anyhow::Result<()> {
    ctrlc::set_handler(|| {
        let Some(flag) = STOP.get() else { return };
        if flag.swap(true, Ordering::SeqCst) {
            eprintln!("\ninterrupted twice: exiting without saving the current step");
            std::process::exit(128 + SIGINT);
        }
        let _ = SIGNAL.compare_exchange(0, SIGINT, Ordering::SeqCst, Ordering::SeqCst);
        eprintln!("\nCtrl-C: finishing the current step, then saving (Ctrl-C again to quit now)");
    })
    .context("cannot install the Ctrl-C handler")
}

/// Two finite numbers separated by a comma (`A,B`); errors show `shape`, e.g. `ROW,COL`.
pub fn parse_pair(text: &str, shape: &str) -> Result<(f64, f64), String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    match parts.as_slice() {
        [a, b] => match (a.parse::<f64>(), b.parse::<f64>()) {
            (Ok(a), Ok(b)) if a.is_finite() && b.is_finite() => Ok((a, b)),
            _ => Err(format!("'{text}' is not {shape} (two numbers)")),
        },
        _ => Err(format!("'{text}' is not {shape} (two numbers)")),
    }
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
