//! The `photomat` binary under SIGTERM: `train-gan` finishes the current step, writes its
//! state, prints the resume command and exits with 143 (128 + SIGTERM), and `--resume`
//! continues from the saved step. A child process, since the signal goes to the whole process.
//! Also as a child with stderr to a pipe (not a terminal): a diverging run's warnings.
#![cfg(unix)]

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn photomat() -> Command {
    Command::new(env!("CARGO_BIN_EXE_photomat"))
}

fn succeeded(output: Output, what: &str) -> String {
    let stdout = String::from_utf8(output.stdout).expect("UTF-8 output");
    assert!(
        output.status.success(),
        "{what}: {:?}\n{stdout}\n{}",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    stdout
}

fn run(args: &[&str]) -> String {
    succeeded(photomat().args(args).output().unwrap(), &args.join(" "))
}

/// The flags of a tiny 32² model.
const TINY: [&str; 6] = [
    "--size",
    "32",
    "--multiplier",
    "0.015625",
    "--latent-dim",
    "16",
];

fn path(p: &Path) -> &str {
    p.to_str().expect("UTF-8 temp path")
}

/// A prepared data set of six simulated 128² photos at 64², in `dir/data`.
fn tiny_dataset(dir: &Path) -> std::path::PathBuf {
    let (sim, data) = (dir.join("sim"), dir.join("data"));
    run(&[
        "simulate",
        "--count",
        "6",
        "--size",
        "128",
        "--seed",
        "3",
        "--format",
        "png",
        "--out",
        path(&sim),
    ]);
    run(&[
        "prepare",
        "--photos",
        path(&sim.join("photos")),
        "--out",
        path(&data),
        "--size",
        "64",
    ]);
    data
}

#[test]
fn diverging_updates_are_reported_on_a_non_terminal_stderr_and_not_checkpointed() {
    let dir = tempfile::tempdir().unwrap();
    let (data, out) = (tiny_dataset(dir.path()), dir.path().join("run"));
    // A learning rate of 1e30 sends the weights to infinity after the first update.
    let output = photomat()
        .args(["train-gan", "--data", path(&data), "--out", path(&out)])
        .args(TINY)
        .args(["--steps", "3", "--lr", "1e30"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("warning: step 3: skipped the update: G loss is NaN"),
        "{stderr}"
    );
    assert!(
        stderr.contains("warning: no checkpoint after step 3"),
        "{stderr}"
    );
    let log = std::fs::read_to_string(out.join("log.csv")).unwrap();
    assert!(
        log.lines().last().unwrap().contains("G loss is NaN"),
        "{log}"
    );
    // The folder keeps the first checkpoint, written before any step.
    let state: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("gan.json")).unwrap()).unwrap();
    assert_eq!(state["provenance"]["step"], 0, "{state}");
}

#[test]
fn sigterm_checkpoints_exits_143_and_resumes_from_the_saved_step() {
    let dir = tempfile::tempdir().unwrap();
    let (data, out) = (tiny_dataset(dir.path()), dir.path().join("run"));
    let mut train = photomat();
    train
        .args(["train-gan", "--data", path(&data), "--out", path(&out)])
        .args(TINY)
        .args(["--steps", "100000", "--checkpoint-every", "1"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let child = train.spawn().unwrap();
    let state = out.join("train_state.safetensors");
    let deadline = Instant::now() + Duration::from_secs(600);
    while !state.is_file() {
        assert!(Instant::now() < deadline, "no checkpoint after 10 minutes");
        std::thread::sleep(Duration::from_millis(100));
    }
    // A second writer on the run folder fails at once, naming the first.
    let second = photomat()
        .args(["train-gan", "--out", path(&out), "--resume", "--steps", "2"])
        .output()
        .unwrap();
    let second_err = String::from_utf8_lossy(&second.stderr);
    assert!(!second.status.success(), "{second_err}");
    assert!(
        second_err.contains(&format!(
            "in use by process {} (photomat train-gan)",
            child.id()
        )),
        "{second_err}"
    );
    // SAFETY: kill(2) on the child's PID, which stays its own until it is waited for below.
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGTERM) }, 0);
    let output = child.wait_with_output().unwrap();
    let stdout = String::from_utf8(output.stdout).unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(143), "{stdout}\n{stderr}");
    assert!(stderr.contains("SIGTERM"), "{stderr}");
    assert!(state.is_file() && out.join("gan.safetensors").is_file());
    let saved: u64 = stdout
        .split("interrupted at step ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no interruption line in:\n{stdout}"));
    assert!(saved >= 1, "{stdout}");
    assert!(
        stdout.contains(&format!(
            "photomat train-gan --out {} --resume",
            out.display()
        )),
        "{stdout}"
    );

    let next = (saved + 1).to_string();
    let resumed = run(&[
        "train-gan",
        "--out",
        path(&out),
        "--resume",
        "--steps",
        &next,
    ]);
    assert!(
        resumed.contains(&format!("steps {saved} → {next}")),
        "{resumed}"
    );
    assert!(
        resumed.contains(&format!("trained 1 steps ({next} in total")),
        "{resumed}"
    );
    // The printed command resumes with the run's own cadence (train.json keeps it).
    let saved: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("train.json")).unwrap()).unwrap();
    assert_eq!(saved["cadence"]["checkpoint_every"], 1, "{saved}");
}
