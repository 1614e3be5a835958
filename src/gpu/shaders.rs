//! The WGSL sources of every pass (`shaders/*.wgsl`, f64 versions) and their rewriting to
//! the precision a device runs. The lowest module of [`crate::gpu`]: the context hashes
//! these sources for its pipeline cache, the kernels build their pipelines from them.

/// Floating-point precision the kernels run in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    /// `SHADER_F64`: the CPU kernel's arithmetic to round-off.
    F64,
    /// Fallback on adapters without f64 (measured error: docs/gpu.md, "Kernels").
    F32,
}

/// The element kernel's WGSL source (f64 version).
pub const ELEMENT_WGSL: &str = include_str!("../../shaders/element.wgsl");
/// The WGSL source of the assembly pass (f64 version).
pub const ASSEMBLE_WGSL: &str = include_str!("../../shaders/assemble.wgsl");
/// The WGSL source of the increment gather pass (f64 version).
pub const GATHER_WGSL: &str = include_str!("../../shaders/gather.wgsl");
/// The WGSL source of the batched block-tridiagonal solver (f64 only).
pub const BLOCKTRI_WGSL: &str = include_str!("../../shaders/blocktri.wgsl");
/// The WGSL source of the planar element kernel (f64 only).
pub const PLANAR_WGSL: &str = include_str!("../../shaders/planar.wgsl");
/// The WGSL source of the upload scatter pass (f64 version).
pub(crate) const SCATTER_WGSL: &str = include_str!("../../shaders/scatter.wgsl");
/// The WGSL source of the solver-report compaction pass.
pub(crate) const COMPACT_WGSL: &str = include_str!("../../shaders/compact.wgsl");

/// The sources the on-disk pipeline cache is keyed by: every shader the crate compiles, so
/// that a changed pass never reuses a stale compiled pipeline.
pub(crate) const CACHE_KEYED: [&str; 7] = [
    ELEMENT_WGSL,
    ASSEMBLE_WGSL,
    GATHER_WGSL,
    BLOCKTRI_WGSL,
    PLANAR_WGSL,
    SCATTER_WGSL,
    COMPACT_WGSL,
];

/// `src` for precision `p` (the f32 variant rewrites `Real` and, where present, the
/// element-kernel constants that do not fit an f32).
pub(crate) fn shader_precision(src: &str, p: Precision) -> String {
    match p {
        Precision::F64 => src.to_string(),
        Precision::F32 => src
            .replace("alias Real = f64;", "alias Real = f32;")
            .replace("const TINY: Real = 1e-300;", "const TINY: Real = 1e-30;")
            .replace("const HUGE: Real = 1e300;", "const HUGE: Real = 1e30;")
            .replace(
                "const CNU_TOL: Real = 1e-15;",
                "const CNU_TOL: Real = 1e-7;",
            ),
    }
}

/// Bytes per shader scalar (`Real`) in precision `p`.
pub(crate) fn real_width(p: Precision) -> usize {
    match p {
        Precision::F64 => 8,
        Precision::F32 => 4,
    }
}

#[cfg(test)]
mod tests {
    /// Every WGSL file in `shaders/` keys the pipeline cache (a shader added without it
    /// would let a changed pass reuse a stale compiled pipeline).
    #[test]
    fn every_shader_keys_the_pipeline_cache() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
        let mut n = 0;
        for e in std::fs::read_dir(&dir).unwrap() {
            let path = e.unwrap().path();
            if path.extension().is_some_and(|x| x == "wgsl") {
                let src = std::fs::read_to_string(&path).unwrap();
                assert!(
                    super::CACHE_KEYED.contains(&src.as_str()),
                    "{} does not key the pipeline cache",
                    path.display()
                );
                n += 1;
            }
        }
        assert_eq!(n, super::CACHE_KEYED.len());
    }
}
