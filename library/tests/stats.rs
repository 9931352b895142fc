//! The library's map statistics as `photomat eval-gan --library` compares them: a set of
//! materials with flat normals is far from the library's relief, one with the library's own
//! kind of relief is near, and box-filtering to the compared side keeps a smooth material's
//! statistics.

use photomat_brdfs as _;
use photomat_core::map_distribution::{StatisticDistance, compare, material_stats};
use photomat_library::index::MATERIALS_DIR;
use photomat_library::material::MaterialFolders;
use photomat_library::split::Split;
use photomat_library::stats::split_stats;
use photomat_library::testing::tiny_library;

fn row<'a>(rows: &'a [StatisticDistance], statistic: &str) -> &'a StatisticDistance {
    rows.iter()
        .find(|r| r.statistic == statistic)
        .unwrap_or_else(|| panic!("no row '{statistic}' in {rows:?}"))
}

#[test]
fn flat_normals_are_far_from_the_librarys_relief_and_its_own_kind_of_relief_is_near() {
    let dir = tempfile::tempdir().unwrap();
    let library = tiny_library(dir.path(), 16, 64);
    let reference = split_stats(&library, Split::Train, 8, 64).unwrap();
    let validation = split_stats(&library, Split::Validation, 4, 64).unwrap();
    assert_eq!((reference.len(), validation.len()), (8, 4));

    // The validation materials again, with their height zeroed: same colours, flat normals.
    let index = photomat_library::index::LibraryIndex::load(&library).unwrap();
    let flat: Vec<_> = index
        .split(Split::Validation)
        .iter()
        .map(|entry| {
            let dir = library.join(MATERIALS_DIR).join(&entry.id);
            let mut loaded = MaterialFolders::of(&dir).load_height().unwrap();
            let height = loaded.maps.get("height").unwrap().zeros_like().unwrap();
            loaded.maps.insert("height", height);
            material_stats(&loaded.brdf, &loaded.maps).unwrap()
        })
        .collect();

    let near = compare(&validation, &reference);
    let far = compare(&flat, &reference);
    for statistic in ["normal angle rms (deg)", "normal tilt per texel (deg)"] {
        let (n, f) = (row(&near, statistic), row(&far, statistic));
        assert!(
            f.median < 1e-3,
            "{statistic}: flat normals have median {}",
            f.median
        );
        assert!(n.reference_median > 2.0, "{statistic}: {n:?}");
        assert!(
            f.wasserstein > 2.0 * n.wasserstein && f.wasserstein > 0.5 * n.reference_median,
            "{statistic}: flat {f:?} against relief {n:?}"
        );
    }
    // Colour is the same in both sets: the flat set is as near in diffuse as the true one.
    let (n, f) = (
        row(&near, "diffuse mean (linear)"),
        row(&far, "diffuse mean (linear)"),
    );
    assert!((n.wasserstein - f.wasserstein).abs() < 1e-6, "{n:?} {f:?}");
    // A set compared with itself is at distance zero in every statistic.
    assert!(
        compare(&reference, &reference)
            .iter()
            .all(|r| r.wasserstein < 1e-12)
    );
}

#[test]
fn box_filtering_to_the_compared_side_keeps_a_smooth_materials_statistics() {
    let dir = tempfile::tempdir().unwrap();
    let library = tiny_library(dir.path(), 4, 128);
    let full = split_stats(&library, Split::Train, 2, 128).unwrap();
    let half = split_stats(&library, Split::Train, 2, 64).unwrap();
    for (a, b) in full.iter().zip(&half) {
        // Waves of at most 4 periods per side lose under 2 % of their slope to a 2×2 box.
        let (a_rms, b_rms) = (a.normal_rms_deg.unwrap(), b.normal_rms_deg.unwrap());
        assert!((a_rms - b_rms).abs() < 0.03 * a_rms, "{a_rms} vs {b_rms}");
        let (ad, bd) = (a.diffuse.unwrap(), b.diffuse.unwrap());
        assert!((ad.0 - bd.0).abs() < 1e-3, "{ad:?} vs {bd:?}");
    }
}
