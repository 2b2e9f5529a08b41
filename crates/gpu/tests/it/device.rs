//! The GPU layer on a real adapter (lavapipe in CI): transfers, reductions against the
//! CPU's f64, limits and bad input. Without an adapter these skip with the reason, except
//! under `CI=true`, where they fail.

use lucent_gpu::{
    DeviceField, DeviceField64, GpuContext, GpuError, Reducer, Transfers, context_or_skip,
};
use rand::{Rng, SeedableRng};

#[test]
fn the_context_reports_its_adapter_and_limits() {
    let Some(context) = context_or_skip("the_context_reports_its_adapter_and_limits") else {
        return;
    };
    let text = context.describe();
    eprintln!("{text}");
    assert!(
        text.contains(&context.info().name) && text.contains("MiB"),
        "{text}"
    );
    // lucent asked for at least one 256³ f32 grid per binding and 8 storage buffers.
    assert!(context.limits().max_storage_buffer_binding_size >= 64 << 20);
    assert!(context.limits().max_storage_buffers_per_shader_stage >= 8);
}

#[test]
fn a_field_goes_up_and_comes_back_bit_for_bit() {
    let Some(context) = context_or_skip("a_field_goes_up_and_comes_back_bit_for_bit") else {
        return;
    };
    let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
    // Sizes around the workgroup and not multiples of 8.
    for len in [0usize, 1, 255, 256, 257, 1001, 77_777] {
        let values: Vec<f32> = (0..len).map(|_| rng.random_range(-1e3f32..1e3)).collect();
        let field = DeviceField::upload(&context, "values", &values, false).unwrap();
        assert_eq!(field.download(&context).unwrap(), values, "len {len}");
    }
}

/// Through kept staging in chunks (chunk sizes that do and do not divide the field, one
/// larger than it, chunks large enough to be copied by several threads): f32 and f64 fields up and back bit for bit, a wrong length and a value
/// that is not finite refused with a typed error.
#[test]
fn staged_transfers_are_bit_for_bit_across_chunks() {
    let Some(context) = context_or_skip("staged_transfers_are_bit_for_bit_across_chunks") else {
        return;
    };
    let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
    // The last chunks are copied by several threads (from 4 MiB on).
    for (len, chunk) in [
        (1000, 256),
        (1000, 4000),
        (777, 100),
        (5, 1 << 20),
        (3_000_001, 5 << 20),
    ] {
        let transfers = Transfers::with_chunk(&context, chunk).unwrap();
        let values: Vec<f32> = (0..len).map(|_| rng.random_range(-1e3..1e3)).collect();
        let field = DeviceField::zeros(&context, "f32", len).unwrap();
        field
            .write_staged(&context, &values, false, &transfers)
            .unwrap();
        let mut back = vec![0.0f32; len];
        field
            .download_into(&context, &mut back, &transfers)
            .unwrap();
        assert_eq!(back, values, "f32, {len} values in chunks of {chunk} bytes");
        let values: Vec<f64> = (0..len).map(|_| rng.random_range(-1e3..1e3)).collect();
        let field = DeviceField64::zeros(&context, "f64", len).unwrap();
        field.write_staged(&context, &values, &transfers).unwrap();
        let mut back = vec![0.0f64; len];
        field
            .download_into(&context, &mut back, &transfers)
            .unwrap();
        assert_eq!(back, values, "f64, {len} values in chunks of {chunk} bytes");
        assert_eq!(field.download(&context).unwrap(), values);
        let mut bad = values.clone();
        bad[len / 2] = f64::INFINITY;
        assert!(matches!(
            field.write_staged(&context, &bad, &transfers),
            Err(GpuError::BadInput { index, .. }) if index == len / 2
        ));
        assert!(
            field
                .write_staged(&context, &values[1..], &transfers)
                .is_err()
        );
        assert!(
            field
                .download_into(&context, &mut back[1..], &transfers)
                .is_err()
        );
    }
}

