//! Timing a kernel: timestamp queries where the adapter has them (the GPU's own clock,
//! the pass alone), wall time from submit to completion otherwise.

use std::time::Instant;

use crate::context::GpuContext;
use crate::error::GpuError;
use crate::field::Readback;

/// Where a [`Timing`] came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimingSource {
    /// The device's timestamps at the start and the end of the pass.
    Timestamps,
    /// The host's clock from submit to completion (includes submission overhead).
    WallClock,
}

/// How long one compute pass took.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timing {
    /// Seconds.
    pub seconds: f64,
    /// How it was measured.
    pub source: TimingSource,
}

/// What a timed pass records its timestamps with, kept by the context.
#[derive(Debug)]
pub(crate) struct TimingObjects {
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    ticks: Option<Readback>,
}

impl GpuContext {
    /// Records `record` into one compute pass, submits it alone and waits for it: the
    /// pass's time by timestamp queries where the adapter offers them, else wall time.
    pub fn timed_pass(
        &self,
        label: &str,
        record: impl FnOnce(&mut wgpu::ComputePass<'_>),
    ) -> Result<Timing, GpuError> {
        self.timed_commands(label, |_| {}, record, |_| {})
    }

    /// One command buffer of `before` (clears, copies), one compute pass of `record` and
    /// `after` (copies into a [`crate::Readback`], say), submitted and waited for; the
    /// pass alone timed as by [`GpuContext::timed_pass`]. The timestamps come back through
    /// a staging copy in the same command buffer: one submit and one wait in all.
    pub fn timed_commands(
        &self,
        label: &str,
        before: impl FnOnce(&mut wgpu::CommandEncoder),
        record: impl FnOnce(&mut wgpu::ComputePass<'_>),
        after: impl FnOnce(&mut wgpu::CommandEncoder),
    ) -> Result<Timing, GpuError> {
        let device = self.device();
        let mut kept = self
            .timing
            .lock()
            .map_err(|e| GpuError::Device(e.to_string()))?;
        if self.has_timestamps() && kept.is_none() {
            *kept = Some(self.checked(|| TimingObjects {
                set: device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("lucent timestamps"),
                    ty: wgpu::QueryType::Timestamp,
                    count: 2,
                }),
                resolve: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("lucent timestamp resolve"),
                    size: 16,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
                ticks: None,
            })?);
            if let Some(objects) = kept.as_mut() {
                objects.ticks = Some(Readback::new(self, "lucent timestamps", 16)?);
            }
        }
        let queries = kept.as_ref().map(|o| (&o.set, &o.resolve));
        let ticks = kept.as_ref().and_then(|o| o.ticks.as_ref());
        let started = self.checked(|| {
            let mut encoder = device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
            before(&mut encoder);
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some(label),
                    timestamp_writes: queries.map(|(set, _)| wgpu::ComputePassTimestampWrites {
                        query_set: set,
                        beginning_of_pass_write_index: Some(0),
                        end_of_pass_write_index: Some(1),
                    }),
                });
                record(&mut pass);
            }
            if let (Some((set, resolve)), Some(ticks)) = (queries, ticks) {
                encoder.resolve_query_set(set, 0..2, resolve, 0);
                ticks.record(&mut encoder, resolve, 0, 0, 16);
            }
            after(&mut encoder);
            let started = Instant::now();
            self.queue().submit([encoder.finish()]);
            started
        })?;
        self.wait()?;
        let wall = started.elapsed().as_secs_f64();
        match ticks {
            Some(ticks) => {
                let bytes = ticks.read(self)?;
                let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&bytes);
                let period = f64::from(self.queue().get_timestamp_period());
                Ok(Timing {
                    seconds: ticks[1].saturating_sub(ticks[0]) as f64 * period * 1e-9,
                    source: TimingSource::Timestamps,
                })
            }
            None => Ok(Timing {
                seconds: wall,
                source: TimingSource::WallClock,
            }),
        }
    }
}
