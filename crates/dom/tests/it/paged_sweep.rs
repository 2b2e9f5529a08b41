//! The sweeps with their per-direction work paged: for grids whose sides are not multiples
//! of the block, every closure, angular sets with and without coarse storage, a sky at
//! the boundary and a source that varies per cell and direction, a sweep whose work lives
//! in a pool of the fewest pages allowed and a few more (backed by a file) gives the
//! in-memory sweep's fluence and outflow bit for bit — and really went through the file
//! (written only, when the sweep fills the source itself); whole solves (with DSA and
//! Anderson mixing) give the same fluence, in-scattered radiance and residuals; a pool
//! below the working set is refused before anything runs.

use glam::DVec3;
use lucent_core::Stopping;
use lucent_dom::angular::Ordinates;
use lucent_dom::{
    Closure, DomBoundary, DomProblem, DomSettings, PagedWork, SourceIteration, solve,
};
use lucent_grid::GridGeometry;
use lucent_optics::{Phase, SphericalQuadrature};
use lucent_paging::Eviction;
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

fn paged(settings: DomSettings, pages: usize, page_bytes: u64, nru: bool) -> DomSettings {
    DomSettings {
        paged_work: Some(PagedWork {
            pool_bytes: pages as u64 * page_bytes,
            eviction: if nru { Eviction::Nru } else { Eviction::Lru },
        }),
        ..settings
    }
}

fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
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
        extra in 0usize..5,
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
        let expected = in_memory.sweep_only().unwrap();
        let pages = SourceIteration::min_work_pages() + extra;
        let settings = paged(settings, pages, in_memory.work_page_bytes(), nru);
        let mut out_of_core = SourceIteration::new(&problem, &ordinates, &settings).unwrap();
        let got = out_of_core.sweep_only().unwrap();
        prop_assert!(same_bits(&got.fluence, &expected.fluence), "fluence differs");
        prop_assert_eq!(got.outflow_power.to_bits(), expected.outflow_power.to_bits());
        // More pages than slots: pages went through the file. With interpolated sources
        // the source is written into the pages first and read back by the sweep;
        // otherwise the sweep fills each block's source itself and reads nothing.
        let stats = got.pager.unwrap();
        let total = (0..8).filter(|&o| !ordinates.octant(o).is_empty()).count()
            * dims.iter().map(|d| d.div_ceil(block)).product::<usize>();
        if total > pages {
            prop_assert!(stats.evictions > 0, "{:?}", stats);
            prop_assert_eq!(stats.bytes_read > 0, ordinates.interpolation().is_some(), "{:?}", stats);
        }
    }

    #[test]
    fn a_paged_solve_has_the_in_memory_bits(
        dims in proptest::array::uniform3(3usize..11),
        block in prop_oneof![Just(2usize), Just(4)],
        coarse_storage in any::<bool>(),
        anderson in prop_oneof![Just(0usize), Just(2)],
        extra in 0usize..3,
    ) {
        // The whole source iteration (sweeps, scattering products from the pages, DSA,
        // Anderson mixing): fluence, in-scattered radiance and residuals to the bit.
        let ordinates = Ordinates::new(
            SphericalQuadrature::level_symmetric(4).unwrap(),
            coarse_storage.then(|| SphericalQuadrature::octahedral(0).unwrap()),
            Phase::henyey_greenstein(0.6).unwrap(),
        )
        .unwrap();
        let problem = problem(dims, &ordinates);
        let settings = DomSettings { block, anderson, ..DomSettings::default() };
        let stopping = Stopping { relative_tolerance: 1e-6, max_iterations: 12, ..Stopping::default() };
        let expected = solve(&problem, &ordinates, &settings, &stopping).unwrap();
        let page_bytes = SourceIteration::new(&problem, &ordinates, &settings).unwrap().work_page_bytes();
        let settings = paged(settings, SourceIteration::min_work_pages() + extra, page_bytes, false);
        let got = solve(&problem, &ordinates, &settings, &stopping).unwrap();
        prop_assert!(same_bits(&got.fluence, &expected.fluence), "fluence differs");
        prop_assert!(got.inscattered.iter().zip(&expected.inscattered).all(|(a, b)| a.to_bits() == b.to_bits()));
        prop_assert!(same_bits(&got.convergence.residuals, &expected.convergence.residuals), "{:?} {:?}", got.convergence, expected.convergence);
        prop_assert_eq!(got.convergence.stop_reason, expected.convergence.stop_reason);
    }
}

