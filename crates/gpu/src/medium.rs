//! A problem's medium on the device: σ_t and the albedo of every channel, uploaded once
//! and shared by every GPU backend.

use lucent_core::{Field, Problem};

use crate::context::GpuContext;
use crate::error::GpuError;
use crate::field::DeviceField;

/// σ_t (1/length) and albedo per channel on the device, in the problem's cell order.
#[derive(Debug)]
pub struct DeviceMedium {
    /// σ_t per extinction channel (one for a grey medium, three for RGB extinction).
    pub sigma_t: Vec<DeviceField>,
    /// The albedo per channel, expanded to one value per cell (a constant albedo too:
    /// kernels read every coefficient the same way).
    pub albedo: Vec<DeviceField>,
}

impl DeviceMedium {
    /// Uploads `problem`'s medium after checking, before any allocation, that every field
    /// is finite and non-negative (albedo ≤ 1 is the problem's own invariant) and that the
    /// whole medium fits one binding per field.
    pub fn upload(context: &GpuContext, problem: &Problem) -> Result<Self, GpuError> {
        let medium = problem.medium();
        let cells = problem.geometry().voxel_count();
        let bytes = cells as u64 * 4;
        context.check_binding("one field of the medium", bytes)?;
        let sigma_t = medium
            .sigma_t
            .iter()
            .enumerate()
            .map(|(c, grid)| DeviceField::from_grid(context, &format!("sigma_t[{c}]"), grid, true))
            .collect::<Result<Vec<_>, _>>()?;
        let albedo = (0..medium.albedo.len())
            .map(|c| {
                let what = format!("albedo[{c}]");
                match medium.albedo(c) {
                    Field::Grid(grid) => DeviceField::from_grid(context, &what, grid, true),
                    Field::Constant(a) => {
                        DeviceField::upload(context, &what, &vec![*a; cells], true)
                    }
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { sigma_t, albedo })
    }

    /// Bytes the medium of `problem` takes on the device, for memory estimates.
    pub fn bytes(problem: &Problem) -> u64 {
        let medium = problem.medium();
        let fields = (medium.sigma_t.len() + medium.albedo.len()) as u64;
        fields * problem.geometry().voxel_count() as u64 * 4
    }
}
