//! The sweeps with their per-direction work paged: for grids whose sides are not multiples
//! of the block, every closure, angular sets with and without coarse storage, a sky at
//! the boundary and a source that varies per cell and direction, a sweep whose work lives
//! in a pager of a few pages (backed by a file) gives the in-memory sweep's fluence and
//! outflow bit for bit — and really went through the file (written only, when the sweep
//! fills the source itself).

use std::sync::Arc;

use glam::DVec3;
use lucent_dom::angular::Ordinates;
use lucent_dom::{Closure, DomBoundary, DomProblem, DomSettings, SourceIteration};
use lucent_grid::GridGeometry;
use lucent_optics::{Phase, SphericalQuadrature};
use lucent_paging::{Eviction, FileStore, Pager, PagerOptions};
use proptest::prelude::*;

fn problem(dims: [usize; 3], ordinates: &Ordinates) -> DomProblem {
    let geometry = GridGeometry::from_bounds(dims, DVec3::ZERO, DVec3::new(1.0, 0.8, 0.9)).unwrap();
    let n = geometry.voxel_count();
    let m = ordinates.storage().len();
    let sigma_t: Vec<f32> = (0..n)
        .map(|c| {
            let [i, j, k] = geometry.coords(c);
            let p = geometry.cell_centre(i, j, k);
            (3.0 + 2.5 * (7.0 * p.x).sin() * (4.0 * p.y + 1.0).cos() + 2.0 * p.z) as f32
        })
        .collect();
    DomProblem {
        geometry,
        sigma_s: sigma_t.iter().map(|s| 0.7 * s).collect(),
        sigma_t,
        fixed: (0..n * m)
            .map(|i| ((i * 7919) % 13) as f32 * 0.05)
            .collect(),
        boundary: DomBoundary {
            radiance: 0.4,
            reflectance: 0.0,
        },
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn a_paged_sweep_has_the_in_memory_bits(
        dims in proptest::array::uniform3(2usize..13),
        block in prop_oneof![Just(2usize), Just(3), Just(4), Just(8)],
        closure in prop_oneof![Just(Closure::Step), Just(Closure::Diamond), Just(Closure::Exponential)],
        order in prop_oneof![Just(2usize), Just(4)],
        coarse_storage in any::<bool>(),
        slots in 1u64..6,
        nru in any::<bool>(),
    ) {
        let ordinates = Ordinates::new(
            SphericalQuadrature::level_symmetric(order).unwrap(),
            coarse_storage.then(|| SphericalQuadrature::octahedral(0).unwrap()),
            Phase::henyey_greenstein(0.5).unwrap(),
        )
        .unwrap();
        let problem = problem(dims, &ordinates);
        let settings = DomSettings { closure, block, ..DomSettings::default() };
        let mut in_memory = SourceIteration::new(&problem, &ordinates, &settings).unwrap();
        let expected = in_memory.sweep_only(None).unwrap();
        let mut paged = SourceIteration::new(&problem, &ordinates, &settings).unwrap();
        let len = paged.work_page_len();
        let pager = Arc::new(
            Pager::new(
                Box::new(FileStore::create().unwrap()),
                0,
                len,
                1,
                PagerOptions {
                    budget_bytes: slots * 8 * len as u64,
                    eviction: if nru { Eviction::Nru } else { Eviction::Lru },
                    fill: 0.0f64,
                },
            )
            .unwrap(),
        );
        let pages = paged.work_pages(pager.clone()).unwrap();
        let got = paged.sweep_only(Some(&pages)).unwrap();
        let same = got.fluence.len() == expected.fluence.len()
            && got.fluence.iter().zip(&expected.fluence).all(|(a, b)| a.to_bits() == b.to_bits());
        prop_assert!(same, "fluence differs");
        prop_assert_eq!(got.outflow_power.to_bits(), expected.outflow_power.to_bits());
        // More pages than slots: pages went through the file. With coarse storage the
        // interpolated source is stored first and read back by the sweep; otherwise the
        // sweep fills each block's source itself and reads nothing.
        let stats = got.pager.unwrap();
        if pager.brick_count() as u64 > slots {
            prop_assert!(stats.bytes_written > 0 && stats.evictions > 0, "{:?}", stats);
            prop_assert_eq!(stats.bytes_read > 0, ordinates.interpolation().is_some(), "{:?}", stats);
        }
    }
}

#[test]
fn pages_of_the_wrong_length_are_refused() {
    let ordinates = Ordinates::new(
        SphericalQuadrature::level_symmetric(2).unwrap(),
        None,
        Phase::Isotropic,
    )
    .unwrap();
    let problem = problem([5, 4, 3], &ordinates);
    let settings = DomSettings::default();
    let iteration = SourceIteration::new(&problem, &ordinates, &settings).unwrap();
    let pager = Arc::new(
        Pager::new(
            Box::new(FileStore::create().unwrap()),
            0,
            iteration.work_page_len() + 1,
            1,
            PagerOptions {
                budget_bytes: 1 << 20,
                eviction: Eviction::Lru,
                fill: 0.0f64,
            },
        )
        .unwrap(),
    );
    let result = iteration.work_pages(pager);
    assert!(
        matches!(result, Err(lucent_dom::DomError::Paging(ref m)) if m.contains("pages of")),
        "{result:?}"
    );
}
