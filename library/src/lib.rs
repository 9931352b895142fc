//! # photomat-library
//!
//! The material library: artist-made SVBRDF maps (base colour, tangent-space normal map,
//! specular, gloss and height maps of photographed surfaces) imported from game-data packages
//! into photomat material folders, with their provenance and licences, split into training,
//! validation and test materials; and the flash photos rendered from them, the data every
//! learned part of photomat trains and is validated on (docs/data.md).
//!
//! - [`tree`]: a package's files as one tree, zip and pk3 archives opened as folders;
//! - [`decode`]: PNG, JPEG, TGA and DDS textures decoded under the pixel limit;
//! - [`pairing`]: which files make one material, from the packages' material files or by
//!   file-name suffixes;
//! - [`normals`]: normal maps in photomat's convention, the green channel decided per map;
//! - [`relief`]: heights integrated from normals (periodic least squares) and their map;
//! - [`resample`]: squaring, halving and resizing periodic textures;
//! - [`convert`]: one texture set → a library material's maps, or why not;
//! - [`licence`]: a package's Debian copyright file, a licence per file;
//! - [`package`]: what a source folder is (package, version) and the held-back packages;
//! - [`filter`]: what is not a surface, by path, and near-duplicate clusters;
//! - [`split`]: training, validation and test materials, by cluster;
//! - [`material`]: a library material's two folders (`ggx`, `height`) and its provenance;
//! - [`index`]: `library.json`, every material with its split, package and licences;
//! - [`sheet`]: the contact sheet of a sample of the library;
//! - [`import`]: the importer behind `photomat library import`;
//! - [`photos`]: a split of the library as the simulator's material family, seen at random
//!   scales, offsets and orientations, mixed, for flash photos of it;
//! - [`stats`]: the statistics of a split's true maps, what sampled materials are compared with;
//! - [`testing`]: a small synthetic library for the tests of what reads libraries.

pub mod convert;
pub mod decode;
pub mod filter;
pub mod import;
pub mod index;
pub mod licence;
pub mod material;
pub mod normals;
pub mod package;
pub mod pairing;
pub mod photos;
pub mod relief;
pub mod resample;
pub mod sheet;
pub mod split;
pub mod stats;
pub mod testing;
pub mod tree;
