//! The `photomat` binary never overwrites a result without asking and checks memory before it
//! spends it (docs/robustness.md, "Output folders", "Limits"): `capture` onto an earlier
//! capture is refused, `--overwrite` leaves no file of the old one, a capture killed during an
//! overwrite leaves the old or the new capture whole, inputs inside the output and a highlight
//! outside the photo are refused, settings over the memory budget are refused with the
//! estimate, and an interrupted capture says so on stderr. A child process, since kills and
//! signals go to the whole process.
#![cfg(unix)]

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn photomat() -> Command {
    Command::new(env!("CARGO_BIN_EXE_photomat"))
}

fn path(p: &Path) -> &str {
    p.to_str().expect("UTF-8 temp path")
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

fn succeeded(output: Output, what: &str) {
    assert!(
        output.status.success(),
        "{what}: {:?}\n{}",
        output.status,
        stderr(&output)
    );
}

/// One simulated 64² flash photo, written by `photomat simulate`.
fn photo(dir: &Path) -> PathBuf {
    let sim = dir.join("sim");
    let output = photomat()
        .args(["simulate", "--count", "1", "--size", "64", "--seed", "2"])
        .args(["--format", "png", "--out", path(&sim)])
        .output()
        .unwrap();
    succeeded(output, "simulate");
    sim.join("photos/000000.png")
}

/// `photomat capture PHOTO --brdf SPEC --out OUT` of a quick fit (32², 30 steps, a warm-up
/// of 5), with `extra` flags, which replace those defaults they name.
fn capture(photo: &Path, spec: &str, out: &Path, extra: &[&str]) -> Command {
    let mut command = photomat();
    command.args(["capture", path(photo), "--brdf", spec, "--out", path(out)]);
    for (flag, value) in [("--size", "32"), ("--steps", "30"), ("--warmup-steps", "5")] {
        if !extra.contains(&flag) {
            command.args([flag, value]);
        }
    }
    command
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    command
}

/// The model a capture folder holds, after checking that it is whole: `capture.json` names
/// it, `material/` holds exactly the files its manifest names, and `export/` exists.
fn whole_capture(out: &Path) -> String {
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("capture.json")).unwrap()).unwrap();
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("material/material.json")).unwrap())
            .unwrap();
    assert_eq!(
        record["brdf"], manifest["brdf"],
        "capture.json and material/ disagree"
    );
    let mut named: BTreeSet<String> = BTreeSet::from(["material.json".to_string()]);
    for map in manifest["maps"].as_array().unwrap() {
        for key in ["png", "exr"] {
            if let Some(file) = map[key].as_str() {
                named.insert(file.to_string());
            }
        }
    }
    let held: BTreeSet<String> = std::fs::read_dir(out.join("material"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| !n.starts_with('.'))
        .collect();
    assert_eq!(held, named, "material/ holds a file of another capture");
    assert!(out.join("export").is_dir() && out.join("sheet.png").is_file());
    record["brdf"].as_str().unwrap().to_string()
}

#[test]
fn capture_refuses_an_earlier_capture_and_overwrite_replaces_it_whole() {
    let dir = tempfile::tempdir().unwrap();
    let photo = photo(dir.path());
    let out = dir.path().join("cap");
    succeeded(
        capture(&photo, "height(ggx)", &out, &[]).output().unwrap(),
        "first",
    );
    assert!(whole_capture(&out).starts_with("height(ggx"));
    let again = capture(&photo, "lambert", &out, &[]).output().unwrap();
    assert!(!again.status.success());
    assert!(
        stderr(&again).contains("already holds a capture")
            && stderr(&again).contains("--overwrite"),
        "{}",
        stderr(&again)
    );
    succeeded(
        capture(&photo, "lambert", &out, &["--overwrite"])
            .output()
            .unwrap(),
        "overwrite",
    );
    // Nothing of the height(ggx) capture is left: no height, specular or roughness map.
    assert_eq!(whole_capture(&out), "lambert");
    assert!(!out.join("material/height.png").exists());

    // Inputs inside the output, and a highlight outside the photo, are refused.
    let known = capture(
        &photo,
        "lambert",
        &out,
        &["--overwrite", "--known", path(&out.join("material"))],
    )
    .output()
    .unwrap();
    assert!(
        stderr(&known).contains("--known lies inside the output folder"),
        "{}",
        stderr(&known)
    );
    let outside = capture(
        &photo,
        "lambert",
        &dir.path().join("c2"),
        &["--highlight", "500,-3"],
    )
    .output()
    .unwrap();
    assert!(
        stderr(&outside).contains("--highlight 500,-3 lies outside the 32×32 square"),
        "{}",
        stderr(&outside)
    );
    // A GIF is refused naming what photos are read as, not another command.
    let gif = dir.path().join("photo.gif");
    std::fs::write(&gif, b"GIF89a\x01\x00\x01\x00\x00\x00\x00;").unwrap();
    let gif = capture(&gif, "lambert", &dir.path().join("c3"), &[])
        .output()
        .unwrap();
    assert!(
        stderr(&gif).contains("photos are read as JPEG or PNG")
            && !stderr(&gif).contains("prepare"),
        "{}",
        stderr(&gif)
    );
}

