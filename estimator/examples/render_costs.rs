//! The trade study's cost axis alone: flash render and render + gradient time per megatexel of
//! each model in a list, timed together in interleaved rounds
//! ([`photomat_estimator::trade::cost::render_costs`]), without training any estimator. For
//! placing a new model beside the ones `photomat trade` measured, as ratios to the first.
//!
//! ```text
//! cargo run --release -p photomat-estimator --example render_costs -- "lambert,blinn_phong,ggx"
//! ```

use anyhow::Context;
use photomat_brdfs as _; // link the built-in BRDF plugins
use photomat_core::{Brdf, lookup, plugin_spec::split_list};
use photomat_estimator::trade::cost::{BENCH_SIDE, REPEATS, render_costs};

fn main() -> anyhow::Result<()> {
    let list = std::env::args()
        .nth(1)
        .context("usage: render_costs \"SPEC,SPEC,…\"")?;
    let brdfs: Vec<Brdf> = split_list(&list)?
        .iter()
        .map(|s| lookup(s))
        .collect::<Result<_, _>>()?;
    let costs = render_costs(&brdfs, 1)?;
    println!(
        "{BENCH_SIDE}² random maps, fastest of {REPEATS} interleaved rounds, f32, ratio to {}",
        brdfs[0].name()
    );
    println!("| model | n | render ms/Mtexel | render+grad ms/Mtexel | ratio | ratio with grad |");
    println!("|---|---|---|---|---|---|");
    for (brdf, cost) in brdfs.iter().zip(&costs) {
        println!(
            "| `{}` | {} | {:.1} | {:.1} | {:.2} | {:.2} |",
            brdf.name(),
            brdf.channels(),
            cost.eval_ms_per_megatexel,
            cost.eval_grad_ms_per_megatexel,
            cost.eval_ms_per_megatexel / costs[0].eval_ms_per_megatexel,
            cost.eval_grad_ms_per_megatexel / costs[0].eval_grad_ms_per_megatexel,
        );
    }
    Ok(())
}