#[test]
fn reductions_match_the_cpus_f64_sums() {
    // Pairwise within 256, f64 across: relative error ≲ 8·2⁻²⁴ ≈ 5e-7 for sums of
    // non-negative values (the bound of the crate's *Precision*); 1e-6 is that with a
    // factor 2 of margin. Mixed signs are compared against Σ|x|, the scale the rounding
    // acts on. The maximum is exact.
    let Some(context) = context_or_skip("reductions_match_the_cpus_f64_sums") else {
        return;
    };
    let reducer = Reducer::new(&context).unwrap();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
    for len in [1usize, 300, 65_536, 1_000_003] {
        for signed in [false, true] {
            let values: Vec<f32> = (0..len)
                .map(|_| {
                    let v = rng.random_range(0.0f32..2.0) * 10f32.powi(rng.random_range(-3..3));
                    if signed && rng.random_bool(0.5) {
                        -v
                    } else {
                        v
                    }
                })
                .collect();
            let field = DeviceField::upload(&context, "values", &values, false).unwrap();
            let cpu_sum: f64 = values.iter().map(|&v| f64::from(v)).sum();
            let cpu_abs: f64 = values.iter().map(|&v| f64::from(v).abs()).sum();
            let cpu_sq: f64 = values.iter().map(|&v| f64::from(v) * f64::from(v)).sum();
            let cpu_max = values
                .iter()
                .fold(0.0f64, |m, &v| m.max(f64::from(v).abs()));
            let gpu_sum = reducer.sum(&context, &field).unwrap();
            let gpu_sq = reducer.sum_of_squares(&context, &field).unwrap();
            let gpu_max = reducer.max_abs(&context, &field).unwrap();
            assert!(
                (gpu_sum - cpu_sum).abs() <= 1e-6 * cpu_abs,
                "len {len}, signed {signed}: {gpu_sum} vs {cpu_sum}"
            );
            assert!(
                (gpu_sq - cpu_sq).abs() <= 1e-6 * cpu_sq,
                "len {len}: {gpu_sq} vs {cpu_sq}"
            );
            assert_eq!(gpu_max, cpu_max, "len {len}");
        }
    }
    // A running f32 sum of the same million values would be off by ~1e-4 relative: the
    // comparison above can fail.
}

#[test]
fn bad_input_and_oversized_grids_are_refused_before_allocating() {
    let Some(context) =
        context_or_skip("bad_input_and_oversized_grids_are_refused_before_allocating")
    else {
        return;
    };
    let err = DeviceField::upload(&context, "sigma_t", &[1.0, f32::NAN], true).unwrap_err();
    assert!(
        matches!(
            err,
            GpuError::BadInput {
                index: 1,
                problem: "not finite",
                ..
            }
        ),
        "{err}"
    );
    let err = DeviceField::upload(&context, "sigma_t", &[1.0, 2.0, -0.5], true).unwrap_err();
    assert!(
        matches!(
            err,
            GpuError::BadInput {
                index: 2,
                problem: "negative",
                ..
            }
        ),
        "{err}"
    );
    // Negative values are fine where the caller allows them (a signed distance).
    assert!(DeviceField::upload(&context, "sdf", &[-1.0], false).is_ok());
    // One binding beyond the adapter's limit (lavapipe: 128 MiB) is refused with the
    // limit's name, without touching the device.
    let limit = context.limits().max_storage_buffer_binding_size;
    let err = DeviceField::zeros(&context, "a 1024³ grid", (limit / 4 + 1) as usize).unwrap_err();
    match err {
        GpuError::OverBudget {
            limit: name,
            needed,
            available,
            ..
        } => {
            assert_eq!(name, "max_storage_buffer_binding_size");
            assert_eq!(available, limit);
            assert!(needed > limit);
        }
        other => panic!("{other}"),
    }
    // A 256³ grid fits (64 MiB), on lavapipe too.
    assert!(DeviceField::zeros(&context, "a 256³ grid", 256 * 256 * 256).is_ok());
}

#[test]
fn an_adapter_name_that_matches_nothing_is_a_typed_error() {
    let options = lucent_gpu::GpuOptions {
        adapter_name: Some("no-such-adapter-0xdead".into()),
        backends: wgpu::Backends::PRIMARY,
    };
    let err = GpuContext::with_options(&options).unwrap_err();
    assert!(
        matches!(&err, GpuError::NoAdapter { reason } if reason.contains("no-such-adapter-0xdead")),
        "{err}"
    );
}

