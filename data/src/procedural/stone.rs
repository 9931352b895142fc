//! Natural stone: polished marble with veins, granite with mineral grains, and rough
//! sedimentary stone (sandstone, limestone, slate, basalt) with bedding layers and pits.
//!
//! Imitates stone slabs and floor tiles. Marble is a clouded fBm body crossed by veins: thin
//! bands around the zero set of a domain-warped fBm (where a smooth random field changes
//! sign, the band is a winding line), polished to a near mirror. Granite is a mosaic of
//! mineral grains: cells of periodic Worley noise, each grain a mineral drawn from the
//! stone's composition (feldspar, quartz, mica), polished, honed or flamed (flaming raises
//! quartz and plucks mica, so only flamed granite has grain relief). Rough stone is a fBm
//! relief with bedding bands and pitted pores. Every stone is a dielectric, grey F0 0.03-0.05
//! (calcite n ≈ 1.6 gives 0.053, quartz 0.045).
//!
//! Maps for `height(ggx, scale=relief)`: diffuse, specular, roughness, height.
//! Per seed: the kind (a third each), the stone's palette within the kind, vein width and
//! contrast, grain size, finish, layer count, relief strength, orientation (one of the 8
//! symmetries of the square).

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::PatternFamily;
use super::cellular::PeriodicCells;
use super::common::{GgxTexel, Pattern, Symmetry, counts, jitter, mix, scale, smoothstep, srgb};
use super::noise::PeriodicNoise;

/// Configuration of the stone family; every field has a documented default.
#[derive(Debug, Clone)]
pub struct Stone {
    /// World-space height of the height map's full range (default 0.01: rough stone has
    /// millimetre relief on a 10 cm swatch; polished kinds use a sliver of the range).
    pub relief: f64,
    /// Mineral grains per unit along each side of granite, least and most (default 24, 56).
    pub grains: (u32, u32),
}

impl Default for Stone {
    fn default() -> Self {
        Self {
            relief: 0.01,
            grains: (24, 56),
        }
    }
}

/// sRGB body and vein colours of marbles: Carrara, Calacatta, Nero Marquina, verde, rosso.
const MARBLES: [([f64; 3], [f64; 3]); 5] = [
    ([0.90, 0.90, 0.88], [0.42, 0.44, 0.47]),
    ([0.93, 0.90, 0.84], [0.58, 0.47, 0.33]),
    ([0.09, 0.09, 0.10], [0.86, 0.86, 0.85]),
    ([0.22, 0.36, 0.29], [0.80, 0.84, 0.80]),
    ([0.58, 0.27, 0.24], [0.88, 0.82, 0.76]),
];

/// A granite's composition.
struct Composition {
    /// sRGB colours of the two major minerals.
    majors: [[f64; 3]; 2],
    /// Probability that a grain is of the first.
    first: f64,
    /// sRGB colour of the small specks of a third mineral.
    speck: [f64; 3],
    /// Fraction of speck cells that hold one.
    specks: f64,
}

/// Granites: grey (white feldspar, grey quartz, black mica), pink (pink feldspar), black
/// galaxy (bronze specks in black gabbro), Baltic brown.
const GRANITES: [Composition; 4] = [
    Composition {
        majors: [[0.86, 0.85, 0.83], [0.56, 0.56, 0.58]],
        first: 0.55,
        speck: [0.08, 0.08, 0.09],
        specks: 0.3,
    },
    Composition {
        majors: [[0.80, 0.56, 0.50], [0.62, 0.61, 0.60]],
        first: 0.6,
        speck: [0.09, 0.08, 0.08],
        specks: 0.25,
    },
    Composition {
        majors: [[0.06, 0.06, 0.07], [0.18, 0.18, 0.19]],
        first: 0.85,
        speck: [0.62, 0.52, 0.36],
        specks: 0.12,
    },
    Composition {
        majors: [[0.50, 0.33, 0.23], [0.10, 0.09, 0.09]],
        first: 0.7,
        speck: [0.55, 0.55, 0.55],
        specks: 0.15,
    },
];

/// sRGB colours of rough stones: sandstone, red sandstone, limestone, slate, basalt.
const ROUGH: [[f64; 3]; 5] = [
    [0.78, 0.66, 0.50],
    [0.66, 0.41, 0.31],
    [0.85, 0.82, 0.74],
    [0.36, 0.38, 0.41],
    [0.24, 0.24, 0.25],
];

