//! The `photomat` binary: the built-in plugins plus the command line of `photomat-cli`.

fn main() -> std::process::ExitCode {
    photomat_cli::run()
}