#[test]
fn a_capture_killed_during_an_overwrite_leaves_the_old_or_the_new_capture_whole() {
    let dir = tempfile::tempdir().unwrap();
    let photo = photo(dir.path());
    let out = dir.path().join("cap");
    succeeded(
        capture(&photo, "height(ggx)", &out, &[]).output().unwrap(),
        "first",
    );
    let mut seen = BTreeSet::new();
    // Kills spread over a capture's run, from its start to its commit.
    for delay_ms in [0u64, 150, 400, 800, 1300, 2000, 3000] {
        let mut child = capture(&photo, "lambert", &out, &["--overwrite"])
            .spawn()
            .unwrap();
        std::thread::sleep(Duration::from_millis(delay_ms));
        child.kill().unwrap();
        child.wait().unwrap();
        // The next command on the folder finishes or undoes what the kill interrupted.
        photomat_core::output_folder::recover(&out).unwrap();
        let model = whole_capture(&out);
        assert!(
            model == "lambert" || model.starts_with("height(ggx"),
            "{model}"
        );
        seen.insert(model);
        // Back to the old capture for the next kill.
        if seen.contains("lambert") {
            succeeded(
                capture(&photo, "height(ggx)", &out, &["--overwrite"])
                    .output()
                    .unwrap(),
                "reset",
            );
        }
    }
}

#[test]
fn settings_over_the_memory_budget_are_refused_with_the_estimate() {
    let dir = tempfile::tempdir().unwrap();
    let photo = photo(dir.path());
    let output = capture(
        &photo,
        "lambert",
        &dir.path().join("cap"),
        &["--size", "2048"],
    )
    .env("PHOTOMAT_MEMORY_LIMIT", "1G")
    .output()
    .unwrap();
    let err = stderr(&output);
    assert!(
        err.contains("--size 2048 needs about 8.5 GB") && err.contains("use --size 512"),
        "{err}"
    );
    assert!(
        !dir.path().join("cap").exists(),
        "nothing is written before the check"
    );
    let sample = photomat()
        .args([
            "sample",
            "--count",
            "1",
            "--size",
            "4096",
            "--out",
            path(&dir.path().join("s")),
        ])
        .env("PHOTOMAT_MEMORY_LIMIT", "6G")
        .output()
        .unwrap();
    let err = stderr(&sample);
    assert!(
        err.contains("--size 4096 needs about") && err.contains("or less"),
        "{err}"
    );
    // Flags have upper bounds: a batch of a hundred million is refused by the parser.
    let batch = photomat()
        .args([
            "train-gan",
            "--data",
            "d",
            "--out",
            path(&dir.path().join("r")),
        ])
        .args(["--steps", "1", "--batch", "100000000"])
        .output()
        .unwrap();
    assert_eq!(batch.status.code(), Some(2), "{}", stderr(&batch));
}

#[test]
fn an_interrupted_capture_says_on_stderr_that_nothing_was_written() {
    let dir = tempfile::tempdir().unwrap();
    let photo = photo(dir.path());
    let out = dir.path().join("cap");
    let child = capture(&photo, "lambert", &out, &["--steps", "100000"])
        .spawn()
        .unwrap();
    // The first steps have run once the staging folder exists.
    let staging = dir.path().join(".cap.photomat-new");
    let deadline = Instant::now() + Duration::from_secs(120);
    while !staging.exists() {
        assert!(Instant::now() < deadline, "the capture did not start");
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_millis(500));
    // SAFETY: kill(2) on the child's PID, which stays its own until it is waited for below.
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGINT) }, 0);
    let output = child.wait_with_output().unwrap();
    assert_eq!(output.status.code(), Some(130), "{}", stderr(&output));
    assert!(
        stderr(&output).contains("interrupted: nothing was written"),
        "{}",
        stderr(&output)
    );
    assert!(!out.exists());
}