/// What kind of stone a member is, with its kind-specific parameters.
enum Kind {
    Marble {
        body: [f64; 3],
        vein: [f64; 3],
        /// Half-width of a vein in fBm units.
        width: f64,
        /// Vein opacity.
        contrast: f64,
    },
    Granite {
        majors: [[f64; 3]; 2],
        first: f64,
        speck: [f64; 3],
        specks: f64,
        cells: PeriodicCells,
        speck_cells: PeriodicCells,
        grains: u32,
        /// 0 polished, 1 flamed.
        flamed: f64,
    },
    Rough {
        colour: [f64; 3],
        layers: u32,
        cells: PeriodicCells,
        pits: u32,
    },
}

/// One member of the family.
pub(crate) struct Slab {
    kind: Kind,
    symmetry: Symmetry,
    /// Base roughness of the finish.
    finish: f64,
    f0: f64,
    noise: [PeriodicNoise; 4],
}

impl PatternFamily for Stone {
    const NAME: &'static str = "stone";
    type Member = Slab;

    fn brdf(&self) -> String {
        format!("height(ggx, scale={})", self.relief)
    }

    fn member(&self, seed: u64) -> Slab {
        let mut rng = StdRng::seed_from_u64(seed);
        let noise = [(); 4].map(|_| PeriodicNoise::new(rng.random()));
        let (kind, finish) = match rng.random_range(0..3) {
            0 => {
                let (body, vein) = MARBLES[rng.random_range(0..MARBLES.len())];
                let kind = Kind::Marble {
                    body: srgb(jitter(&mut rng, body, 0.05)),
                    vein: srgb(jitter(&mut rng, vein, 0.1)),
                    width: rng.random_range(0.012..0.04),
                    contrast: rng.random_range(0.5..0.95),
                };
                (kind, rng.random_range(0.05..0.16))
            }
            1 => {
                let c = &GRANITES[rng.random_range(0..GRANITES.len())];
                let flamed = if rng.random_bool(0.3) { 1.0 } else { 0.0 };
                let kind = Kind::Granite {
                    majors: c.majors.map(|m| srgb(jitter(&mut rng, m, 0.06))),
                    first: c.first,
                    speck: srgb(jitter(&mut rng, c.speck, 0.06)),
                    specks: c.specks,
                    cells: PeriodicCells::new(rng.random(), 1.0),
                    speck_cells: PeriodicCells::new(rng.random(), 1.0),
                    grains: rng.random_range(counts(self.grains, 1)),
                    flamed,
                };
                let finish = if flamed > 0.0 {
                    rng.random_range(0.6..0.8)
                } else if rng.random_bool(0.5) {
                    rng.random_range(0.07..0.15) // polished
                } else {
                    rng.random_range(0.3..0.5) // honed
                };
                (kind, finish)
            }
            _ => {
                let colour = ROUGH[rng.random_range(0..ROUGH.len())];
                let kind = Kind::Rough {
                    colour: srgb(jitter(&mut rng, colour, 0.06)),
                    layers: rng.random_range(2..9),
                    cells: PeriodicCells::new(rng.random(), 1.0),
                    pits: rng.random_range(16..40),
                };
                (kind, rng.random_range(0.7..0.92))
            }
        };
        Slab {
            kind,
            symmetry: Symmetry::random(&mut rng),
            finish,
            f0: rng.random_range(0.035..0.05),
            noise,
        }
    }
}

impl Pattern for Slab {
    type Texel = GgxTexel;

