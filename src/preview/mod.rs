//! `sky preview` (issue 14): the baked LUTs decoded on a GPU through wgpu,
//! headless, on a real GPU or on Mesa's lavapipe (a Vulkan driver on the
//! CPU), with the WGSL in `shaders/`. Behind the `preview` feature, so the
//! library and `sky worker` do not pull wgpu.
//!
//! Built: the device ([`gpu`]), one frame's buffers and pass times
//! ([`frame`]), the sky pass ([`sky_pass`], tested against the CPU
//! decoder by readback), the landscape and its global fog
//! ([`landscape`]), the clouds' noise ([`cloud_noise`]), coverage
//! ([`cloud_coverage`]) and G-buffer with its amortisation and lighting
//! ([`clouds`]), the benchmark's baseline ([`plain_pass`]) and the session
//! that renders frames of a timeline ([`session`]).

pub mod cloud_coverage;
pub mod cloud_noise;
pub mod clouds;
pub mod frame;
pub mod gpu;
pub mod landscape;
pub mod plain_pass;
pub mod session;
pub mod sky_pass;

/// What stops a preview.
#[derive(Debug, thiserror::Error)]
pub enum PreviewError {
    /// No adapter: no GPU and no Vulkan driver such as lavapipe.
    #[error("no GPU adapter ({0}); on a machine without a GPU install Mesa's lavapipe (apt-get install mesa-vulkan-drivers libvulkan1) and set WGPU_BACKEND=vulkan")]
    NoAdapter(String),
    #[error("the GPU device could not be opened: {0}")]
    Device(String),
    /// A shader, pipeline or command the device refused (a validation
    /// error), with wgpu's message.
    #[error("the GPU refused the {what}: {message}")]
    Validation { what: &'static str, message: String },
    #[error("reading back from the GPU failed: {0}")]
    Readback(String),
    /// The bake cannot be previewed.
    #[error("{0}")]
    Bake(String),
}

/// The WGSL sources, compiled into the binary (and validated by naga in
/// the tests).
pub mod shaders {
    /// The basis-sky decode (see `sky_pass`).
    pub const SKY_DECODE: &str = include_str!("../../shaders/sky_decode.wgsl");
    /// The landscape's depth buffer and lit surfaces (see `landscape`).
    pub const TERRAIN: &str = include_str!("../../shaders/terrain.wgsl");
    /// The global fog in front of the landscape (see `landscape`).
    pub const FOG: &str = include_str!("../../shaders/fog.wgsl");
    /// The benchmark's baseline, a plain textured pass (see `plain_pass`).
    pub const PLAIN_TEXTURE: &str = include_str!("../../shaders/plain_texture.wgsl");
    /// The clouds' noise textures (see `cloud_noise`).
    pub const CLOUD_NOISE: &str =
        concat!(include_str!("../../shaders/hash.wgsl"), include_str!("../../shaders/cloud_noise.wgsl"));
    /// The cumulus map, shadow volume and cloud G-buffer (see `clouds`).
    pub const CLOUDS: &str =
        concat!(include_str!("../../shaders/hash.wgsl"), include_str!("../../shaders/clouds.wgsl"));
    /// The G-buffer's deferred lighting (see `clouds`).
    pub const CLOUD_LIGHTING: &str = include_str!("../../shaders/cloud_lighting.wgsl");
    /// Every shader, by file name.
    pub const ALL: &[(&str, &str)] = &[
        ("cloud_noise.wgsl", CLOUD_NOISE),
        ("clouds.wgsl", CLOUDS),
        ("cloud_lighting.wgsl", CLOUD_LIGHTING),
        ("sky_decode.wgsl", SKY_DECODE),
        ("terrain.wgsl", TERRAIN),
        ("fog.wgsl", FOG),
        ("plain_texture.wgsl", PLAIN_TEXTURE),
    ];
}

#[cfg(test)]
mod tests {
    /// Every shader parses and validates with naga, the compiler wgpu uses,
    /// without a device.
    #[test]
    fn every_shader_validates() {
        for &(name, source) in super::shaders::ALL {
            let module = wgpu::naga::front::wgsl::parse_str(source)
                .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(source)));
            wgpu::naga::valid::Validator::new(
                wgpu::naga::valid::ValidationFlags::all(),
                wgpu::naga::valid::Capabilities::default(),
            )
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {e:?}"));
        }
    }
}
