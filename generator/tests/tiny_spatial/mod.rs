//! The tiny spatial G shared by the tests of the spatial generator (`spatial.rs`), its
//! periodic waves (`waves.rs`) and its training on patches (`train_spatial.rs`).

use photomat_generator::{GeneratorConfig, SpatialConfig};

/// 32² training size (cell of 8 texels), 8 channels per block, w of 16, F of 8 channels,
/// local latents of 4 channels mapped by 2 layers; no texel size, no waves.
pub fn tiny_spatial_config() -> GeneratorConfig {
    GeneratorConfig {
        resolution: 32,
        channel_multiplier: 1.0 / 64.0,
        latent_dim: 16,
        feature_channels: 8,
        relight_hidden: 8,
        tileable: true,
        spatial: Some(SpatialConfig {
            local_dim: 4,
            layers: 2,
            ..SpatialConfig::default()
        }),
        ..Default::default()
    }
}

/// `config`'s spatial options, changed by `change` (the config must be spatial).
pub fn with_spatial(
    mut config: GeneratorConfig,
    change: impl FnOnce(&mut SpatialConfig),
) -> GeneratorConfig {
    change(config.spatial.as_mut().expect("a spatial config"));
    config
}
