//! VGG19 features for the Gram loss, from torchvision-compatible weights in a safetensors file
//! (`docs/neural-models.md`, "Gram loss": VGG19 with max-pools replaced by average pools,
//! features after pool1 … pool5, ImageNet-normalised input).
//!
//! Network: torchvision's `vgg19().features` (Simonyan & Zisserman 2015, configuration E):
//! 3×3 convs with zero padding 1, each followed by ReLU, in five stages of 2, 2, 4, 4, 4
//! convs; every `MaxPool2d(2)` is replaced by a 2×2 average pool (Gatys et al. 2015 found
//! average pooling gives smoother gradients for texture synthesis). Input: display-encoded
//! RGB in [0, 1], normalised by ImageNet's mean (0.485, 0.456, 0.406) and standard deviation
//! (0.229, 0.224, 0.225) as torchvision's models expect.
//!
//! # The weights file
//! Pretrained weights cannot be downloaded on the build machines; users bring their own. The
//! file holds, in any float dtype, the 16 convs' `weight` (C_out, C_in, 3, 3) and `bias`
//! (C_out) under torchvision's indices of `vgg19().features`:
//!
//! ```text
//! features.{0,2,5,7,10,12,14,16,19,21,23,25,28,30,32,34}.{weight,bias}
//! ```
//!
//! (the names without the `features.` prefix are accepted too; other tensors, e.g. the
//! classifier's, are ignored). To write it from PyTorch with torchvision and safetensors
//! installed:
//!
//! ```text
//! import torchvision
//! from safetensors.torch import save_file
//! vgg = torchvision.models.vgg19(weights=torchvision.models.VGG19_Weights.IMAGENET1K_V1)
//! state = {f"features.{k}": v.contiguous() for k, v in vgg.features.state_dict().items()}
//! save_file(state, "vgg19.safetensors")   # 80 MB of float32
//! ```
//!
//! The loader checks names and shapes but not the widths' values: any channel widths that are
//! consistent from layer to layer load (VGG19's are 64, 128, 256, 512, 512), so a narrow file
//! of the same layout works too. Errors name the file and the missing or mis-shaped tensor.

use std::path::Path;

use candle_core::safetensors::MmapedSafetensors;
use candle_core::{DType, Device};
use photomat_core::{Error, Result};
use photomat_kernels::Conv2dSpec;

use super::extractor::{ConvLayer, PooledConvStack};

/// torchvision indices of the convs in `vgg19().features`, per stage (pool1 … pool5 follow).
pub const VGG19_CONV_INDICES: [&[usize]; 5] = [
    &[0, 2],
    &[5, 7],
    &[10, 12, 14, 16],
    &[19, 21, 23, 25],
    &[28, 30, 32, 34],
];

/// ImageNet mean of torchvision's normalisation.
pub const IMAGENET_MEAN: [f64; 3] = [0.485, 0.456, 0.406];
/// ImageNet standard deviation of torchvision's normalisation.
pub const IMAGENET_STD: [f64; 3] = [0.229, 0.224, 0.225];

/// Loads VGG19's convs from the safetensors file `path` (see the module docs) into an
/// average-pooled feature stack with weights in `dtype` on `device`.
pub fn load_vgg19(path: &Path, dtype: DType, device: &Device) -> Result<PooledConvStack> {
    // SAFETY: the file is mapped read-only while the tensors are copied out of it; modifying
    // it concurrently is outside this API's contract (as for candle's own loaders).
    let file = unsafe { MmapedSafetensors::new(path) }
        .map_err(|e| Error::file(path, format!("cannot read VGG19 weights: {e}")))?;
    let names: std::collections::HashSet<String> =
        file.tensors().into_iter().map(|(n, _)| n).collect();
    let find = |index: usize, what: &str| -> Result<String> {
        let full = format!("features.{index}.{what}");
        let bare = format!("{index}.{what}");
        if names.contains(&full) {
            Ok(full)
        } else if names.contains(&bare) {
            Ok(bare)
        } else {
            Err(Error::file(
                path,
                format!(
                    "VGG19 tensor `{full}` is missing (expected torchvision's \
                     vgg19().features names, see `photomat train-estimator --help`)"
                ),
            ))
        }
    };
    let mut c_in = 3;
    let mut stages = Vec::with_capacity(VGG19_CONV_INDICES.len());
    for indices in VGG19_CONV_INDICES {
        let mut stage = Vec::with_capacity(indices.len());
        for &i in indices {
            let (wn, bn) = (find(i, "weight")?, find(i, "bias")?);
            let load = |name: &str| {
                file.load(name, device)
                    .and_then(|t| t.to_dtype(dtype))
                    .map_err(|e| Error::file(path, format!("cannot load `{name}`: {e}")))
            };
            let (weight, bias) = (load(&wn)?, load(&bn)?);
            let c_out = match *weight.dims() {
                [co, ci, 3, 3] if ci == c_in => co,
                _ => {
                    return Err(Error::file(
                        path,
                        format!(
                            "VGG19 tensor `{wn}` has shape {:?}, expected (C_out, {c_in}, 3, 3) \
                             (its input width must be the previous layer's output width)",
                            weight.dims()
                        ),
                    ));
                }
            };
            if bias.dims() != [c_out] {
                return Err(Error::file(
                    path,
                    format!(
                        "VGG19 tensor `{bn}` has shape {:?}, expected ({c_out})",
                        bias.dims()
                    ),
                ));
            }
            stage.push(ConvLayer { weight, bias });
            c_in = c_out;
        }
        stages.push(stage);
    }
    Ok(PooledConvStack::new(
        stages,
        IMAGENET_MEAN,
        IMAGENET_STD,
        Conv2dSpec::zeros(1, 1),
        format!("vgg19 ({})", path.display()),
    )?)
}