#[test]
fn a_pass_is_timed_by_the_devices_clock_and_scales_with_its_work() {
    // The reduction kernel over 256 values and over 16 M values: both times positive,
    // below the host's wall time around the call, and the large pass the longer one.
    let Some(context) =
        context_or_skip("a_pass_is_timed_by_the_devices_clock_and_scales_with_its_work")
    else {
        return;
    };
    let device = context.device();
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("reduce"),
        source: wgpu::ShaderSource::Wgsl(lucent_gpu::shaders::REDUCE.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("sum"),
        layout: None,
        module: &module,
        entry_point: Some("sum"),
        compilation_options: Default::default(),
        cache: None,
    });
    let mut times = Vec::new();
    for len in [256usize, 1 << 24] {
        let values = DeviceField::zeros(&context, "values", len).unwrap();
        let groups = len.div_ceil(256);
        let groups_x = groups.min(65_535);
        let groups_y = groups.div_ceil(groups_x);
        let partials = DeviceField::zeros(&context, "partials", groups_x * groups_y).unwrap();
        let params_uniform = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("params"),
            size: 16,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        context.queue().write_buffer(
            &params_uniform,
            0,
            bytemuck::cast_slice(&[len as u32, groups_x as u32, 0, 0]),
        );
        let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: values.buffer().as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: partials.buffer().as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: params_uniform.as_entire_binding(),
                },
            ],
        });
        let host = std::time::Instant::now();
        let timing = context
            .timed_pass("sum", |pass| {
                pass.set_pipeline(&pipeline);
                pass.set_bind_group(0, &bind, &[]);
                pass.dispatch_workgroups(groups_x as u32, groups_y as u32, 1);
            })
            .unwrap();
        let wall = host.elapsed().as_secs_f64();
        if context.has_timestamps() {
            assert_eq!(timing.source, lucent_gpu::TimingSource::Timestamps);
        }
        assert!(
            timing.seconds > 0.0 && timing.seconds <= wall,
            "{timing:?} vs wall {wall}"
        );
        times.push(timing.seconds);
    }
    assert!(times[1] > times[0], "{times:?}");
}

#[test]
fn a_problems_medium_goes_up_per_channel_as_the_host_holds_it() {
    use glam::DVec3;
    use lucent_core::{Boundary, Field, Light, Medium, Problem, Spectrum};
    use lucent_grid::{Grid, GridGeometry};
    let Some(context) =
        context_or_skip("a_problems_medium_goes_up_per_channel_as_the_host_holds_it")
    else {
        return;
    };
    // RGB extinction on a 7 × 5 × 3 grid (not a multiple of 8), a per-cell albedo in one
    // channel and constants in the others.
    let g = GridGeometry::new([7, 5, 3], DVec3::splat(0.5), DVec3::ZERO).unwrap();
    let ramp = |scale: f32| {
        let mut grid = Grid::filled(g, 0.0);
        for (i, v) in grid.data_mut().iter_mut().enumerate() {
            *v = scale * i as f32;
        }
        grid
    };
    let albedo_grid = ramp(1.0 / 105.0);
    let medium = Medium {
        sigma_t: vec![ramp(0.5), ramp(1.0), ramp(2.0)],
        albedo: vec![
            Field::Grid(albedo_grid.clone()),
            Field::Constant(0.25),
            Field::Constant(0.75),
        ],
        phase: lucent_optics::Phase::Isotropic,
    };
    let sun = Light::Directional {
        direction: DVec3::NEG_Z,
        irradiance: Spectrum::Rgb([1.0, 1.0, 1.0]),
    };
    let problem = Problem::new(g, medium, vec![sun], Boundary::Vacuum, None).unwrap();
    let device = lucent_gpu::DeviceMedium::upload(&context, &problem).unwrap();
    assert_eq!(device.sigma_t.len(), 3);
    assert_eq!(device.albedo.len(), 3);
    for c in 0..3 {
        assert_eq!(
            device.sigma_t[c].download(&context).unwrap(),
            problem.medium().sigma_t(c).data()
        );
    }
    assert_eq!(
        device.albedo[0].download(&context).unwrap(),
        albedo_grid.data()
    );
    assert_eq!(
        device.albedo[2].download(&context).unwrap(),
        vec![0.75f32; 105]
    );
    assert_eq!(lucent_gpu::DeviceMedium::bytes(&problem), 6 * 105 * 4);
}
