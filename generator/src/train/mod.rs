//! GAN training of G, M and D (PhotoMat §3–4, StyleGAN2-ADA's training loop; DESIGN §4).
//!
//! - [`adam`]: Adam over named variables with checkpointable state and the
//!   lazy-regularisation correction.

pub mod adam;
