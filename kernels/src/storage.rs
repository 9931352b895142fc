//! The CPU operands of this crate's custom ops: the contiguous slice of a candle storage and
//! the check of its shape, each failing with an error that names the op.

use candle_core::{Layout, Result, Shape, bail};

/// The contiguous slice of a storage, or an error naming the op.
pub(crate) fn contiguous<'a, T>(v: &'a [T], layout: &Layout, op: &str) -> Result<&'a [T]> {
    match layout.contiguous_offsets() {
        Some((start, end)) => Ok(&v[start..end]),
        None => bail!("{op}: expected a contiguous tensor"),
    }
}

/// Checks a CPU operand's shape against the one its op expects.
pub(crate) fn expect_shape(layout: &Layout, shape: &Shape, op: &str, what: &str) -> Result<()> {
    if layout.shape() != shape {
        bail!(
            "{op}: {what} has shape {:?}, expected {shape:?}",
            layout.shape()
        );
    }
    Ok(())
}
