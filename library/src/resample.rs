//! Resampling of planar texture images: repeating a periodic texture to a square, halving by
//! 2×2 box means, and bilinear resizing with wrap-around (textures of a material tile, so
//! every filter here treats the image as periodic).

use photomat_core::image_io::PlanarImage;

/// `image` repeated along its shorter side to a square (a `w × h` texture with `w = k·h` for
/// an integer `k` tiles into `w × w` exactly); `None` when the sides are not whole multiples.
pub fn tile_to_square(image: &PlanarImage) -> Option<PlanarImage> {
    let (w, h) = (image.width, image.height);
    let side = w.max(h);
    if !side.is_multiple_of(w.min(h)) {
        return None;
    }
    let mut data = vec![0.0f32; image.channels * side * side];
    for c in 0..image.channels {
        for r in 0..side {
            for col in 0..side {
                data[(c * side + r) * side + col] = image.get(c, r % h, col % w);
            }
        }
    }
    Some(PlanarImage {
        channels: image.channels,
        height: side,
        width: side,
        data,
    })
}

/// `image` (even sides) halved by 2×2 box means.
pub fn halve(image: &PlanarImage) -> PlanarImage {
    let (w, h) = (image.width / 2, image.height / 2);
    let mut data = vec![0.0f32; image.channels * w * h];
    for c in 0..image.channels {
        for r in 0..h {
            for col in 0..w {
                let sum = image.get(c, 2 * r, 2 * col)
                    + image.get(c, 2 * r, 2 * col + 1)
                    + image.get(c, 2 * r + 1, 2 * col)
                    + image.get(c, 2 * r + 1, 2 * col + 1);
                data[(c * h + r) * w + col] = 0.25 * sum;
            }
        }
    }
    PlanarImage {
        channels: image.channels,
        height: h,
        width: w,
        data,
    }
}

/// `image` resized to `width × height` by bilinear interpolation between texel centres,
/// wrapping around (a periodic texture); first halved while it is at least twice as large, so
/// that shrinking averages instead of skipping texels.
pub fn resize(image: &PlanarImage, width: usize, height: usize) -> PlanarImage {
    let mut image = image.clone();
    while image.width >= 2 * width
        && image.height >= 2 * height
        && image.width.is_multiple_of(2)
        && image.height.is_multiple_of(2)
    {
        image = halve(&image);
    }
    if image.width == width && image.height == height {
        return image;
    }
    let (sx, sy) = (
        image.width as f64 / width as f64,
        image.height as f64 / height as f64,
    );
    let mut data = vec![0.0f32; image.channels * width * height];
    for c in 0..image.channels {
        for r in 0..height {
            // Continuous coordinates, texel centres at +½ ([`PlanarImage::sample_periodic`]).
            let y = (r as f64 + 0.5) * sy;
            for col in 0..width {
                let x = (col as f64 + 0.5) * sx;
                data[(c * height + r) * width + col] = image.sample_periodic(c, y, x);
            }
        }
    }
    PlanarImage {
        channels: image.channels,
        height,
        width,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiling_repeats_the_short_side_and_halving_averages() {
        let strip = PlanarImage::new(1, 1, 2, vec![1.0, 3.0]).unwrap();
        let square = tile_to_square(&strip).unwrap();
        assert_eq!(square.data, [1.0, 3.0, 1.0, 3.0]);
        assert_eq!(halve(&square).data, [2.0]);
        assert!(tile_to_square(&PlanarImage::filled(1, 2, 3, 0.0)).is_none());
    }

    #[test]
    fn resizing_keeps_constants_and_the_mean_of_a_periodic_ramp() {
        let constant = PlanarImage::filled(2, 8, 8, 0.25);
        let up = resize(&constant, 12, 12);
        assert!(up.data.iter().all(|v| (v - 0.25).abs() < 1e-6));
        let ramp = PlanarImage::new(1, 1, 4, vec![0.0, 1.0, 2.0, 3.0]).unwrap();
        let down = resize(&ramp, 2, 1);
        assert_eq!(down.data, [0.5, 2.5]);
    }
}
