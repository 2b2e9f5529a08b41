//! The adapter, the device and the limits lucent asks for.

use crate::error::GpuError;

/// The smallest storage-buffer binding lucent needs: one 256³ f32 grid (64 MiB).
pub(crate) const MIN_BINDING_BYTES: u64 = 64 << 20;
/// The fewest storage buffers per shader stage lucent's kernels bind (ping-pong fields,
/// coefficients, sources, reductions): lavapipe offers 32, the WebGPU default is 8.
pub(crate) const MIN_STORAGE_BUFFERS: u32 = 8;

/// How to choose an adapter.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GpuOptions {
    /// Only an adapter whose name contains this (case-insensitive); `WGPU_ADAPTER_NAME`.
    pub adapter_name: Option<String>,
    /// Which APIs to look at; `WGPU_BACKEND` (`vulkan`, `metal`, `dx12`, comma-separated),
    /// else Vulkan, Metal and DX12.
    pub backends: wgpu::Backends,
}

impl GpuOptions {
    /// The options the environment asks for (`WGPU_ADAPTER_NAME`, `WGPU_BACKEND`).
    pub fn from_env() -> Self {
        Self {
            adapter_name: std::env::var("WGPU_ADAPTER_NAME")
                .ok()
                .filter(|n| !n.trim().is_empty()),
            backends: wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY),
        }
    }
}

/// A device ready for lucent's kernels, with what its adapter is and allows.
#[derive(Debug)]
pub struct GpuContext {
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    limits: wgpu::Limits,
    timestamps: bool,
    f64: bool,
    /// The query set, resolve buffer and readback of timed passes, made on first use and
    /// kept (a timed pass per cycle of an iteration should not allocate).
    pub(crate) timing: std::sync::Mutex<Option<crate::timing::TimingObjects>>,
    /// Compiled kernels by (file, entry point): a pipeline is compiled once per device.
    kernels: std::sync::Mutex<
        std::collections::HashMap<(String, String), std::sync::Arc<crate::kernel::Kernel>>,
    >,
}

impl GpuContext {
    /// The adapter the environment asks for, else the default one.
    pub fn new() -> Result<Self, GpuError> {
        Self::with_options(&GpuOptions::from_env())
    }

