//! Copies a `photomat train-gan` run folder's state without the optimisers' moments, the
//! form a run takes when it is committed to a repository to be continued elsewhere
//! (`photomat_generator::train::state::write_without_optimiser`; models/training/).
//!
//! `cargo run --release -p photomat-generator --example portable_checkpoint -- RUN OUT`
//!
//! `photomat train-gan --out OUT --resume --data DATA --steps N` then continues it: the
//! networks and counters exactly, Adam from zero moments.

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [run, out] = args.as_slice() else {
        anyhow::bail!("usage: portable_checkpoint RUN OUT");
    };
    let bytes = photomat_generator::train::state::write_without_optimiser(
        std::path::Path::new(run),
        std::path::Path::new(out),
    )?;
    println!(
        "{out}: the state of {run} without its optimisers ({:.1} MB)",
        bytes as f64 / 1e6
    );
    Ok(())
}