#[test]
fn a_pool_below_the_working_set_is_refused_before_the_solve() {
    let ordinates = Ordinates::new(
        SphericalQuadrature::level_symmetric(2).unwrap(),
        None,
        Phase::Isotropic,
    )
    .unwrap();
    let problem = problem([5, 4, 3], &ordinates);
    let settings = DomSettings::default();
    let page_bytes = SourceIteration::new(&problem, &ordinates, &settings)
        .unwrap()
        .work_page_bytes();
    let settings = paged(
        settings,
        SourceIteration::min_work_pages() - 1,
        page_bytes,
        false,
    );
    let result = SourceIteration::new(&problem, &ordinates, &settings).map(|_| ());
    assert!(
        matches!(result, Err(lucent_dom::DomError::Paging(ref m)) if m.contains("budget")),
        "{result:?}"
    );
}

#[test]
fn a_memory_budget_too_small_for_the_work_pages_it() {
    // Through the registry: a budget below the in-memory estimate but above everything
    // except the sweeps' work pages the work (same bits, a peak estimate within the
    // budget); a budget below the rest is refused before anything runs.
    use lucent_core::{
        Boundary, Field, Light, Medium, ParamValue, Params, Problem, SolveError, SolveOptions,
        Solver, Spectrum,
    };
    let geometry =
        GridGeometry::from_bounds([12, 11, 10], DVec3::splat(-1.0), DVec3::splat(1.0)).unwrap();
    let density =
        lucent_grid::Grid::from_fn(geometry, |p| (6.0 * (1.0 - p.length()).max(0.0)) as f32);
    let medium = Medium {
        sigma_t: vec![density],
        albedo: vec![Field::Constant(0.9)],
        phase: Phase::henyey_greenstein(0.5).unwrap(),
    };
    let lights = vec![
        Light::Directional {
            direction: DVec3::new(0.2, 0.3, -0.9).normalize(),
            irradiance: Spectrum::Grey(1.0),
        },
        Light::Sky {
            radiance: Spectrum::Grey(0.1),
        },
    ];
    let problem = Problem::new(geometry, medium, lights, Boundary::Vacuum, None).unwrap();
    let mut params = Params::default();
    params.0.insert("block".into(), ParamValue::Int(4));
    params.0.insert("order".into(), ParamValue::Int(4));
    let solver = lucent_dom::DomSolver::from_params(&params).unwrap();
    let in_memory = solver.solve(&problem, &SolveOptions::default()).unwrap();
    let dense = in_memory.report.peak_memory_bytes;
    // S4: 24 directions of f64 per cell.
    let work = geometry.voxel_count() as u64 * 24 * 8;
    let budget = dense - work / 2;
    let options = SolveOptions {
        memory_budget: budget,
        ..SolveOptions::default()
    };
    let paged = solver.solve(&problem, &options).unwrap();
    assert!(
        paged.report.peak_memory_bytes <= budget,
        "{:?}",
        paged.report
    );
    assert_eq!(paged.report.iterations, in_memory.report.iterations);
    let same = paged
        .fluence(0)
        .data()
        .iter()
        .zip(in_memory.fluence(0).data());
    assert!(same.clone().all(|(a, b)| a.to_bits() == b.to_bits()));
    let tight = SolveOptions {
        memory_budget: dense - work - 1,
        ..SolveOptions::default()
    };
    assert!(matches!(
        solver.solve(&problem, &tight),
        Err(SolveError::OverBudget { .. })
    ));
}