    /// The adapter `options` ask for, with lucent's limits requested explicitly: the
    /// adapter's own storage-binding size, buffer size and storage buffers per stage (at
    /// least 64 MiB, one 256³ f32 grid, and 8), and timestamp queries
    /// where it has them.
    pub fn with_options(options: &GpuOptions) -> Result<Self, GpuError> {
        let instance = wgpu::Instance::new(
            wgpu::InstanceDescriptor {
                backends: options.backends,
                ..wgpu::InstanceDescriptor::new_without_display_handle()
            }
            .with_env(),
        );
        let adapter = match &options.adapter_name {
            Some(name) => {
                let wanted = name.to_lowercase();
                let adapters = pollster::block_on(instance.enumerate_adapters(options.backends));
                let names: Vec<String> = adapters.iter().map(|a| a.get_info().name).collect();
                adapters
                    .into_iter()
                    .find(|a| a.get_info().name.to_lowercase().contains(&wanted))
                    .ok_or_else(|| GpuError::NoAdapter {
                        reason: format!(
                            "none is named like WGPU_ADAPTER_NAME = `{name}` (found: {})",
                            if names.is_empty() {
                                "none".to_owned()
                            } else {
                                names.join(", ")
                            }
                        ),
                    })?
            }
            None => pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                ..Default::default()
            }))
            .map_err(|e| GpuError::NoAdapter {
                reason: e.to_string(),
            })?,
        };
        let info = adapter.get_info();
        let offered = adapter.limits();
        let need = |what: &'static str, needed: u64, available: u64| {
            if available < needed {
                Err(GpuError::Unsupported {
                    adapter: info.name.clone(),
                    what,
                    needed,
                    available,
                })
            } else {
                Ok(())
            }
        };
        need(
            "max_storage_buffer_binding_size",
            MIN_BINDING_BYTES,
            offered.max_storage_buffer_binding_size,
        )?;
        need(
            "max_storage_buffers_per_shader_stage",
            u64::from(MIN_STORAGE_BUFFERS),
            u64::from(offered.max_storage_buffers_per_shader_stage),
        )?;
        need(
            "max_compute_invocations_per_workgroup",
            256,
            u64::from(offered.max_compute_invocations_per_workgroup),
        )?;
        let limits = wgpu::Limits {
            max_storage_buffer_binding_size: offered.max_storage_buffer_binding_size,
            max_buffer_size: offered.max_buffer_size,
            max_storage_buffers_per_shader_stage: offered.max_storage_buffers_per_shader_stage,
            // All buffers a stage binds (storage + uniform): `gpu-lbm`'s D3Q19 step binds
            // 25 storage buffers and one uniform block.
            max_buffers_and_acceleration_structures_per_shader_stage: offered
                .max_buffers_and_acceleration_structures_per_shader_stage,
            max_compute_workgroups_per_dimension: offered.max_compute_workgroups_per_dimension,
            max_compute_invocations_per_workgroup: 256,
            max_compute_workgroup_size_x: 256,
            ..wgpu::Limits::downlevel_defaults()
        };
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        // f64 in shaders (Vulkan's shaderFloat64: NVIDIA, AMD, Intel and lavapipe have
        // it, Metal does not): the kernels that must keep an f64 solution and residual
        // on the device ask for it, and fall back to the host where it is missing.
        let f64 = adapter.features().contains(wgpu::Features::SHADER_F64);
        let mut features = wgpu::Features::empty();
        features.set(wgpu::Features::TIMESTAMP_QUERY, timestamps);
        features.set(wgpu::Features::SHADER_F64, f64);
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("lucent"),
            required_features: features,
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device(e.to_string()))?;
        Ok(Self {
            device,
            queue,
            info,
            limits,
            timestamps,
            f64,
            timing: Default::default(),
            kernels: Default::default(),
        })
    }

    /// Entry point `entry` of `source` (named `file`), compiled on first use and kept:
    /// backends ask for their kernels per solve without recompiling them (pipeline
    /// creation costs milliseconds on a GPU driver, and a software adapter's compiler
    /// tens of MiB of memory).
    pub fn kernel(
        &self,
        file: &str,
        source: &str,
        entry: &str,
    ) -> Result<std::sync::Arc<crate::kernel::Kernel>, GpuError> {
        let key = (file.to_owned(), entry.to_owned());
        if let Some(k) = self
            .kernels
            .lock()
            .map_err(|e| GpuError::Device(e.to_string()))?
            .get(&key)
        {
            return Ok(k.clone());
        }
        let kernel = std::sync::Arc::new(crate::kernel::Kernel::new(self, file, source, entry)?);
        self.kernels
            .lock()
            .map_err(|e| GpuError::Device(e.to_string()))?
            .insert(key, kernel.clone());
        Ok(kernel)
    }

    /// The process's shared context: the environment's adapter, opened on first use and
    /// kept (opening a device costs tens of milliseconds; backends share one). A failure
    /// is kept too, so every later call reports the same reason at once.
    pub fn shared() -> Result<&'static GpuContext, GpuError> {
        static SHARED: std::sync::OnceLock<Result<GpuContext, GpuError>> =
            std::sync::OnceLock::new();
        SHARED
            .get_or_init(GpuContext::new)
            .as_ref()
            .map_err(Clone::clone)
    }

    /// The device.
    pub fn device(&self) -> &wgpu::Device {
        &self.device
    }

    /// Its queue.
    pub fn queue(&self) -> &wgpu::Queue {
        &self.queue
    }

    /// What the adapter is.
    pub fn info(&self) -> &wgpu::AdapterInfo {
        &self.info
    }

    /// The limits the device was created with.
    pub fn limits(&self) -> &wgpu::Limits {
        &self.limits
    }

    /// Whether kernels can be timed by timestamp queries (else by wall time).
    pub fn has_timestamps(&self) -> bool {
        self.timestamps
    }

    /// Whether kernels may use f64 (the device was created with `SHADER_F64`).
    pub fn has_f64(&self) -> bool {
        self.f64
    }

    /// Whether the adapter is a CPU implementation (lavapipe, WARP): good for correctness,
    /// never for quoting GPU speed.
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// One line for people: the adapter, its API and the limits in use.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?}{}): storage bindings up to {} MiB, {} storage buffers per stage, timestamps {}, f64 {}",
            self.info.name,
            self.info.backend,
            self.info.device_type,
            if self.info.driver_info.is_empty() {
                String::new()
            } else {
                format!(", {}", self.info.driver_info)
            },
            self.limits.max_storage_buffer_binding_size >> 20,
            self.limits.max_storage_buffers_per_shader_stage,
            if self.timestamps { "yes" } else { "no" },
            if self.f64 { "yes" } else { "no" }
        )
    }

    /// Fails with [`GpuError::OverBudget`] unless one binding of `bytes` fits the
    /// device's limits (binding size and buffer size).
    pub fn check_binding(&self, what: &str, bytes: u64) -> Result<(), GpuError> {
        for (limit, available) in [
            (
                "max_storage_buffer_binding_size",
                self.limits.max_storage_buffer_binding_size,
            ),
            ("max_buffer_size", self.limits.max_buffer_size),
        ] {
            if bytes > available {
                return Err(GpuError::OverBudget {
                    what: what.to_owned(),
                    limit,
                    needed: bytes,
                    available,
                });
            }
        }
        Ok(())
    }

    /// Runs `f`, turning the device's validation and out-of-memory errors during it into
    /// a [`GpuError::Device`] instead of wgpu's default panic.
    pub fn checked<T>(&self, f: impl FnOnce() -> T) -> Result<T, GpuError> {
        let memory = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let value = f();
        let errors = [
            pollster::block_on(validation.pop()),
            pollster::block_on(memory.pop()),
        ];
        match errors.into_iter().flatten().next() {
            Some(e) => Err(GpuError::Device(e.to_string())),
            None => Ok(value),
        }
    }

    /// Waits until the queue has finished everything submitted.
    pub fn wait(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: None,
                timeout: None,
            })
            .map(|_| ())
            .map_err(|e| GpuError::Device(e.to_string()))
    }
}

/// A context for a test, or `None` (with the reason printed) where no adapter exists —
/// except under CI (`CI=true`), where a missing adapter fails the run instead of skipping.
pub fn context_or_skip(test: &str) -> Option<GpuContext> {
    match GpuContext::new() {
        Ok(context) => Some(context),
        Err(e) => {
            let ci = std::env::var("CI").is_ok_and(|v| v == "true" || v == "1");
            assert!(!ci, "{test}: CI=true and {e}");
            eprintln!("skipping {test}: {e}");
            None
        }
    }
}
