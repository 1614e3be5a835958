//! Size limits checked *before* anything proportional to user input is allocated: elements
//! per scene, members per sweep, and a memory estimate (members × elements × bytes per
//! element) against a limit the user can raise with the `COSSERAT_MAX_MEMORY` environment
//! variable (`docs/guarantees.md`).

/// Most elements in one scene (all rods together), and in one segment.
pub const MAX_SCENE_ELEMENTS: usize = 1_000_000;

/// Most time steps of one run (`t_end / dt`).
pub const MAX_STEPS: f64 = 1e9;

/// Most members in one sweep (or rods in one bench batch).
pub const MAX_MEMBERS: u64 = 10_000_000;

/// Memory a running member needs per element, in bytes (element data, state, the block
/// sparse tangent and its factorization, records): the peak RSS of `cosserat run` on the
/// cantilever with 10⁵ elements less that with 10³, per element, measured 11.7 kB.
pub const BYTES_PER_ELEMENT: u64 = 12_000;

/// Memory a member needs besides its elements (its scene, solver set-up, records).
pub const BYTES_PER_MEMBER: u64 = 200_000;

/// Memory of a queued member's description (its model and parameters) per element, and
/// besides its elements: `bench --rods 100000 --elements 10` held 459 MB of member
/// descriptions (4.6 kB per member) before running.
pub const DESCRIPTION_BYTES_PER_ELEMENT: u64 = 400;

/// See [`DESCRIPTION_BYTES_PER_ELEMENT`].
pub const DESCRIPTION_BYTES_PER_MEMBER: u64 = 1_000;

/// Most members of a batch running at once: the GPU path's default slots
/// (`crate::batch::DEFAULT_GPU_SLOTS`); the CPU path runs one per thread. Measured peak
/// RSS of `bench --rods 100000 --elements 10 --steps 2`: 0.46 GB on the CPU path, 1.9 GB on
/// the GPU path (4096 slots); this estimate gives 1.8 GB.
pub const MAX_IN_FLIGHT: u64 = 4096;

/// Default memory limit when `COSSERAT_MAX_MEMORY` is not set: 16 GiB.
pub const DEFAULT_MAX_MEMORY: u64 = 16 << 30;

/// The environment variable that overrides [`DEFAULT_MAX_MEMORY`] (bytes, or with a
/// `K`, `M`, `G` or `T` suffix, powers of 1024: `COSSERAT_MAX_MEMORY=64G`).
pub const MEMORY_ENV: &str = "COSSERAT_MAX_MEMORY";

/// A size refused before allocation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LimitError {
    /// The estimate exceeds the memory limit.
    #[error(
        "{what} would need about {} of memory ({members} member(s) × {elements} element(s)), above the limit of {} (set {MEMORY_ENV}, e.g. {MEMORY_ENV}=64G, to raise it)",
        human(*.bytes), human(*.limit)
    )]
    Memory {
        /// What was being sized.
        what: String,
        /// Members (or rods).
        members: u64,
        /// Elements per member.
        elements: u64,
        /// Estimated bytes.
        bytes: u64,
        /// The limit in force.
        limit: u64,
    },
    /// `COSSERAT_MAX_MEMORY` cannot be read.
    #[error("{MEMORY_ENV}: cannot read `{0}` as a size (expected bytes or a number with K, M, G or T, e.g. 64G)")]
    BadEnv(String),
}

/// Bytes as `12.3 GiB`.
pub fn human(b: u64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut x = b as f64;
    let mut u = 0;
    while x >= 1024.0 && u + 1 < units.len() {
        x /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{b} B")
    } else {
        format!("{x:.1} {}", units[u])
    }
}

/// Parses a size: plain bytes or a number with a `K`, `M`, `G`, `T` suffix (optionally
/// followed by `B` or `iB`), powers of 1024.
pub fn parse_size(s: &str) -> Option<u64> {
    let t = s.trim();
    let t = t
        .strip_suffix("iB")
        .or_else(|| t.strip_suffix('B'))
        .unwrap_or(t);
    let (num, mult) = match t.chars().last()? {
        'k' | 'K' => (&t[..t.len() - 1], 1u64 << 10),
        'm' | 'M' => (&t[..t.len() - 1], 1 << 20),
        'g' | 'G' => (&t[..t.len() - 1], 1 << 30),
        't' | 'T' => (&t[..t.len() - 1], 1 << 40),
        _ => (t, 1),
    };
    let x: f64 = num.trim().parse().ok()?;
    if !(x.is_finite() && x > 0.0) {
        return None;
    }
    let b = x * mult as f64;
    (b < u64::MAX as f64).then_some(b as u64)
}

/// The memory limit in force: `COSSERAT_MAX_MEMORY` if set, else [`DEFAULT_MAX_MEMORY`].
pub fn memory_limit() -> Result<u64, LimitError> {
    match std::env::var(MEMORY_ENV) {
        Ok(v) => parse_size(&v).ok_or(LimitError::BadEnv(v)),
        Err(_) => Ok(DEFAULT_MAX_MEMORY),
    }
}

/// Estimated bytes of a batch of `members` members of `elements` elements each
/// (saturating): every member's description is held for the whole batch, but at most
/// [`MAX_IN_FLIGHT`] members run at once (the batches stream members through their slots).
pub fn estimate(members: u64, elements: u64) -> u64 {
    let described = members.saturating_mul(
        elements
            .saturating_mul(DESCRIPTION_BYTES_PER_ELEMENT)
            .saturating_add(DESCRIPTION_BYTES_PER_MEMBER),
    );
    let running = members.min(MAX_IN_FLIGHT).saturating_mul(
        elements
            .saturating_mul(BYTES_PER_ELEMENT)
            .saturating_add(BYTES_PER_MEMBER),
    );
    described.saturating_add(running)
}

/// Refuses `members` × `elements` when its estimate exceeds the limit in force.
pub fn check_memory(what: &str, members: u64, elements: u64) -> Result<(), LimitError> {
    let limit = memory_limit()?;
    let bytes = estimate(members, elements);
    if bytes > limit {
        return Err(LimitError::Memory {
            what: what.to_string(),
            members,
            elements,
            bytes,
            limit,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_with_binary_suffixes_and_reject_nonsense() {
        assert_eq!(parse_size("1024"), Some(1024));
        assert_eq!(parse_size("64G"), Some(64 << 30));
        assert_eq!(parse_size("1.5KiB"), Some(1536));
        assert_eq!(parse_size("2MB"), Some(2 << 20));
        for bad in ["", "G", "-1G", "NaNG", "1e300T", "x"] {
            assert_eq!(parse_size(bad), None, "{bad}");
        }
    }

    #[test]
    fn estimate_saturates_and_the_error_names_the_override() {
        assert_eq!(estimate(u64::MAX, u64::MAX), u64::MAX);
        let e = LimitError::Memory {
            what: "sweep".into(),
            members: 10,
            elements: 5,
            bytes: 3 << 30,
            limit: 1 << 30,
        }
        .to_string();
        assert!(
            e.contains("3.0 GiB") && e.contains("COSSERAT_MAX_MEMORY"),
            "{e}"
        );
    }
}