    fn sample(&self, u: f64, v: f64) -> GgxTexel {
        let (x, y) = self.symmetry.apply(u, v);
        let [n0, n1, n2, n3] = &self.noise;
        let cloud = n0.fbm(x, y, 3, 5);
        let (diffuse, roughness, height) = match &self.kind {
            Kind::Marble {
                body,
                vein,
                width,
                contrast,
            } => {
                // Veins: the zero set of fBm over coordinates warped by two more fBms.
                let (wx, wy) = (x + 0.3 * n1.fbm(x, y, 2, 4), y + 0.3 * n2.fbm(x, y, 2, 4));
                let main = 1.0 - smoothstep(0.0, *width, n3.fbm(wx, wy, 2, 5).abs());
                let fine = 1.0 - smoothstep(0.0, 0.4 * width, n3.fbm(wx, wy, 5, 3).abs());
                let veins = (main + 0.5 * fine).min(1.0); // crossing veins are no more than opaque
                let body = scale(*body, 1.0 + 0.15 * cloud);
                let diffuse = mix(body, *vein, contrast * veins);
                // Polished: a hair rougher and lower along veins (softer filling minerals).
                (
                    diffuse,
                    self.finish + 0.05 * veins,
                    0.5 + 0.02 * cloud - 0.04 * veins,
                )
            }
            Kind::Granite {
                majors,
                first,
                speck,
                specks,
                cells,
                speck_cells,
                grains,
                flamed,
            } => {
                // Irregular grains: cells over coordinates warped by a third of a grain.
                let w = 0.35 / *grains as f64;
                let (wx, wy) = (
                    x + w * n1.fbm(x, y, 2 * grains, 2),
                    y + w * n2.fbm(x, y, 2 * grains, 2),
                );
                let grain = cells.sample(wx, wy, *grains);
                let mineral = usize::from(grain.random(0) >= *first);
                // Specks: round grains of the third mineral in a finer, sparser layer.
                let fine = speck_cells.sample(wx, wy, 5 * grains / 2);
                let in_speck = fine.random(0) < *specks && fine.f1 < 0.45;
                let texture = n3.fbm(x, y, 4 * grains, 2); // inside a crystal: cleavage, inclusions
                let (colour, shade, relief, id) = if in_speck {
                    (*speck, 1.0, 0.3, fine.random(1))
                } else {
                    // Flaming: quartz (the second major) proud, feldspar lower, mica plucked.
                    let relief = [0.6, 0.8][mineral];
                    (
                        majors[mineral],
                        1.0 + 0.12 * texture,
                        relief,
                        grain.random(1),
                    )
                };
                let diffuse = scale(colour, shade * (0.85 + 0.3 * id));
                let rim = 1.0 - smoothstep(0.0, 0.08, grain.border);
                let height = 0.5 + flamed * (relief + 0.1 * id - 0.55 - 0.15 * rim);
                (
                    diffuse,
                    self.finish + 0.03 * texture + 0.1 * flamed * rim,
                    height,
                )
            }
            Kind::Rough {
                colour,
                layers,
                cells,
                pits,
            } => {
                // Bedding: bands along x, wobbled so they are never straight.
                let band =
                    (std::f64::consts::TAU * (*layers as f64 * y + 0.5 * n1.fbm(x, y, 2, 3))).sin();
                let grit = n2.fbm(x, y, 64, 2);
                let pit_cell = cells.sample(x, y, *pits);
                let pit = if pit_cell.random(0) < 0.35 {
                    1.0 - smoothstep(0.0, 0.3, pit_cell.f1)
                } else {
                    0.0
                };
                let shade = (1.0 + 0.1 * band + 0.15 * cloud + 0.1 * grit) * (1.0 - 0.35 * pit);
                let bumps = n3.fbm(x, y, 6, 5);
                let height = 0.55 + 0.3 * bumps + 0.1 * grit - 0.25 * pit;
                (scale(*colour, shade), self.finish + 0.05 * grit, height)
            }
        };
        GgxTexel {
            diffuse,
            specular: [self.f0; 3],
            roughness,
            height,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::procedural::common::testing::{assert_periodic, channel_stats};

    fn kind(seed: u64) -> usize {
        match Stone::default().member(seed).kind {
            Kind::Marble { .. } => 0,
            Kind::Granite { .. } => 1,
            Kind::Rough { .. } => 2,
        }
    }

    #[test]
    fn stone_is_periodic_for_every_kind() {
        let mut seen = [false; 3];
        for seed in 0..12 {
            assert_periodic(&Stone::default().member(seed));
            seen[kind(seed)] = true;
        }
        assert_eq!(seen, [true; 3], "seeds 0..12 should cover every kind");
    }

    #[test]
    fn stone_is_a_dielectric_whose_roughness_follows_its_finish() {
        for seed in 0..12 {
            let s = channel_stats(&Stone::default().member(seed));
            assert!(
                (0.03..=0.05).contains(&s[3].1),
                "seed {seed}: F0 {:?}",
                s[3]
            );
            let r = s[6].1;
            match kind(seed) {
                0 => assert!(r < 0.25, "marble is polished: {r}"),
                2 => assert!(r > 0.6, "rough stone is rough: {r}"),
                _ => assert!((0.05..0.9).contains(&r), "granite: {r}"),
            }
        }
    }

    #[test]
    fn stone_polished_kinds_are_flatter_than_rough_stone() {
        let spread = |seed| {
            let s = channel_stats(&Stone::default().member(seed));
            s[7].2 - s[7].0
        };
        let (marble, rough) = (
            (0..12).find(|&s| kind(s) == 0),
            (0..12).find(|&s| kind(s) == 2),
        );
        let (m, r) = (spread(marble.unwrap()), spread(rough.unwrap()));
        assert!(m < 0.2 && r > 0.3 && m < r, "marble {m}, rough {r}");
    }
}
