//! Which adapter lucent would use, with its limits, and one round trip: a 128³ Gaussian
//! blob uploaded, summed on the device (pairwise + f64) and on the host (f64).
//!
//! `cargo run --profile examples -p lucent-gpu --example adapter_report`
//! (`WGPU_ADAPTER_NAME=llvmpipe` picks lavapipe; `WGPU_BACKEND=vulkan` one API).

use glam::DVec3;
use lucent_gpu::{DeviceField, GpuContext, Reducer};
use lucent_grid::GridGeometry;
use lucent_grid::procedural::gaussian_blob;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let context = GpuContext::new()?;
    eprintln!("adapter: {}", context.describe());
    if context.is_software() {
        eprintln!("(a CPU implementation: fine for correctness, not for GPU speed)");
    }
    let geometry = GridGeometry::from_bounds([128; 3], DVec3::splat(-1.0), DVec3::splat(1.0))?;
    let blob = gaussian_blob(geometry, DVec3::ZERO, 0.3)?;
    let field = DeviceField::from_grid(&context, "blob", &blob, true)?;
    let reducer = Reducer::new(&context)?;
    let device = reducer.sum(&context, &field)?;
    let host: f64 = blob.data().iter().map(|&v| f64::from(v)).sum();
    eprintln!(
        "sum over 128³ cells: device {device:.9e}, host {host:.9e}, relative difference {:.2e}",
        (device - host).abs() / host
    );
    Ok(())
}
